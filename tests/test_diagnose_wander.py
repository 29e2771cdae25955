"""The slow-noise model of time-ordered rows (``solvers.diagnose.wander``): white noise plus a
first-order Gauss–Markov wander, fitted by REML, and the likelihood ratio of a candidate with
the wander profiled out.

Data: unit white noise on 300 rows 2 s apart (a 600 s record), plus a Gauss–Markov series of
variance λ and correlation time τ drawn here by its exact discretisation; a line in time is the
candidate. Known answers: the generalised-least-squares variance of the line's slope under the
true covariance (computed here from it), so a line sized at 10σ of that variance must be found,
and a wander alone must not be read as a line."""

from __future__ import annotations

import numpy as np
import pytest

from solvers.diagnose.wander import EVIDENT_LR, WanderModel

N = 300
T_S = np.arange(N) * 2.0
ONE = np.ones((N, 1))
LINE = ((T_S - T_S.mean()) / T_S.std())[:, None]
SEEDS = range(8)


def gauss_markov(rng, tau_s):
    x = np.empty(N)
    x[0] = rng.standard_normal()
    a = np.exp(-np.diff(T_S) / tau_s)
    for i in range(1, N):
        x[i] = a[i - 1] * x[i - 1] + np.sqrt(1 - a[i - 1] ** 2) * rng.standard_normal()
    return x


def record(seed, lam, tau_s, slope=0.0):
    rng = np.random.default_rng(seed)
    y = rng.standard_normal(N) + slope * LINE[:, 0]
    return y + np.sqrt(lam) * gauss_markov(rng, tau_s) if lam > 0 else y


def residual(X, y):
    return y - X @ np.linalg.lstsq(X, y, rcond=None)[0]


def line_tests(y, wm):
    """(white-noise deviance, profiled likelihood ratio, whether the line's residual wanders) of
    the line beside a constant."""
    e0, e1 = residual(ONE, y), residual(np.hstack([ONE, LINE]), y)
    return (N * np.log((e0 @ e0) / (e1 @ e1)), *wm.lr(ONE, LINE, e0, e1, {}))


def gls_slope_sd(lam, tau_s):
    C = np.eye(N) + lam * np.exp(-np.abs(T_S[:, None] - T_S[None, :]) / tau_s)
    Z = np.hstack([ONE, LINE])
    return float(np.sqrt(np.linalg.inv(Z.T @ np.linalg.solve(C, Z))[1, 1]))


@pytest.fixture(scope="module")
def wm():
    return WanderModel(T_S, np.zeros(N, int), np.ones(N))


def test_white_noise_shows_no_wander_and_keeps_the_white_deviance(wm):
    for seed in SEEDS:
        y = record(seed, 0.0, 1.0, slope=0.3)
        both = np.hstack([ONE, LINE])
        assert wm.fit(both, residual(both, y))[0][3] < EVIDENT_LR  # the line's own residual is white
        D, _, wanders = line_tests(y, wm)
        assert D > 5 and not wanders  # the line is tested as before, against white noise


def test_a_wander_is_seen_and_its_correlation_time_measured(wm):
    fits = [wm.fit(ONE, residual(ONE, record(seed, 1.0, 60.0)))[0] for seed in SEEDS]
    assert all(f[3] > EVIDENT_LR for f in fits)
    assert 20 < np.median([f[1] for f in fits]) < 200
    assert 0.3 < np.median([f[0] for f in fits]) < 3.0


def test_a_wander_alone_is_not_a_line(wm):
    D, T, wanders = zip(*(line_tests(record(seed, 1.0, 60.0), wm) for seed in SEEDS))
    assert np.mean(D) > 20  # against white noise, the wander looks like a drift
    assert all(wanders)
    assert np.mean(T) < 4 and max(T) < 10.8  # χ²₁: mean 1, 0.1 % above 10.8


def test_a_line_at_ten_sigma_of_the_true_covariance_is_found(wm):
    slope = 10 * gls_slope_sd(1.0, 60.0)
    T = [line_tests(record(100 + seed, 1.0, 60.0, slope), wm)[1:] for seed in SEEDS]
    assert sum(wanders and t > 10.8 for t, wanders in T) >= 7, T


def test_a_drawn_wander_has_the_model_s_variance_and_correlation(wm):
    (part,) = wm.parts
    x = part.draw(60.0, np.random.default_rng(0), 4000)  # rows × draws
    assert abs(np.var(x) - 1.0) < 0.05
    lag1 = np.mean(x[1:] * x[:-1]) / np.mean(x * x)
    assert abs(lag1 - np.exp(-2.0 / 60.0)) < 0.01  # rows 2 s apart


def test_on_white_noise_the_calibration_leaves_the_ratio_as_it_is(wm):
    """White noise fitted beside the line: the draws give the χ²₁ of the white-noise test, and a
    statistic keeps its own tail probability."""
    from solvers.diagnose.engine import _null_equivalent, chi2_isf

    y = record(7, 0.0, 1.0)
    null = wm.null_lr(ONE, LINE, residual(np.hstack([ONE, LINE]), y), 400)
    assert 0.7 < np.mean(null) < 1.4
    for p in (0.05, 0.01, 0.001):
        T = chi2_isf(p, 1)
        assert 0.6 * T < _null_equivalent(T, null, 1) < 1.6 * T


def calibrated(y, wm):
    from solvers.diagnose.engine import _null_equivalent

    e0, e1 = residual(ONE, y), residual(np.hstack([ONE, LINE]), y)
    T, _ = wm.lr(ONE, LINE, e0, e1, {}, baseline=True)
    return T, min(T, _null_equivalent(T, wm.null_lr(ONE, LINE, e1, 100), 1))


def test_a_wander_of_half_the_record_is_calibrated_and_a_line_at_ten_sigma_still_found(wm):
    """τ = 300 s in a 600 s record: the profiled ratio of a line on the wander alone is larger
    than χ²₁'s (the wander's few independent stretches), the draws bring it back; a line at 10σ
    of the true covariance stays far above the tail."""
    nulls = [calibrated(record(300 + seed, 1.0, 300.0), wm) for seed in range(12)]
    assert max(c for _, c in nulls) < 10.8  # χ²₁ above 10.8: 0.1 %
    assert all(c <= T for T, c in nulls)
    slope = 10 * gls_slope_sd(1.0, 300.0)
    found = [calibrated(record(400 + seed, 1.0, 300.0, slope), wm)[1] > 10.8 for seed in range(12)]
    assert sum(found) >= 8, found


def test_a_wander_longer_than_the_record_is_drawn_white(wm):
    """Correlated over more than the record, the wander left beside a line is a drift over it: the
    draws are white noise's, and the line keeps its white-noise tail."""
    y = record(11, 25.0, 20000.0) + 0.5 * (LINE[:, 0] ** 2)  # a curve in time the line leaves
    e1 = residual(np.hstack([ONE, LINE]), y)
    (fit,) = wm.fit(np.hstack([ONE, LINE]), e1)
    assert fit[1] >= T_S[-1] - T_S[0] and fit[3] > EVIDENT_LR
    assert np.mean(wm.null_lr(ONE, LINE, e1, 200)) < 1.5
