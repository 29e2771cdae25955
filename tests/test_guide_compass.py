"""The UI-free P3 sweep guide (station.procedures.guide_compass) on the simulated device."""
from __future__ import annotations

import numpy as np
import pytest

from station.procedures.guide_compass import CompassConfig, CompassGuide, SweepOperator
from station.screens.compass import sweep_positions
from station.sources import SimSource


def make(min_s=30.0, target=0.8, seed=2):
    now = [0.0]
    src = SimSource(seed=seed, procedure="compass", clock=lambda: now[0]).start()
    guide = CompassGuide(sample_rate_hz=src.rate_hz, units=src.units, device_id=src.device_id, site=src.site,
                         config=CompassConfig(min_s=min_s, target_coverage=target))
    return now, src, guide


def run(now, src, guide, seconds, operator=None):
    covs, events = [], []
    t_end = now[0] + seconds
    while now[0] < t_end and guide.phase == "sweep":
        now[0] += 0.1
        b = src.drain()
        st = guide.update(b.t_s, b.accel, b.gyro, b.mag, b.temp_c)
        if operator is not None:
            operator.step(guide, st.t_s)
        covs.append(st.coverage)
        events += guide.take_events()
    return covs, events


def test_sweep_reaches_the_target_and_the_fit_recovers_the_hard_iron():
    from station.calibrate import calibrate_capture

    now, src, guide = make()
    covs, events = run(now, src, guide, 300, SweepOperator(src.place, sweep_positions(src.positions), hold_s=1.0))
    assert guide.phase == "done" and events[-1][0] == "done"
    assert np.all(np.diff(covs) >= 0) and covs[-1] >= 0.8
    assert guide.status().recorded_s >= 30.0
    cap = guide.capture()
    assert cap.is_time_series and cap.meta["mag_unit"] == "uT" and cap.n_rows == guide.status().n_samples
    result = calibrate_capture(cap)
    h, sigma = np.asarray(result["params"]["hard_iron"]), np.asarray(result["uncertainty"]["hard_iron"])
    truth = np.asarray(src.imu.mag["h"])  # the simulated device's hard iron, uT
    assert np.all(np.abs(h - truth) < 4 * sigma + 1e-9), (h, truth, sigma)


def test_a_unit_left_still_covers_almost_nothing():
    now, src, guide = make(min_s=5.0)
    covs, events = run(now, src, guide, 20)
    assert guide.phase == "sweep" and not events
    assert covs[-1] <= 2 / 72  # one direction (a neighbouring cell at most, from noise)
    assert guide.coverage_map()[0] == "·" * 12 or sum(r.count("█") for r in guide.coverage_map()) <= 2


def test_finish_restart_abort():
    now, src, guide = make()
    run(now, src, guide, 3)
    guide.finish()
    assert guide.phase == "done" and guide.take_events()[0][0] == "done"
    guide.restart()
    assert guide.phase == "sweep" and guide.status().n_samples == 0 and guide.coverage == 0
    guide.abort()
    assert guide.phase == "aborted"
    st = guide.update([1.0], [[0, 0, 1]], [[0, 0, 0]], [[1, 2, 3]])
    assert st.n_samples == 0  # ignored once aborted


def test_time_limit_ends_the_recording():
    now, src, guide = make(min_s=1.0)
    guide.config.max_s = 5.0
    run(now, src, guide, 10)
    assert guide.phase == "done" and "time limit" in guide.status().message


@pytest.mark.parametrize("bad", [{"target_coverage": 0}, {"min_s": 10, "max_s": 5}, {"n_bands": 1}])
def test_bad_config_is_refused(bad):
    with pytest.raises(ValueError):
        CompassConfig(**bad)


def test_cells_are_equal_area():
    """Uniform directions fill the 72 cells evenly (bands uniform in z: equal areas)."""
    guide = CompassGuide(sample_rate_hz=100, units={})
    v = np.random.default_rng(0).normal(size=(72_000, 3))
    b, s = guide.cells(v)
    counts = np.bincount(b * 12 + s, minlength=72)
    assert counts.min() > 850 and counts.max() < 1150  # 1000 ± 4.7 sigma (Poisson)
