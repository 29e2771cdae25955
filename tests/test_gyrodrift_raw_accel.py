"""P4 mode B with an analogue accelerometer (V): its zero-g offset must be known before its
direction means a tilt; without it the station says so and does not invent pitch and roll."""

from __future__ import annotations

import pytest

from solvers.simulate import NOMINAL_ACCEL_ZERO_V, simulate
from station.calibrate import calibrate_capture
from station.capture import Capture
from station.errors import InputError


def _capture_in_volts(offset_meta: str | None) -> Capture:
    sim = simulate("gyro-drift", seed=3, pitch_deg=4.0, roll_deg=-3.0)
    cols = dict(sim.columns)
    for k in ("ax", "ay", "az"):  # an analogue front end: 0.0855 V per m/s² about 1.65 V
        cols[k] = NOMINAL_ACCEL_ZERO_V + 0.0855 * cols[k]
    meta = dict(sim.meta, accel_unit="V")
    if offset_meta is not None:
        meta["accel_offset"] = offset_meta
    return Capture(meta=meta, columns=cols, path="v.csv")


def test_volts_without_offset_are_not_used_for_tilt():
    res = calibrate_capture(_capture_in_volts(None))
    assert res["params"]["pitch_deg"] == 0.0 and res["params"]["roll_deg"] == 0.0
    assert any("accel_offset" in w for w in res["warnings"])


def test_volts_with_offset_give_the_true_tilt():
    z = NOMINAL_ACCEL_ZERO_V
    res = calibrate_capture(_capture_in_volts(f"{z}, {z}, {z}"))
    # noise 0.01 m/s² per sample over 18,000 samples: the tilt is good to far better than 0.05°
    assert res["params"]["pitch_deg"] == pytest.approx(4.0, abs=0.05)
    assert res["params"]["roll_deg"] == pytest.approx(-3.0, abs=0.05)


def test_malformed_offset_is_one_line():
    with pytest.raises(InputError, match="three numbers"):
        calibrate_capture(_capture_in_volts("1.65, 1.65"))
