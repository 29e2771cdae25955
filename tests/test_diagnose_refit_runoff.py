"""The extended model's refit must not run off along a direction the data hardly fix.

Captures from the blind generator (benchmarks/blind_generator.py: written from the specs only,
white noise plus Gauss–Markov bias instability and a random walk); the hidden effect's name
goes to the generator only. Before, an unlabelled P1 table with a step in time went to K 25000
times its size (every position read as one specific force; `residual:time` named with a gain
of 96 %), and an LDV X shrank 40-fold beside a smooth function of each axis' input, with a
time delay named at a gain of −305 %."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from station_run import station_json

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))


def _matrix(params: dict) -> np.ndarray:
    return np.asarray(params.get("K", params.get("X")), float)


@pytest.mark.parametrize(
    "procedure, effect, seed",
    [("accel-tabletop", "quadratic", 540301), ("ldv", "time_delay", 580301)],
)
def test_extended_model_stays_a_sensor(tmp_path, procedure, effect, seed):
    import blind_generator

    path = tmp_path / "capture.csv"
    blind_generator.generate(procedure, effect, seed, str(path))
    res = station_json("diagnose", path, "--json")
    base, ext = _matrix(res["baseline"]["params"]), _matrix(res["extended"]["params"])
    assert np.linalg.norm(ext - base) < 0.5 * np.linalg.norm(base), (base, ext)
    # no effect named makes the held-out RMS of the model before it far worse (each gain is taken
    # in the final refitted order, where one that passed beside fewer effects can be a hair below 0)
    assert all(e["gain"] > -0.01 for e in res["effects"]), [(e["name"], e["gain"]) for e in res["effects"]]
    # what remains is not fitted away below the noise: the baseline's held-out RMS, not 4 % of it
    assert res["extended"]["cv_rms"] > 0.3 * res["baseline"]["cv_rms"]
    if procedure == "accel-tabletop":
        assert effect in res["verdict"], res["verdict"]  # named, or tied with the one named
