"""The UI-free P4 static-base hold (station.procedures.gyrodrift_guide) on the simulated device."""
from __future__ import annotations

import numpy as np
import pytest

from station.procedures.gyrodrift_guide import HoldConfig, HoldGuide
from station.sources import SimSource

SIM_FRAME = "x forward, y left, z up"  # the simulated unit lies level with z up


def make(duration_s=180.0, seed=1):
    now = [0.0]
    src = SimSource(seed=seed, procedure="gyro-drift", clock=lambda: now[0], max_batch_s=1.0).start()
    guide = HoldGuide(sample_rate_hz=src.rate_hz, units=src.units, device_id=src.device_id, site=src.site,
                      config=HoldConfig(duration_s=duration_s, settle_s=1.0, frame=SIM_FRAME))
    return now, src, guide


def run(now, src, guide, seconds):
    events = []
    t_end = now[0] + seconds
    st = guide.status()
    while now[0] < t_end and guide.phase not in ("done", "aborted"):
        now[0] += 0.1
        b = src.drain()
        st = guide.update(b.t_s, b.accel, b.gyro, b.temp_c)
        events += guide.take_events()
    return st, events


def test_hold_records_and_the_p4_fit_recovers_the_drift():
    from station.calibrate import calibrate_capture

    now, src, guide = make()
    st, events = run(now, src, guide, 200)
    assert guide.phase == "done" and ("done", "") in events
    cap = guide.capture()
    assert cap.meta["gyro_mode"] == "static" and 180.0 <= cap.columns["t"][-1] - cap.columns["t"][0] < 181.0
    result = calibrate_capture(cap)
    # drift_raw is in the capture's own axes (gx gy gz), like the simulator's bias
    eps = np.asarray(src.imu.gyro["eps"])  # the simulated gyro bias, rad/s
    got = np.asarray(result["drift_raw"]["value"])
    sig = np.asarray(result["drift_raw"]["sigma"])
    assert np.all(np.abs(got - eps) < 4 * sig), (got, eps, sig)


def test_moving_restarts_the_recording():
    now, src, guide = make(duration_s=10.0)
    st, _ = run(now, src, guide, 6.0)
    assert st.phase == "average" and st.countdown_s < 10.0
    src.place("level")  # already level: nudge it by moving to a P1 face and back
    src.imu.set_orientation("x_up")
    st, events = run(now, src, guide, 1.5)
    assert ("restarted", "moved during the recording") in events and st.phase in ("place", "settle")
    assert st.n_samples == 0


def test_abort_and_bad_config():
    now, src, guide = make()
    run(now, src, guide, 2)
    guide.abort()
    assert guide.phase == "aborted"
    with pytest.raises(ValueError):
        HoldConfig(duration_s=0)
