"""Allan deviation and the standard error of a mean under correlated noise.

Overlapping Allan deviation of a *rate* series ``y`` sampled every ``dt_s`` seconds
(IEEE Std 952, Eq. for the overlapping estimator), computed from the cumulative sum
(the "phase" ``x_k = dt Σ y``)::

    σ²(τ) = 1 / (2 τ² (N − 2m)) Σ_{k} (x_{k+2m} − 2 x_{k+m} + x_k)²,   τ = m dt

It matches ``allantools.oadev(y, rate=1/dt, data_type='freq')`` (tests check it).

Standard error of the mean of a record of length ``T``: for white noise
``σ_mean = ADEV(τ) sqrt(τ / T)`` at every τ. With correlated noise (bias instability,
flicker, random walk) ``ADEV(τ) sqrt(τ/T)`` grows with τ. :func:`mean_standard_error`
reports the largest of: the white ``σ / sqrt(n)``; the maximum of ``ADEV(τ) sqrt(τ/T)``
over half-octave-spaced τ up to ``T / 3`` (the longest τ with a usable estimate); and the
Allan deviation *at the record length*, ``ADEV(T)``, extrapolated by a fitted noise model
(white + flat floor + rate random walk, :func:`fit_noise_model`). That is the 1-sigma the
gyro drift reports, and the figure to compare with the accuracy asked.

Limit: noise correlated on the scale of the record itself (a Gauss-Markov bias with
correlation time ~T/3) is partly invisible in any record of length T; there the reported
error is short by up to ~1.4x (tests/test_allan.py measures the coverage).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "oadev",
    "octave_taus",
    "mean_standard_error",
    "MeanError",
    "time_needed_s",
    "noise_fit",
    "NoiseFit",
    "white_random_walk",
]


def octave_taus(n: int, dt_s: float, max_fraction: float = 0.25, per_octave: int = 1) -> np.ndarray:
    """Cluster sizes 1, 2, 4, ... (``per_octave`` steps per octave) up to ``max_fraction * n``
    samples, and that top size itself, as τ in seconds."""
    top = max(1, int(n * max_fraction))
    m = np.rint(2.0 ** (np.arange(0, int(per_octave * math.log2(top)) + 1) / per_octave)).astype(int)
    m = np.unique(np.append(m[m <= top], top))
    return m.astype(float) * dt_s


def oadev(y, dt_s: float, taus_s=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Overlapping Allan deviation of rate samples ``y`` (N,) or (N, k).

    Returns ``(taus_s, adev, n_terms)``; ``adev`` has shape (len(taus), k) for 2-D input.
    τ values that are not whole multiples of ``dt_s`` are rounded to the nearest; τ with
    fewer than one term (2m ≥ N) are dropped.
    """
    y = np.asarray(y, dtype=float)
    one_d = y.ndim == 1
    Y = y[:, None] if one_d else y
    n = Y.shape[0]
    if taus_s is None:
        taus_s = octave_taus(n, dt_s, 0.5)
    m = np.unique(np.maximum(1, np.rint(np.asarray(taus_s, dtype=float) / dt_s).astype(int)))
    m = m[2 * m < n]
    x = np.vstack([np.zeros((1, Y.shape[1])), np.cumsum(Y, axis=0) * dt_s])
    out = np.empty((len(m), Y.shape[1]))
    terms = np.empty(len(m), dtype=int)
    for i, mi in enumerate(m):
        d = x[2 * mi :] - 2.0 * x[mi:-mi] + x[: -2 * mi]
        tau = mi * dt_s
        out[i] = np.sqrt(np.sum(d * d, axis=0) / (2.0 * tau * tau * d.shape[0]))
        terms[i] = d.shape[0]
    taus = m * dt_s
    return taus, (out[:, 0] if one_d else out), terms


@dataclass
class MeanError:
    """The mean of a rate record and its 1-sigma standard error (per axis)."""

    mean: np.ndarray  # (k,)
    se: np.ndarray  # (k,) the reported 1-sigma: max(white, Allan-based)
    se_white: np.ndarray  # σ / sqrt(n), what uncorrelated noise alone would give
    tau_at_max_s: np.ndarray  # τ where ADEV(τ) sqrt(τ/T) peaked
    duration_s: float
    taus_s: np.ndarray
    adev: np.ndarray  # (len(taus), k)
    noise_model: np.ndarray | None = None  # (k, 3): AVAR(τ) = c0/τ + c1 + c2 τ, per axis
    se_model: np.ndarray | None = None  # sqrt(c0/T + c1 + c2 T), the model at τ = T


def fit_noise_model(taus_s, adev, terms, dt_s: float) -> np.ndarray:
    """Non-negative fit ``AVAR(τ) = c0/τ + c1 + c2 τ`` (white rate noise ``N² = c0``, a flat
    bias-instability floor ``c1``, rate random walk ``K² = 3 c2``), each point weighted by
    its relative precision ``sqrt(terms / m)`` (Allan-variance estimates at large τ are
    poor). Returns (k, 3) coefficients."""
    from scipy.optimize import nnls

    t = np.asarray(taus_s, dtype=float)
    a = np.atleast_2d(np.asarray(adev, dtype=float).T).T if np.ndim(adev) == 1 else np.asarray(adev, dtype=float)
    m = np.maximum(np.rint(t / dt_s), 1.0)
    out = np.zeros((a.shape[1], 3))
    for k in range(a.shape[1]):
        av = a[:, k] ** 2
        if not np.all(av > 0):
            continue
        w = np.sqrt(np.maximum(np.asarray(terms) / m, 1.0)) / av
        A = np.column_stack([1.0 / t, np.ones_like(t), t]) * w[:, None]
        out[k], _ = nnls(A, av * w)
    return out


def mean_standard_error(y, dt_s: float, max_fraction: float = 1.0 / 3.0) -> MeanError:
    """Mean of ``y`` (N,) or (N, k) and its standard error accounting for correlated
    noise: ``max(σ/sqrt(n), max_τ ADEV(τ) sqrt(τ/T))`` over τ ≤ ``max_fraction`` T."""
    y = np.asarray(y, dtype=float)
    Y = y[:, None] if y.ndim == 1 else y
    n = Y.shape[0]
    T = n * dt_s
    mean = Y.mean(axis=0)
    se_white = Y.std(axis=0, ddof=1) / math.sqrt(n) if n > 1 else np.full(Y.shape[1], np.inf)
    taus, adev, terms = oadev(Y, dt_s, octave_taus(n, dt_s, max_fraction, per_octave=2))
    model = se_model = None
    if len(taus) >= 3:
        model = fit_noise_model(taus, adev, terms, dt_s)
        se_model = np.sqrt(model[:, 0] / T + model[:, 1] + model[:, 2] * T)
    if len(taus):
        cand = adev * np.sqrt(taus / T)[:, None]
        imax = np.argmax(cand, axis=0)
        se_allan = cand[imax, np.arange(Y.shape[1])]
        tau_at = taus[imax]
    else:
        se_allan, tau_at = np.zeros(Y.shape[1]), np.zeros(Y.shape[1])
    se = np.maximum(se_white, se_allan)
    if se_model is not None:
        se = np.maximum(se, se_model)
    return MeanError(
        mean=mean,
        se=se,
        se_white=se_white,
        tau_at_max_s=tau_at,
        duration_s=T,
        taus_s=taus,
        adev=adev,
        noise_model=model,
        se_model=se_model,
    )


def hold_mean_se(seg, t_s) -> np.ndarray | None:
    """The standard error of a hold's mean, per column of ``seg`` (N, k), with correlated
    noise (bias instability) included: the larger of the white ``σ/sqrt(n)`` and the fitted
    noise model (white + bias instability + random walk) at the hold's length. ``t_s``: the
    rows' times (the step is their median difference); rows with a non-finite value are
    dropped. None when fewer than 16 rows are left or the times do not advance (then the
    caller falls back to ``σ/sqrt(n)``). P1 uses it for every position, the accelerometer's
    and the gyro's: std/sqrt(n) alone understates it when the bias wanders during the hold."""
    seg = np.asarray(seg, dtype=float)
    t_s = np.asarray(t_s, dtype=float)
    seg = seg[np.all(np.isfinite(seg), axis=1)]
    if len(seg) < 16 or len(t_s) < 2:
        return None
    dt = float(np.median(np.diff(t_s)))
    if not dt > 0:
        return None
    me = mean_standard_error(seg, dt)
    if me.se_model is None:
        return np.asarray(me.se_white, dtype=float)
    # the fitted model at the hold's length: the raw Allan maximum over a few τ of one short
    # hold scatters upward
    return np.maximum(np.asarray(me.se_white, dtype=float), np.asarray(me.se_model, dtype=float))


def white_density(holds) -> np.ndarray | None:
    """Per column, the white noise density N (unit · √s) of the samples within holds: the white
    term ``c0 = N²`` of the noise model :func:`mean_standard_error` fits (the one calibrate uses),
    the median over the holds. ``holds``: ``(samples (N, k), times (N,))`` per hold; rows with a
    non-finite value are dropped. None where no hold gives one (fewer than 16 rows, times that do
    not advance, no model fitted)."""
    c0 = []
    for seg, ts in holds:
        seg, ts = np.asarray(seg, dtype=float), np.asarray(ts, dtype=float)
        ok = np.all(np.isfinite(seg), axis=1)
        seg, ts = seg[ok], ts[ok]
        if len(seg) < 16:
            continue
        dt = float(np.median(np.diff(ts)))
        if not dt > 0:
            continue
        me = mean_standard_error(seg, dt)
        if me.noise_model is not None:
            c0.append(me.noise_model[:, 0])
    if not c0:
        return None
    return np.sqrt(np.median(np.array(c0), axis=0))


def time_needed_s(me: MeanError, accuracy: float) -> np.ndarray:
    """Record length for a 1-sigma of ``accuracy`` (same unit as the data), per axis.

    The larger of: the achieved error extrapolated as white (``∝ 1/sqrt(T)``), and the
    shortest ``T'`` with ``c0/T' + c1 + c2 T' <= accuracy²`` from the fitted noise model
    (``inf`` when the model's floor — bias instability, rate random walk — never gets
    there)."""
    need = me.duration_s * (np.asarray(me.se, dtype=float) / accuracy) ** 2
    if me.noise_model is None:
        return need
    a2 = accuracy**2
    out = need.copy()
    for k, (c0, c1, c2) in enumerate(me.noise_model):
        room = a2 - c1
        if room <= 0:
            out[k] = np.inf
        elif c2 <= 0:
            out[k] = max(need[k], c0 / room)
        else:
            disc = room * room - 4.0 * c2 * c0
            out[k] = np.inf if disc < 0 else max(need[k], (room - np.sqrt(disc)) / (2.0 * c2))
    return out


# --- noise parameters with their uncertainty (station noise, Kalibr's imu.yaml) -------------

BIAS_INSTABILITY_FACTOR = 0.664  # ADEV floor = sqrt(2 ln 2 / π) · B (IEEE 952, flicker rate noise)
CI_1SIGMA = 0.6826894921370859


@dataclass
class NoiseFit:
    """Allan analysis of a still record of rates ``y`` (N, k) in unit u (e.g. rad/s, m/s²).

    ``white`` N is the white-noise density (ADEV = N/√τ): u·√s = u/√Hz, Kalibr's
    ``*_noise_density``; ``random_walk`` K is the rate random walk (ADEV = K √(τ/3)): u/√s =
    u/s/√Hz, Kalibr's ``*_random_walk``. N and K are the maximum-likelihood estimates of
    Kalibr's discrete model (white noise plus a random walk of the bias) from the spectrum of
    the first differences (:func:`white_random_walk`); their 1-sigma comes from the same
    likelihood (N: its curvature; K: the larger side of the likelihood-ratio 68 % interval
    ``random_walk_lo``..``random_walk_hi``, which does not shrink with a low estimate).

    Why not the Allan fit: N and K used to come from a weighted fit of the Allan variance with a
    parametric-bootstrap sigma. Its K was biased low (mean 0.75 K, 1 record in 10 at K = 0, for
    300 s records of benchmarks/bench_noise.py) and the bootstrap, run at the low estimate, gave
    those records too small a sigma: rms((K̂ - K)/σ) was 2.6 / 2.3 / 1.8 at 300 / 600 / 1800 s.
    The likelihood estimate gives about 1.0 at each length (docs/benchmarks.md).

    ``bias_instability`` B = min ADEV / 0.664 (u) at ``bias_instability_tau_s``. ``model`` is the
    weighted non-negative fit ``AVAR = c0/τ + c1 + c2 τ`` of the Allan deviation (each point
    weighted by ``AVAR √(2/edf)``, edf from Greenhall's algorithm, allantools.edf_greenhall, for
    the noise that dominates at that τ); ``adev_lo``/``adev_hi``: 68 % confidence interval of
    each ADEV point (allantools.confidence_interval, chi-squared with that edf).
    ``random_walk_min_duration_s`` says how long a record K needs (callers warn).
    Bias instability (flicker) is not in Kalibr's model nor in this fit (its effect on K is not
    measured); the Allan curve and ``bias_instability`` show it.
    """

    taus_s: np.ndarray
    adev: np.ndarray  # (m, k)
    adev_lo: np.ndarray  # (m, k)
    adev_hi: np.ndarray  # (m, k)
    edf: np.ndarray  # (m, k)
    white: np.ndarray  # (k,)
    white_sigma: np.ndarray
    random_walk: np.ndarray
    random_walk_sigma: np.ndarray
    bias_instability: np.ndarray
    bias_instability_tau_s: np.ndarray
    model: np.ndarray  # (k, 3): AVAR = c0/τ + c1 + c2 τ
    duration_s: float
    n: int
    # record length for which K's sigma holds: the longest τ (T/3) at least 4x the τ where
    # white noise and random walk cross (√3 N / K); inf when K fits to 0
    random_walk_min_duration_s: np.ndarray | None = None
    random_walk_lo: np.ndarray | None = None  # 68 % likelihood-ratio interval of K
    random_walk_hi: np.ndarray | None = None


def _alpha(c, tau: float) -> int:
    """Frequency-noise exponent of the term that dominates AVAR at τ: white 0, flicker −1, random walk −2."""
    terms = (c[0] / tau, c[1], c[2] * tau)
    return (0, -1, -2)[int(np.argmax(terms))]


def _wls(A0, av, sd):
    from scipy.optimize import nnls

    c, _ = nnls(A0 / sd[:, None], av / sd)
    return c


TAPER_FRACTION = 0.1  # Tukey taper of the differences: 5 % cosine at each end


@dataclass
class WhiteRandomWalk:
    """:func:`white_random_walk` per axis (k,): N, K and their uncertainty."""

    white: np.ndarray
    white_sigma: np.ndarray
    random_walk: np.ndarray
    random_walk_sigma: np.ndarray  # max(K - lo, hi - K): the larger side of the 68 % interval
    random_walk_lo: np.ndarray
    random_walk_hi: np.ndarray


def white_random_walk(y, dt_s: float, taper: float = TAPER_FRACTION) -> WhiteRandomWalk:
    """Maximum-likelihood white-noise density N and rate random walk K of rates ``y`` (N,) or (N, k).

    Model (Kalibr's discrete one): ``y_i = b_i + N/√dt w_i``, ``b_i = b_{i-1} + K √dt v_i``. The
    differences ``d_i = y_i − y_{i−1}`` are stationary with spectrum ``S(ω) = a (2 − 2 cos ω) + b``,
    ``a = N²/dt``, ``b = K² dt``. Whittle's likelihood of their periodogram is maximised by
    iteratively reweighted least squares (``b ≥ 0``). Two details make it honest at the low
    frequencies K lives at: the differences are tapered (Tukey, ``taper``) because the plain
    periodogram leaks ``2a/n`` of white noise into every bin, over 100 times ``b`` for typical
    gyros; and the model is the *expected* tapered periodogram (``a (2 − 2ρ₁ cos ω) + b``, ρ₁ the
    taper's lag-1 autocorrelation). The taper correlates neighbouring bins; the variance is the
    sandwich ``F⁻¹ M F⁻¹`` with that correlation (lags 1-3). K's interval: where twice the
    log-likelihood ratio, scaled by the sandwich/Fisher variance ratio, reaches 1 (a 68 %
    interval; the lower end is 0 when the data do not exclude it). K's 1-sigma is the larger side
    of that interval: the interval is lopsided when K is poorly resolved (its upper side longer
    when the estimate is low), and half its width understated the error of low estimates (rms z
    1.4 instead of 1.0 for 300 s records in benchmarks/bench_noise.py).
    """
    from scipy.optimize import brentq
    from scipy.signal.windows import tukey

    from solvers.linalg import lstsq

    y = np.asarray(y, dtype=float)
    Y = y[:, None] if y.ndim == 1 else y
    d = np.diff(Y, axis=0)
    n, k = d.shape
    h = tukey(n, taper)
    h /= math.sqrt(float(np.sum(h * h)))
    d = d - (h @ d) / np.sum(h)  # a steady ramp of the rate (warm-up) is no random walk
    rho1 = float(np.sum(h[1:] * h[:-1]))
    j = np.arange(1, (n - 1) // 2 + 1)
    w = 2.0 * np.pi * j / n
    periodogram = np.abs(np.fft.rfft(d * h[:, None], axis=0)[j]) ** 2
    G = np.column_stack([2.0 - 2.0 * rho1 * np.cos(w), np.ones_like(w)])
    corr2 = np.abs(np.fft.fft(h * h)[:4]) ** 2  # squared correlation of bins 1..3 apart
    out = {name: np.full(k, np.nan) for name in ("a", "b", "sa", "lo", "hi")}
    for ax in range(k):
        P = periodogram[:, ax]
        if not np.all(np.isfinite(P)) or not np.any(P > 0):
            continue
        S = np.full(len(w), float(P.mean()))
        p = np.zeros(2)
        for _ in range(200):
            U = G / S[:, None]
            q = lstsq(U, P / S)[0]
            if q[1] < 0:  # b ≥ 0: white noise alone
                q = np.array([np.sum(G[:, 0] * P / S**2) / np.sum(G[:, 0] ** 2 / S**2), 0.0])
            q[0] = max(q[0], 1e-300)
            done = np.allclose(q, p, rtol=1e-9, atol=0.0)
            p, S = q, G @ q
            if done:
                break
        U = G / S[:, None]
        F = U.T @ U
        M = F.copy()
        for lag in range(1, 4):
            C = U[:-lag].T @ U[lag:]
            M += corr2[lag] * (C + C.T)
        Fi = np.linalg.inv(F)
        cov = Fi @ M @ Fi
        kappa = cov[1, 1] / Fi[1, 1]

        def nll(b, a=p[0], P=P):
            S = G[:, 0] * a + b
            return float(np.sum(np.log(S) + P / S))

        ll0 = nll(p[1])

        def excess(log_b, nll=nll, ll0=ll0, kappa=kappa):
            return 2.0 * (nll(math.exp(log_b)) - ll0) / kappa - 1.0

        scale = math.sqrt(cov[1, 1]) if p[1] == 0 else max(p[1], math.sqrt(cov[1, 1]))
        top = math.log(scale)
        while excess(top) < 0:
            top += 1.0
        bottom = math.log(p[1]) if p[1] > 0 else top - 60.0
        out["hi"][ax] = math.exp(brentq(excess, bottom, top, xtol=1e-6))
        if p[1] > 0 and excess(math.log(p[1]) - 60.0) > 0:
            out["lo"][ax] = math.exp(brentq(excess, math.log(p[1]) - 60.0, math.log(p[1]), xtol=1e-6))
        else:
            out["lo"][ax] = 0.0
        out["a"][ax], out["b"][ax], out["sa"][ax] = p[0], p[1], math.sqrt(cov[0, 0])
    white = np.sqrt(out["a"] * dt_s)
    lo, hi = np.sqrt(out["lo"] / dt_s), np.sqrt(out["hi"] / dt_s)
    return WhiteRandomWalk(
        white=white,
        white_sigma=np.sqrt(dt_s) * out["sa"] / (2.0 * np.sqrt(out["a"])),
        random_walk=np.sqrt(out["b"] / dt_s),
        random_walk_sigma=np.maximum(hi - np.sqrt(out["b"] / dt_s), np.sqrt(out["b"] / dt_s) - lo),
        random_walk_lo=lo,
        random_walk_hi=hi,
    )


def noise_fit(y, dt_s: float, per_octave: int = 2, max_fraction: float = 1.0 / 3.0) -> NoiseFit:
    """White-noise density, bias instability and rate random walk of rates ``y`` (N,) or (N, k)."""
    import allantools

    y = np.asarray(y, dtype=float)
    Y = y[:, None] if y.ndim == 1 else y
    n, k = Y.shape
    grid = octave_taus(n, dt_s, max_fraction, per_octave=per_octave)
    taus, adev, terms = oadev(Y, dt_s, grid)
    ms = np.maximum(np.rint(taus / dt_s), 1).astype(int)
    model = fit_noise_model(taus, adev, terms, dt_s)
    edf = np.ones_like(adev)
    sds = np.ones_like(adev)
    A0 = np.column_stack([1.0 / taus, np.ones_like(taus), taus])
    for j in range(k):
        av = adev[:, j] ** 2
        if not np.all(av > 0):
            continue
        for _ in range(3):  # weights from the model's AVAR (not the noisy points), refit
            c = model[j]
            edf[:, j] = [
                allantools.edf_greenhall(alpha=_alpha(c, t), d=2, m=int(m), N=n + 1, overlapping=True)
                for t, m in zip(taus, ms)
            ]
            pred = A0 @ c if np.any(c > 0) else av
            sds[:, j] = np.maximum(pred, 1e-300) * np.sqrt(2.0 / edf[:, j])
            model[j] = _wls(A0, av, sds[:, j])
    wr = white_random_walk(Y, dt_s)
    white, rw = wr.white, wr.random_walk
    lo, hi = np.empty_like(adev), np.empty_like(adev)
    for i in range(len(taus)):
        for j in range(k):
            lo[i, j], hi[i, j] = allantools.confidence_interval(adev[i, j], edf[i, j], ci=CI_1SIGMA)
    imin = np.argmin(adev, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.where(rw > 0, 12.0 * math.sqrt(3.0) * white / np.where(rw > 0, rw, 1.0), np.inf)
    return NoiseFit(
        taus_s=taus,
        adev=adev,
        adev_lo=lo,
        adev_hi=hi,
        edf=edf,
        white=white,
        white_sigma=wr.white_sigma,
        random_walk=rw,
        random_walk_sigma=wr.random_walk_sigma,
        bias_instability=adev[imin, np.arange(k)] / BIAS_INSTABILITY_FACTOR,
        bias_instability_tau_s=taus[imin],
        model=model,
        duration_s=n * dt_s,
        n=n,
        random_walk_min_duration_s=need,
        random_walk_lo=wr.random_walk_lo,
        random_walk_hi=wr.random_walk_hi,
    )
