"""A compass capture of a unit that was never turned is refused for that reason, not let
through by sensor noise that points everywhere about its own midrange centre."""

from __future__ import annotations

import numpy as np
import pytest

from solvers.simulate import simulate
from station.calibrate import calibrate_capture
from station.capture import Capture
from station.errors import StationError


def test_still_unit_is_refused_as_not_turned():
    sim = simulate("compass", seed=1)
    rng = np.random.default_rng(0)
    n = 3000
    cols = {"t": np.arange(n) / 50.0}
    for k, v in zip(("ax", "ay", "az"), (0.0, 0.0, 1.0)):
        cols[k] = v + rng.normal(scale=0.002, size=n)
    for k in ("gx", "gy", "gz"):
        cols[k] = rng.normal(scale=0.1, size=n)
    for k, v in zip(("mx", "my", "mz"), (20.0, -3.0, 40.0)):  # uT: field + hard iron, noise 0.15
        cols[k] = v + rng.normal(scale=0.15, size=n)
    with pytest.raises(StationError, match="not turned"):
        calibrate_capture(Capture(meta=sim.meta, columns=cols, path="still.csv"))


def test_a_real_sweep_with_a_large_hard_iron_still_passes():
    sim = simulate("compass", seed=5)
    cols = dict(sim.columns)
    for k in ("mx", "my", "mz"):  # a hard iron of ~3 fields (150 uT) on every axis
        cols[k] = cols[k] + 150.0
    res = calibrate_capture(Capture(meta=sim.meta, columns=cols, path="big.csv"))
    np.testing.assert_allclose(res["params"]["hard_iron"], np.array(sim.truth["hard_iron"]) + 150.0, atol=1.0)
