"""Rows with a missing magnetometer value are left out and counted, never silently."""

from __future__ import annotations

import numpy as np

from solvers.simulate import simulate
from station.calibrate import calibrate_capture
from station.capture import Capture


def test_missing_magnetometer_values_are_counted_in_warnings():
    sim = simulate("compass", seed=2)
    cols = dict(sim.columns)
    mx = cols["mx"].copy()
    mx[::2] = np.nan
    cols["mx"] = mx
    res = calibrate_capture(Capture(meta=sim.meta, columns=cols, path="c.csv"))
    n = len(mx)
    assert any(f"{(n + 1) // 2} of {n} rows left out" in w for w in res["warnings"])
