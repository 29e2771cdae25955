"""The fitting engine: estimates, covariance, identifiability, gauge and misfit."""

from __future__ import annotations

import numpy as np
import pytest

from solvers.fit import fit, linear_fit
from solvers.frames import rotvec_to_matrix


def test_linear_fit_matches_textbook_covariance():
    rng = np.random.default_rng(0)
    H = np.column_stack([np.ones(50), np.linspace(-1, 1, 50)])
    y = H @ [2.0, -3.0] + rng.normal(scale=0.1, size=50)
    res = linear_fit(H, y, sigma=0.1, names=["a", "b"])
    cov = 0.01 * np.linalg.inv(H.T @ H)
    np.testing.assert_allclose(res.cov, cov, rtol=1e-6, atol=1e-15)
    assert res.success and res.unidentifiable == []
    assert res.condition_number < 10


def test_nonlinear_recovery_coverage_over_seeds():
    """y = A exp(−k t): truth within 1σ ~68 % and 2σ ~95 % of 400 seeded trials."""
    t = np.linspace(0, 5, 40)
    inside1 = inside2 = 0
    trials = 400
    for seed in range(trials):
        rng = np.random.default_rng(seed)
        y = 3.0 * np.exp(-0.7 * t) + rng.normal(scale=0.05, size=t.size)
        res = fit(lambda p: p["A"] * np.exp(-p["k"] * t) - y, {"A": 2.0, "k": 1.0}, sigma=0.05)  # noqa: B023
        z = abs(float(res.params["k"]) - 0.7) / float(res.sigma["k"])
        inside1 += z < 1
        inside2 += z < 2
    # binomial 3-sigma bands around 0.683 and 0.954 for 400 trials
    assert abs(inside1 / trials - 0.683) < 3 * np.sqrt(0.683 * 0.317 / trials)
    assert abs(inside2 / trials - 0.954) < 3 * np.sqrt(0.954 * 0.046 / trials) + 0.005


def test_unidentifiable_parameters_are_named_not_noise():
    t = np.linspace(0, 1, 30)
    y = 2.0 * t + 1.0
    # a and c enter only as their sum: one direction the data cannot see
    res = fit(lambda p: (p["a"] + p["c"]) + p["b"] * t - y, {"a": 0.3, "b": 0.0, "c": 0.1}, sigma=0.01)
    assert set(res.unidentifiable) == {"a", "c"}
    assert np.isnan(res.sigma["a"]) and np.isnan(res.sigma["c"])
    assert np.isfinite(res.sigma["b"]) and res.params["b"] == pytest.approx(2.0)
    assert len(res.null_space) == 1 and set(res.null_space[0]) == {"a", "c"}
    assert res.condition_number == np.inf


def test_norm_condition_gauge_is_reported_then_fixed():
    """|B + M V| = g cannot see a rotation of (B, M): free M has a 3-dim null space;
    an upper-triangular M (imu_tk's gauge) removes it."""
    rng = np.random.default_rng(1)
    M_true = np.eye(3) + np.triu(0.02 * rng.normal(size=(3, 3)))
    B_true = np.array([0.1, -0.2, 0.05])
    dirs = rng.normal(size=(30, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    A = 9.8 * dirs
    V = np.linalg.solve(M_true, (A - B_true).T).T

    def resid(p):
        return np.linalg.norm(p["B"] + V @ p["M"].T, axis=1) - 9.8

    start = {"B": np.zeros(3), "M": np.eye(3)}
    full = fit(resid, start, sigma=1e-3)
    assert len(full.null_space) == 3
    assert any(n.startswith("M[") for n in full.unidentifiable)
    tri = fit(resid, start, free={"B": True, "M": np.triu(np.ones((3, 3), dtype=bool))}, sigma=1e-3)
    assert tri.null_space == [] and tri.unidentifiable == []
    np.testing.assert_allclose(tri.params["M"], M_true, atol=1e-8)
    np.testing.assert_allclose(tri.params["B"], B_true, atol=1e-8)
    # and the rotated pair fits just as well: the gauge really is a rotation
    R = rotvec_to_matrix([0.01, -0.02, 0.03])
    assert np.max(np.abs(resid({"B": R @ B_true, "M": R @ M_true}))) < 1e-9


def test_misfit_inflates_uncertainty_and_honest_fit_does_not():
    rng = np.random.default_rng(2)
    x = np.linspace(-1, 1, 200)
    y_ok = 1.0 + 2.0 * x + rng.normal(scale=0.01, size=x.size)
    y_bad = y_ok + 0.2 * x**2  # an unmodelled curvature
    ok = linear_fit(np.column_stack([np.ones_like(x), x]), y_ok, sigma=0.01)
    bad = linear_fit(np.column_stack([np.ones_like(x), x]), y_bad, sigma=0.01)
    assert not ok.misfit_scaled and ok.reduced_chi2 == pytest.approx(1.0, abs=0.3)
    assert bad.misfit_scaled and bad.reduced_chi2 > 10
    assert bad.sigma["x"][0] > 3 * ok.sigma["x"][0]


def test_fixed_blocks_stay_and_report_zero_sigma():
    x = np.linspace(0, 1, 20)
    res = fit(lambda p: p["a"] * x + p["b"] - (2 * x + 1), {"a": 0.0, "b": 1.0}, free={"a": True}, sigma=0.1)
    assert float(res.params["b"]) == 1.0 and float(res.sigma["b"]) == 0.0
    assert res.names == ["a"]


def test_non_finite_start_is_refused():
    with pytest.raises(ValueError, match="not finite"):
        fit(lambda p: np.array([np.nan, 1.0]), {"a": 1.0})
