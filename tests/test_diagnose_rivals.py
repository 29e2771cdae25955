"""Two candidates whose signatures the data barely separate: only the better is named, and
the other goes in its ``confused_with`` unless the data decide between them.

The P1 captures are written by the independent generator (benchmarks/diag_generator.py);
the hidden effect's name goes to the generator only, never to the code under test. The
engine-level test hides one of two correlated one-column effects in a linear problem and
counts how often the other is named instead without being tied to it.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lfilter
from scipy.stats import norm
from station_run import diagnose_generated

from solvers.diagnose.engine import Candidate, Problem, decisive_margin, diagnose

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import diag_generator as G  # noqa: E402


def _diagnose_generated(tmp_path, capsys, procedure, hidden, seed) -> dict:
    """Diagnose a capture the generator draws from ``seed`` with ``hidden`` at 10σ."""
    return diagnose_generated(tmp_path, capsys, procedure, hidden, seed)[0]


@pytest.mark.parametrize("hidden,seed", [("scale_asymmetry", 433000), ("quadratic", 483004)])
def test_p1_input_effect_is_not_named_beside_its_rival_untied(tmp_path, capsys, hidden, seed):
    """A quadratic term or a scale asymmetry at 10σ in a P1 capture the generator draws
    (9–30 positions, labelled or not, or a table of averages): ``D f²`` and ``A min(f, 0)``
    per axis are 0.8–1.0 correlated there, so the other one may be named only as confused
    with the hidden one, never beside it or instead of it on its own. (Seed 433000 named
    ``quadratic`` alone for a scale asymmetry before the head-to-head comparison.)"""
    rival = next(x for x in ("quadratic", "scale_asymmetry") if x != hidden)
    res = _diagnose_generated(tmp_path, capsys, "accel-tabletop", hidden, seed)
    assert hidden in res["verdict"], (hidden, res["verdict"], res["candidates"])
    assert rival not in res["verdict"] or rival in G.tied_names(res, hidden), (hidden, res["verdict"], res["effects"])


@pytest.mark.parametrize("hidden,seed", [("scale_asymmetry", 463001), ("quadratic", 483003)])
def test_p1_input_effect_named_from_few_unlabelled_positions(tmp_path, capsys, hidden, seed):
    """A scale asymmetry or a quadratic term at 10σ in a P1 time series of 11–12 unlabelled
    positions the generator draws: with a whole position held out the model with the effect
    has more parameters than the positions left, so its held-out prediction extrapolates
    (held-out RMS 50–400 times the baseline's) and the effect was not named at all. Validated
    on held-out parts of every hold, it is named, alone or with its rival tied to it."""
    res = _diagnose_generated(tmp_path, capsys, "accel-tabletop", hidden, seed)
    assert hidden in res["verdict"], (hidden, res["verdict"], res["candidates"])
    assert set(res["verdict"]) <= G.tied_names(res, hidden), (hidden, res["verdict"], res["effects"])


def test_p4_drift_with_wander_is_not_replaced_by_a_step_untied(tmp_path, capsys):
    """A time drift at 10σ in an 11-minute static gyro record whose bias wanders (τ ≈ 90 s):
    a bias step (0.86 correlated with a line) fits the wander a little better, by less than
    the decisive margin once its place is counted, so the drift is named with the step tied
    to it. (Seed 442000 named only ``residual:time`` before.)"""
    res = _diagnose_generated(tmp_path, capsys, "gyro-drift", "time_drift", 442000)
    assert "time_drift" in res["verdict"], (res["verdict"], res["candidates"])
    assert set(res["verdict"]) <= G.tied_names(res, "time_drift"), (res["verdict"], res["effects"])


def test_p1_bias_step_displaces_the_drift_that_stood_in_for_it(tmp_path, capsys):
    """A bias step at 10σ in a P1 capture the generator draws (unlabelled, 23 positions): a
    line is 0.87 correlated with a step, so ``time_drift`` is selected first and holds most
    of it; the step beside the drift still explains a quarter of it, the drift beside the
    step nothing, and the step is named as ``residual:time`` at its place. (Seed 501002 named
    only ``time_drift`` while the step had to pass beside the drift at ``F·χ²_k``.) The step's
    place is read here from the generator's noise-free output and never passed on."""
    res = _diagnose_generated(tmp_path, capsys, "accel-tabletop", "bias_step", 501002)
    assert "residual:time" in res["verdict"], (res["verdict"], res["candidates"])
    e = next(e for e in res["effects"] if e["name"] == "residual:time")
    sc = G.scenario_for("accel-tabletop", np.random.default_rng(501002), "bias_step")  # as it was drawn
    size, _ = G.size_for(sc, "bias_step", 10.0)
    jump = G.tabletop_render(sc, "bias_step", size, noise=False).raw - G.tabletop_render(sc, noise=False).raw
    t = np.arange(len(jump)) / sc["rate"]
    t_step = t[np.argmax(np.abs(jump).sum(axis=1) > 0)]
    assert e["shape"] == "step" and abs(e["params"]["at"] - t_step) < 0.05 * t[-1], (e["params"]["at"], t_step)


@pytest.mark.parametrize("seed", [513002, 513011])
def test_ldv_scale_in_temperature_named_against_the_bias_it_resembles(tmp_path, capsys, seed):
    """A scale factor linear in temperature at 10σ in an LDV drive the generator draws (a
    warm-up and a random walk of the temperature, nearly steady speed): it is 0.94–0.97
    correlated with a bias in temperature (and, in the warm-up, with a drift in time), fits
    better than either by 2–3 in BIC, and is one fixed basis, compared head to head as a
    library candidate is. So ``residual:temperature`` (the scale) is named, the bias at most
    tied to it. (Both seeds named ``temperature_bias`` alone while the generic term had to fit
    better by 3.84 and pass beside the bias; 513002's drift, 8 worse in BIC, ruled it out.)"""
    res = _diagnose_generated(tmp_path, capsys, "ldv", "temp_scale", seed)
    assert "residual:temperature" in res["verdict"], (res["verdict"], res["candidates"])
    e = next(e for e in res["effects"] if e["name"] == "residual:temperature")
    assert e["shape"] == "linear" and e["params"].get("acts_on") == "scale", e
    assert set(res["verdict"]) <= G.tied_names(res, "residual:temperature"), (res["verdict"], res["effects"])


def _linear_problem(rng, corr, sep, n=120):
    """``y = X b + a x_a + noise``: two candidates of one column each, ``a`` hidden, their
    columns (off the baseline) correlated by ``corr``, ``a`` sized so that its part outside
    ``x_b`` is ``sep`` noise σ."""
    X = np.column_stack([np.ones(n), np.linspace(-1, 1, n)])
    Q, _ = np.linalg.qr(X)
    u = rng.normal(size=(n, 2))
    u -= Q @ (Q.T @ u)
    ea = u[:, 0] / np.linalg.norm(u[:, 0])
    w = u[:, 1] - ea * (ea @ u[:, 1])
    w /= np.linalg.norm(w)
    xa, xb = ea, corr * ea + math.sqrt(1 - corr**2) * w
    amp = sep / math.sqrt(1 - corr**2)
    y = X @ np.array([0.3, -0.2]) + amp * xa + rng.normal(size=n)

    def residual(p):
        return X @ p["b"] + p.get("ca", 0.0) * xa + p.get("cb", 0.0) * xb - y

    cands = [Candidate("a", {"ca": np.array(0.0)}), Candidate("b", {"cb": np.array(0.0)})]
    return Problem("t", "y = X b", residual, np.ones(n), np.arange(n) % 10, {"b": np.zeros(2)}, {"b": True}, cands, 1.0)


def test_rival_named_instead_at_most_as_often_as_the_margin_allows():
    """The hidden effect's rival (columns 0.9 correlated) is named alone, or beside it untied,
    no more often than a wrong decision past the decisive margin allows (Φ(−√margin) per
    capture, with a binomial allowance), at separations from 1σ to 6σ."""
    rng = np.random.default_rng(400123)
    trials, wrong, tied_or_right = 0, 0, 0
    for sep in (1.0, 2.0, 3.0, 4.0, 6.0):
        for _ in range(40):
            prob = _linear_problem(rng, 0.9, sep)
            d = diagnose(prob)
            trials += 1
            names = {e["name"]: {c["name"] for c in e["confused_with"]} for e in d.effects}
            if "b" in names and "a" not in names.get("b", set()):
                wrong += 1
            elif "a" in names or any("a" in v for v in names.values()):
                tied_or_right += 1
            assert not ("a" in names and "b" in names), names  # never both named on their own
    p = norm.sf(math.sqrt(decisive_margin(prob)))
    assert wrong <= trials * p + 3 * math.sqrt(trials * p * (1 - p)) + 1, (wrong, trials, p)
    assert tied_or_right > trials / 2


def _linear_problem_k(rng, k, corr, amp, n=120):
    """``y = X b + amp·a₁ + noise``: two candidates of k columns each, ``a`` hidden along its
    first column, whose fitted signature the first column of ``b`` shares by ``corr``; their
    other k − 1 columns are unrelated directions (all off the baseline)."""
    X = np.column_stack([np.ones(n), np.linspace(-1, 1, n)])
    Q, _ = np.linalg.qr(X)
    u = rng.normal(size=(n, 2 * k))
    u -= Q @ (Q.T @ u)
    U, _ = np.linalg.qr(u)
    xa = U[:, :k]
    xb = np.column_stack([corr * U[:, 0] + math.sqrt(1 - corr**2) * U[:, k], U[:, k + 1 :]])
    y = X @ np.array([0.3, -0.2]) + amp * xa[:, 0] + rng.normal(size=n)

    def residual(p):
        return X @ p["b"] + xa @ p.get("ca", np.zeros(k)) + xb @ p.get("cb", np.zeros(k)) - y

    cands = [Candidate("a", {"ca": np.zeros(k)}), Candidate("b", {"cb": np.zeros(k)})]
    return Problem("t", "y = X b", residual, np.ones(n), np.arange(n) % 10, {"b": np.zeros(2)}, {"b": True}, cands, 1.0)


def _rival_counts(problems) -> tuple[int, int, int]:
    """(captures, rival ``b`` named without ``a`` tied to it, ``a`` named or tied) over ``problems``."""
    trials = wrong = right = 0
    for prob in problems:
        d = diagnose(prob)
        trials += 1
        names = {e["name"]: {c["name"] for c in e["confused_with"]} for e in d.effects}
        assert not ("a" in names and "b" in names), names  # never both named on their own
        if "b" in names and "a" not in names["b"]:
            wrong += 1
        elif "a" in names or any("a" in v for v in names.values()):
            right += 1
    return trials, wrong, right


def _serial_problem(rng, corr, amp, n=240, phi=0.9):
    """``y = X b + amp·a + noise`` in one time series with AR(1) noise (φ = ``phi``): ``a`` a slow
    signature, its rival ``b`` ``corr`` of it plus an alternating part (fast, so it picks up
    less of the slow noise and its deviance's serial-correlation inflation is smaller)."""
    t = np.linspace(-1, 1, n)
    X = np.column_stack([np.ones(n), t])
    Q, _ = np.linalg.qr(X)
    slow = np.sin(1.5 * np.pi * t + rng.uniform(0, 2 * np.pi))
    fast = np.where(np.arange(n) % 2 == 0, 1.0, -1.0) * rng.choice([-1.0, 1.0], size=n)
    cols = np.column_stack([slow, fast])
    cols -= Q @ (Q.T @ cols)
    xa = cols[:, 0] / np.linalg.norm(cols[:, 0])
    w = cols[:, 1] - xa * (xa @ cols[:, 1])
    xb = corr * xa + math.sqrt(1 - corr**2) * w / np.linalg.norm(w)
    noise = lfilter([1.0], [1.0, -phi], rng.normal(size=n)) * math.sqrt(1 - phi**2)
    y = X @ np.array([0.3, -0.2]) + amp * xa + noise

    def residual(p):
        return X @ p["b"] + p.get("ca", 0.0) * xa + p.get("cb", 0.0) * xb - y

    cands = [Candidate("a", {"ca": np.array(0.0)}), Candidate("b", {"cb": np.array(0.0)})]
    prob = Problem(
        "t", "y = X b", residual, np.ones(n), np.arange(n) * 10 // n, {"b": np.zeros(2)}, {"b": True}, cands, 1.0
    )
    prob.time_ordered = True
    prob.series = np.zeros(n, int)
    return prob


def test_rivals_compared_on_one_noise_scale():
    """A slow effect hidden at 20σ and 40σ in a series with slowly correlated noise, its rival
    0.9–0.95 of it plus a fast part: each deviance alone is taken net of its own serial
    correlation, the rival's less (its fast part picks up little of the slow noise), but the
    two explain the same structure and are compared on one noise scale. The rival is named
    instead no more often than a wrong decision past the margin allows; with each deviance
    net of its own inflation it won in about 25 % of captures, more often the larger the effect."""
    rng = np.random.default_rng(400500)
    probs = (_serial_problem(rng, corr, amp) for corr in (0.9, 0.95) for amp in (20.0, 40.0) for _ in range(40))
    trials, wrong, right = _rival_counts(probs)
    p = norm.sf(math.sqrt(decisive_margin(_serial_problem(rng, 0.9, 1.0))))
    assert wrong <= trials * p + 3 * math.sqrt(trials * p * (1 - p)) + 1, (wrong, trials, p)
    assert right >= trials - wrong - 3, (right, wrong, trials)


def test_k_parameter_rival_named_instead_at_most_at_the_level():
    """A 5-parameter effect hidden at 10σ along one of its columns, its rival's first column
    0.99–0.999 correlated with it (0.4–1.4σ apart) and its other four columns unrelated: the
    rival fits the noise along its own other directions and the hidden one along its own, so
    the two deviances differ by a difference of χ²₄-like parts whatever the signal. The rival
    is named instead no more often than α (binomial allowance); with a one-signature margin
    (``F·χ²₁``) it was, in about 12 % of captures."""
    rng = np.random.default_rng(400321)
    probs = (_linear_problem_k(rng, 5, corr, 10.0) for corr in (0.99, 0.995, 0.999) for _ in range(60))
    trials, wrong, right = _rival_counts(probs)
    p = 0.05
    assert wrong <= trials * p + 3 * math.sqrt(trials * p * (1 - p)), (wrong, trials)
    assert right >= trials - wrong - 3, (right, wrong, trials)
