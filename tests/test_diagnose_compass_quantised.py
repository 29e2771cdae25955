"""Compass (P3) diagnosis of a magnetometer read in counts its noise does not dither.

An AK8963 gives counts of 150 nT; with 20 nT of white noise a still unit reads one count, now
and then the next: the rounding error is a constant per still stretch that no average over the
stretch takes down. Captures are written by the red-team generator
(benchmarks/redteam_captures.py, the shared forward models); a hidden effect's name goes to
the generator only, and the verdict comes from ``station diagnose``."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from station_run import redteam_case, station_json

from solvers import compass as C

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))


@pytest.mark.parametrize("seed", [9194, 9197])
def test_undithered_counts_null_names_nothing(tmp_path, seed):
    """No effect hidden, magnetometer in counts of 150 nT with 20 nT of noise: nothing is named.
    Before, the rows of each hold were taken as independent, each with the white noise alone,
    and a hard-iron step fitted some of the holds' rounding constants: seed 9194 named
    `time_varying_hard_iron` with `residual:time` (D 96 against a bar of 64), 9197
    `residual:time`."""
    res = station_json("diagnose", redteam_case(tmp_path, "compass", "counts_quiet", None, seed), "--json")
    assert res["verdict"] == [], (res["verdict"], res["candidates"])


def test_hard_iron_step_on_undithered_counts_still_named(tmp_path):
    """The same capture with a hard-iron step of about 850 nT (5.7 counts) part-way: named, and
    nothing the report does not tie to it (before, `residual:time` was named beside it: what
    the step left of the holds' rounding constants)."""
    res = station_json(
        "diagnose", redteam_case(tmp_path, "compass", "counts_quiet", "time_varying_hard_iron", 9194), "--json"
    )
    assert "time_varying_hard_iron" in res["verdict"], (res["verdict"], res["candidates"])
    step = next(e for e in res["effects"] if e["name"] == "time_varying_hard_iron")
    tied = {"time_varying_hard_iron"} | {c["name"] for c in step.get("confused_with", [])}
    assert set(res["verdict"]) <= tied, res["verdict"]


def test_shared_rounding_variance_known_limits_and_monte_carlo():
    """τ² of a constant read through a rounding quantiser: q²/12 with no noise (Sheppard: the
    rounding error uniform over a step), about 0 from σ = q/2 (dithered), and between them
    what a Monte Carlo of still stretches gives for the variance of their mean error."""
    q = 150.0
    assert C.rounding_shared_var(0.0, q) == pytest.approx(q**2 / 12, rel=1e-4)
    assert C.rounding_shared_var(0.5 * q, q) < 1e-4 * q**2 / 12
    assert C.rounding_shared_var(20.0, 0.0) == 0.0  # no quantiser
    rng = np.random.default_rng(5)
    x = rng.uniform(0, q, 4000)  # each stretch's true value, anywhere on the grid
    e = np.round((x[:, None] + rng.normal(scale=20.0, size=(4000, 400))) / q) * q - x[:, None]
    tau2 = float(C.rounding_shared_var(20.0, q))
    # the mean error of a stretch of 400 samples: τ² plus the white rest over 400
    mc = float(np.var(e.mean(axis=1)))
    white = 20.0**2 + q**2 / 12 - tau2
    assert mc == pytest.approx(tau2 + white / 400, rel=0.08)  # 4000 stretches: ±4.5 % (1σ) on a variance
    assert float(np.mean(np.var(e, axis=1, ddof=1))) == pytest.approx(white, rel=0.03)


def test_quantum_of_counts_and_of_scaled_counts_only():
    """The grid step per axis: counts, counts times a fixed factor (µT of 0.15 per count), and
    none for readings off any grid (noise written with all its digits)."""
    rng = np.random.default_rng(1)
    counts = np.round(rng.normal(scale=40.0, size=(500, 3)))
    assert np.all(C.quantum(counts) == 1.0)
    assert C.quantum(counts * 0.15) == pytest.approx([0.15] * 3, rel=1e-9)
    assert np.all(C.quantum(rng.normal(scale=40.0, size=(500, 3))) == 0.0)


def test_quantised_noise_recovers_the_noise_before_the_quantiser():
    """σ before the quantiser from the flips of 20 still stretches of 200 samples, and the
    undithered (σ < q/2) from the dithered case: τ² 0 there, σ by Sheppard's correction (also
    where the noise spans many steps: whole nT with 20 nT of noise)."""
    rng = np.random.default_rng(7)
    q, n_s, n = 1.0, 20, 200
    for sigma, undithered in ((0.15, True), (0.3, True), (0.8, False), (20.0, False)):
        x = rng.uniform(-50, 50, size=(n_s, 1, 3))
        y = np.round(x + rng.normal(scale=sigma, size=(n_s, n, 3))).reshape(-1, 3)
        stretches = [(k * n, (k + 1) * n) for k in range(n_s)]
        s, tau2 = C.quantised_noise(y, stretches, C.quantum(y))
        # pooled over 3 axes and 20 stretches; fewer flips where σ is small
        assert s == pytest.approx([sigma] * 3, rel=0.15), (sigma, s)
        assert bool(np.all(tau2 > 0)) is undithered, (sigma, tau2)
        if undithered:
            assert tau2 == pytest.approx(C.rounding_shared_var(s, q), rel=1e-9)


def test_a_capture_off_any_grid_builds_the_problem_it_built_before(tmp_path):
    """The red-team plain capture (µT with all their digits): no quantiser, no still-stretch rows
    (every magnitude row a block of consecutive samples, as before)."""
    from station.capture import read_capture
    from station.procedures.diagnose import analyse

    path = redteam_case(tmp_path, "compass", "plain", None, 9194)
    _, _, inp = analyse(read_capture(str(path)))
    n = read_capture(str(path)).n_rows
    rows = int(np.sum(inp.problem.row_types == 0))
    assert rows == math.ceil(n / math.ceil(n / 4000)), rows
