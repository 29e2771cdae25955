"""``engine.slow_prior_lr``: a candidate's likelihood ratio under the rows' noise with a known
slow part, ``diag(σ²) + slow_cov``, against the generalised least squares written out with the
explicit inverse of that covariance (the textbook estimator, not the Cholesky whitening)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from solvers.diagnose.engine import Problem, slow_prior_lr


def _case(rng, n=60):
    t = np.sort(rng.uniform(0.0, 600.0, n))
    sigma = rng.uniform(0.5, 2.0, n)
    u = rng.normal(size=n)
    slow = np.exp(-np.abs(t[:, None] - t[None, :]) / 180.0) * np.outer(u, u) * 0.8
    A = rng.normal(size=(n, 4))
    J = np.column_stack([t / 600.0, (t / 600.0) ** 2])
    r0 = rng.normal(size=n) + 0.3 * J[:, 0]
    prob = Problem("p", "", lambda p: r0, sigma, np.arange(n), {}, {}, [], 1.0)
    prob.slow_cov = slow
    return prob, A, J, r0


def _gls_resid(Cinv, X, y):
    """The weighted residual r0 + X δ at the GLS minimum of (r0 + X δ)ᵀ C⁻¹ (r0 + X δ)."""
    d = np.linalg.solve(X.T @ Cinv @ X, -X.T @ Cinv @ y)
    return y + X @ d


def test_slow_prior_lr_is_the_gls_likelihood_ratio():
    prob, A, J, r0 = _case(np.random.default_rng(1))
    C = np.eye(r0.size) + prob.slow_cov / np.outer(prob.sigma, prob.sigma)
    Ci = np.linalg.inv(C)
    e0, e1 = _gls_resid(Ci, A, r0), _gls_resid(Ci, np.hstack([A, J]), r0)
    want = r0.size * math.log((e0 @ Ci @ e0) / (e1 @ Ci @ e1))
    assert slow_prior_lr(prob, A, J, r0) == pytest.approx(want, rel=1e-9)


def test_slow_prior_lr_with_a_noise_scale_per_row_kind():
    """Two kinds of rows (P1: sub-hold norm rows with the prior, direction rows without): the
    ratio is summed per kind, each with its own scale, as the deviance (``typed_fit_term``)."""
    prob, A, J, r0 = _case(np.random.default_rng(2))
    kind = (np.arange(r0.size) % 3 == 0).astype(int)
    prob.row_types = kind
    prob.slow_cov = np.where(np.equal.outer(kind, kind) & (kind == 0)[:, None], prob.slow_cov, 0.0)
    C = np.eye(r0.size) + prob.slow_cov / np.outer(prob.sigma, prob.sigma)
    Ci = np.linalg.inv(C)
    e0, e1 = _gls_resid(Ci, A, r0), _gls_resid(Ci, np.hstack([A, J]), r0)
    want = 0.0
    for k in (0, 1):
        s = kind == k
        Cki = np.linalg.inv(C[np.ix_(s, s)])
        want += s.sum() * math.log((e0[s] @ Cki @ e0[s]) / (e1[s] @ Cki @ e1[s]))
    assert slow_prior_lr(prob, A, J, r0) == pytest.approx(want, rel=1e-9)


def test_slow_prior_lr_follows_sigma_changed_in_place():
    """The Cholesky factor is kept between candidates; σ changed in place (same array, same sum,
    two rows swapped) is another noise and gets its own factor (it was keyed by the array's
    address and sum, and the first factor was used again)."""
    prob, A, J, r0 = _case(np.random.default_rng(3))
    slow_prior_lr(prob, A, J, r0)
    i, j = int(np.argmin(prob.sigma)), int(np.argmax(prob.sigma))
    prob.sigma[[i, j]] = prob.sigma[[j, i]]
    fresh = Problem("p", "", lambda p: r0, prob.sigma.copy(), np.arange(r0.size), {}, {}, [], 1.0)
    fresh.slow_cov = prob.slow_cov
    assert slow_prior_lr(prob, A, J, r0) == pytest.approx(slow_prior_lr(fresh, A, J, r0), rel=1e-12)
