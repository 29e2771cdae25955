"""The UI-free P5 guide (station.procedures.ldv_guide) on the simulated vehicle
(solvers.simulate.LiveVehicle): the conditioning of the velocity set as it builds is the
P5 fit's own number, a straight road is never enough, turns make it enough, and the
recording calibrates to the vehicle's true beams."""

from __future__ import annotations

import numpy as np
import pytest

from solvers.ldv import KAPPA_REFUSE, KAPPA_WARN, velocity_condition
from solvers.simulate import LiveVehicle
from station.calibrate import calibrate_capture
from station.errors import UnsupportedError
from station.procedures.ldv_guide import LdvConfig, LdvGuide


def drive(car, guide, seconds, chunk=20):
    st = guide.status()
    for _ in range(int(seconds * car.rate_hz / chunk)):
        d = car.read(chunk)
        st = guide.update(
            d["t_s"],
            np.column_stack([d["vl1"], d["vl2"], d["vl3"]]),
            np.column_stack([d["vx"], d["vy"], d["vz"]]),
            np.column_stack([d["wx"], d["wy"], d["wz"]]),
            d["temp_c"],
        )
        if guide.phase != "record":
            break
    return st


def test_the_live_condition_number_is_the_fits_own():
    car = LiveVehicle(seed=4)
    guide = LdvGuide(sample_rate_hz=car.rate_hz, device_id=car.device_id)
    car.drive(True)
    drive(car, guide, 60)
    car.turns(True)
    st = drive(car, guide, 20)
    cap = guide.capture()
    v = np.column_stack([cap.columns[c] for c in ("vx", "vy", "vz")])
    moving = np.linalg.norm(v, axis=1) >= guide.config.moving_mps
    assert st.kappa == pytest.approx(velocity_condition(v[moving]), rel=1e-6)


def test_a_straight_road_is_never_enough_turns_are():
    car = LiveVehicle(seed=5)
    guide = LdvGuide(sample_rate_hz=car.rate_hz, device_id=car.device_id, config=LdvConfig(min_s=60.0))
    st = drive(car, guide, 10)
    assert st.verdict == "none" and "Parked" in st.message and not st.enough
    car.drive(True)
    st = drive(car, guide, 300)
    assert guide.phase == "record" and st.verdict == "refused" and st.kappa > KAPPA_REFUSE and not st.enough
    assert "Straight driving" in st.message and st.estimate is None
    car.turns(True)
    st = drive(car, guide, 300)
    assert guide.phase == "done" and st.enough and st.kappa <= KAPPA_WARN
    assert [k for k, _ in guide.take_events()] == ["done"]
    result = calibrate_capture(guide.capture())
    truth = car.truth
    for j in range(3):
        b, u = result["params"][f"beam{j + 1}"], result["uncertainty"][f"beam{j + 1}"]
        for key in ("alpha_deg", "beta_deg", "gamma_deg"):
            assert abs(b[key] - truth[key][j]) < 6 * u[key] + 0.05, (j, key)


def test_finishing_on_a_straight_road_is_refused_by_the_fit():
    car = LiveVehicle(seed=6)
    guide = LdvGuide(sample_rate_hz=car.rate_hz, device_id=car.device_id)
    car.drive(True)
    drive(car, guide, 120)
    guide.finish()
    assert guide.phase == "done"
    with pytest.raises(UnsupportedError, match="ill-conditioned"):
        calibrate_capture(guide.capture())


def test_restart_and_abort():
    car = LiveVehicle(seed=7)
    guide = LdvGuide(sample_rate_hz=car.rate_hz)
    car.drive(True)
    drive(car, guide, 30)
    assert guide.status().n_samples > 0
    guide.restart()
    st = guide.status()
    assert st.n_samples == 0 and st.n_epochs == 0 and guide.phase == "record"
    guide.abort()
    assert guide.phase == "aborted"
    with pytest.raises(ValueError):
        LdvConfig(min_s=-1)
