"""A slow wander of a vector (``solvers.diagnose.wander`` with ``directions``): a compass's hard
iron that creeps in the magnetometer's frame reaches each magnitude row along that row's field
direction, so the rows of a turning unit see different components of one wander.

Data: 600 rows 0.2 s apart (a 120 s tumble), each with its own unit direction (a random walk on
the sphere, as a hand turns the unit), unit white noise plus ``d_i · x(t_i)`` with ``x`` three
independent Gauss–Markov series of variance λ and correlation time τ, drawn here by their exact
discretisation. Known answers: λ and τ as drawn; white noise shows no wander."""

from __future__ import annotations

import numpy as np

from solvers.diagnose.wander import EVIDENT_LR, WanderModel

N = 600
T_S = np.arange(N) * 0.2


def directions(rng) -> np.ndarray:
    v = np.cumsum(rng.normal(scale=0.15, size=(N, 3)), axis=0) + rng.normal(size=3)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def vector_gm(rng, tau_s) -> np.ndarray:
    x = np.empty((N, 3))
    x[0] = rng.standard_normal(3)
    a = np.exp(-np.diff(T_S) / tau_s)
    for i in range(1, N):
        x[i] = a[i - 1] * x[i - 1] + np.sqrt(1 - a[i - 1] ** 2) * rng.standard_normal(3)
    return x


def fit(y, d):
    wm = WanderModel(T_S, np.zeros(N, int), np.ones(N), d)
    ((lam, tau, s2, lr),) = wm.fit(np.ones((N, 1)), y - y.mean())
    return lam * s2, tau, lr


def test_a_vector_wander_along_the_rows_directions_is_fitted_with_its_size_and_time():
    """λ = 4 (the wander twice the white noise along a row), τ = 10 s: over 4 records the REML
    fit finds it every time, its variance within a factor 2 of the truth and τ within 3."""
    for seed in range(4):
        rng = np.random.default_rng(seed)
        d = directions(rng)
        y = rng.standard_normal(N) + 2.0 * np.sum(d * vector_gm(rng, 10.0), axis=1)
        var, tau, lr = fit(y, d)
        assert lr > EVIDENT_LR, (seed, lr)
        assert 2.0 < var < 8.0, (seed, var)
        assert 10.0 / 3 < tau < 30.0, (seed, tau)


def test_white_noise_on_turning_rows_shows_no_wander():
    for seed in range(4):
        rng = np.random.default_rng(100 + seed)
        d = directions(rng)
        _, _, lr = fit(rng.standard_normal(N), d)
        assert lr < EVIDENT_LR, (seed, lr)
