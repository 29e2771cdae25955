"""A slow noise of time-ordered rows: white plus a first-order Gauss–Markov wander (bias instability).

Per time-ordered series of weighted rows (``w = 1/σ``: white noise of unit variance), the noise
covariance is modelled as ``s² (I + λ K_τ)``, ``K_τ[i, j] = w_i w_j exp(−|t_i − t_j| / τ) / w̄²``:
the wander's variance relative to the white part ``λ`` and its correlation time ``τ``, on a grid
(``K_τ``'s eigenvectors are computed once per series and ``τ``, so each likelihood is a few
weighted sums).

A wander of a vector (a compass's hard iron that creeps, in the magnetometer's frame) reaches each
row along its own direction: with ``directions`` (rows × d, the rows' sensitivity to each of the
vector's d components) the covariance is ``s² (I + λ K_τ)``, ``K_τ[i, j] = exp(−|t_i − t_j| / τ)
dᵢ · dⱼ / mean |d|²`` (weighted rows), each component an independent Gauss–Markov of the same
variance and ``τ``. The wander is stochastic: it is profiled out of every model's likelihood, where
a candidate (a hard-iron step, a drift) is a deterministic shape tested beside it.

A candidate is tested (``WanderModel.lr``) where the residual its own model leaves still wanders
(REML, the likelihood of the data's part outside the model's columns, so the candidate's signature
is never read as wander): by the likelihood ratio of the model with and without it, the wander
profiled out under both. A Gauss–Markov share of a few percent of a row's variance, within the noise
of an autocorrelation estimate, can mimic a line or a step in time tens of times above the white
noise's deviance; the profiled ratio asks how much better the candidate explains the record than a
wander can.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TAU_PER_SPAN = (0.02, 3.0)  # correlation times scanned, as fractions of the series' span
TAU_STEPS = 10
LAMBDA_GRID = np.concatenate([[0.0], np.logspace(-4, 3, 36)])  # wander variance / white variance per row
MIN_ROWS = 16  # a shorter series is left white
MAX_BINS = 400  # a longer series is taken in this many bins (dense eigenvectors: memory rows², time rows³)
# twice the REML log-likelihood ratio of the wander over white noise (λ, τ: two parameters, τ
# undefined under white) above which a series is taken to wander: white nulls of the independent
# generator stay below 2.5, its 3.5σ effects below 14; the blind generator's bias instability 20-580
EVIDENT_LR = 16.0


class WanderModel:
    """Per series (``series`` ids ≥ 0, time ``t_s`` per row, weights ``w``): the eigenvectors of
    ``K_τ`` on a grid of ``τ``, computed once. A series of more than ``MAX_BINS`` rows is taken in
    ``MAX_BINS`` bins of consecutive rows, the wander constant within each: its likelihood is then
    the white noise's within the bins times the wander's on the bins' means (``_part_loglik``)."""

    def __init__(self, t_s: np.ndarray, series: np.ndarray, w: np.ndarray, directions: np.ndarray | None = None):
        t_s, series, w = np.asarray(t_s, float), np.asarray(series), np.asarray(w, float)
        self.parts = []
        for sid in np.unique(series):
            if sid < 0:
                continue
            idx = np.flatnonzero(series == sid)
            if idx.size < MIN_ROWS:
                continue
            idx = idx[np.argsort(t_s[idx], kind="stable")]
            t = t_s[idx]
            span = float(t.max() - t.min())
            if span <= 0:
                continue
            if directions is not None:
                part = _vector_part(int(sid), idx, t, span, w[idx, None] * np.asarray(directions, float)[idx])
                if part is not None:
                    self.parts.append(part)
                continue
            nb = min(idx.size, MAX_BINS)
            bins = (np.arange(idx.size) * nb) // idx.size
            cnt = np.bincount(bins, minlength=nb).astype(float)
            ww = w[idx] / float(np.mean(w[idx]))
            a = np.bincount(bins, weights=ww, minlength=nb) / np.sqrt(cnt)  # a bin's coordinate of a constant
            tb = np.bincount(bins, weights=t, minlength=nb) / cnt
            dt = np.abs(tb[:, None] - tb[None, :])
            eig = []
            for tau in span * np.geomspace(*TAU_PER_SPAN, TAU_STEPS):
                lam, V = np.linalg.eigh(a[:, None] * np.exp(-dt / tau) * a[None, :])
                eig.append((float(tau), np.maximum(lam, 0.0), V))
            self.parts.append(_Part(int(sid), idx, bins, np.sqrt(cnt), eig, tb, ww))

    def fit(self, X: np.ndarray, e: np.ndarray) -> list[tuple[float, float, float, float]]:
        """Per series: (λ, τ_s, s², LR) maximising the REML likelihood of residual ``e`` (weighted
        rows) of a model with columns ``X``; LR: twice its log-likelihood over white noise's (λ = 0)."""
        return [_reml_fit(part, *_part_loglik(part, X, e[:, None])[1:]) for part in self.parts]

    def evident(self, X: np.ndarray, e: np.ndarray, sigma: np.ndarray) -> list[dict]:
        """The series whose residual ``e`` (weighted rows) of a model with columns ``X`` wanders
        (REML's ratio over white noise ≥ ``EVIDENT_LR``): their series id, the
        wander's standard deviation in the rows' unit (``sigma``: the rows' white σ) and its
        correlation time."""
        out = []
        for part, (lam, tau, s2, lr) in zip(self.parts, self.fit(X, e)):
            if lr >= EVIDENT_LR:
                sig = float(np.sqrt(lam * s2) * np.mean(sigma[part.idx]))
                out.append({"series": part.sid, "sigma": sig, "tau_s": float(tau), "lr": float(lr)})
        return out

    def profile(self, X: np.ndarray, E: np.ndarray) -> np.ndarray:
        """Per series: the Gaussian log-likelihood, maximised over ``(s², λ, τ)`` and the model's
        coefficients (GLS), of residual(s) ``E`` (weighted rows; one column per draw) of a model
        with columns ``X``: shape (series, draws)."""
        E = E.reshape(len(E), -1)
        return np.asarray([_part_loglik(part, X, E)[0].max(axis=(0, 1)) for part in self.parts])

    def null_lr(self, A: np.ndarray, J: np.ndarray, e1: np.ndarray, draws: int, seed: int = 0) -> np.ndarray:
        """The statistic of ``lr`` on ``draws`` records of noise alone, drawn from the slow noise that
        REML fits to ``e1``, the residual of ``[A J]`` (the candidate's signature never taken for
        wander): its distribution where the candidate explains nothing. A series whose wander is
        correlated over the whole record or longer is drawn white: over this record such a wander
        is a drift, and a drift is what the candidates test for (a gyro's warm-up from power-up)."""
        AJ = np.hstack([A, J])
        rng = np.random.default_rng(seed)
        E = np.zeros((len(e1), draws))
        for part, (lam, tau, s2, _) in zip(self.parts, self.fit(AJ, e1)):
            if tau >= part.t_bin[-1] - part.t_bin[0]:
                lam = 0.0  # correlated over more than the record: a drift over it, not noise to test one against
            white = rng.standard_normal((part.idx.size, draws))
            E[part.idx] = np.sqrt(s2) * (white + np.sqrt(lam) * part.draw(tau, rng, draws))
        return np.maximum(0.0, 2.0 * (np.sum(self.profile(AJ, E), axis=0) - np.sum(self.profile(A, E), axis=0)))

    def lr(
        self, A: np.ndarray, J: np.ndarray, e0: np.ndarray, e1: np.ndarray, cache: dict, baseline: bool = False
    ) -> tuple[float, bool]:
        """(the likelihood-ratio statistic of columns ``J`` beside ``A`` with the slow noise profiled
        out under both, whether the residual of ``[A J]`` wanders): ``e0``, ``e1`` the residuals of
        ``A`` and of ``[A J]``; it wanders where REML's ratio over white noise is at least
        ``EVIDENT_LR`` in some series (else the white-noise deviance stands); ``baseline``: or where
        the residual of ``A`` alone does. ``cache`` holds what depends on ``A`` only."""
        ll1, evident = self._ml_and_evident(np.hstack([A, J]), e1)
        if "ll0" not in cache:
            cache["ll0"], cache["evident0"] = self._ml_and_evident(A, e0)
        evident = evident or (baseline and cache["evident0"])
        return max(0.0, 2.0 * (ll1 - cache["ll0"])), evident

    def _ml_and_evident(self, X: np.ndarray, e: np.ndarray) -> tuple[float, bool]:
        """(the profiled ML log-likelihood summed over the series, whether REML's ratio over white
        noise reaches ``EVIDENT_LR`` in some series) of residual ``e`` of a model with columns
        ``X``: one pass per series gives both."""
        ll, evident = 0.0, False
        for part in self.parts:
            ml, reml, rss, dof = _part_loglik(part, X, e[:, None])
            ll += float(ml.max())
            evident = evident or _reml_fit(part, reml, rss, dof)[3] >= EVIDENT_LR
        return ll, evident


def _cols(X: np.ndarray) -> np.ndarray:
    """The columns of ``X`` that have any energy on these rows, orthonormalised to their rank."""
    if X.shape[1] == 0:
        return X
    X = X[:, np.sum(X**2, axis=0) > 0]
    if X.shape[1] == 0:
        return X
    U, s, _ = np.linalg.svd(X, full_matrices=False)
    return U[:, s > s[0] * 1e-9]


@dataclass
class _Part:
    sid: int  # the series' id
    idx: np.ndarray  # the series' rows, in time order
    bins: np.ndarray  # per row: its bin
    root_cnt: np.ndarray  # per bin: √rows
    eig: list  # per τ: (τ, eigenvalues, eigenvectors) of the bins' kernel
    t_bin: np.ndarray  # per bin: its mean time (s)
    w_rel: np.ndarray  # per row: its weight over the series' mean weight (a vector wander: its directions, rows × d)
    # a vector wander: the orthonormal coordinates of each bin's span of directions (coordinates ×
    # rows of the series), where ``root_cnt``'s scalar projection takes the bin's mean otherwise
    proj: np.ndarray | None = None
    bin_times: np.ndarray | None = None  # a vector wander: per bin its mean time (``t_bin`` is per coordinate)

    def draw(self, tau: float, rng, draws: int) -> np.ndarray:
        """Rows × draws of a unit Gauss–Markov wander of correlation time ``tau`` (s), constant
        within a bin, in weighted rows (the ``K_τ`` of the model)."""
        tb = self.t_bin if self.bin_times is None else self.bin_times
        rho = np.exp(-np.diff(tb) / tau)
        d = 1 if self.proj is None else self.w_rel.shape[1]
        x = np.empty((len(tb), d, draws))
        x[0] = rng.standard_normal((d, draws))
        for i, r in enumerate(rho):
            x[i + 1] = r * x[i] + np.sqrt(1.0 - r * r) * rng.standard_normal((d, draws))
        if self.proj is None:
            return self.w_rel[:, None] * x[self.bins, 0]
        return np.einsum("nc,ncb->nb", self.w_rel, x[self.bins])

    def project(self, Y: np.ndarray) -> np.ndarray:
        """The rows' coordinates (columns of ``Y``, the series' rows) where the wander lives: each
        bin's mean (scalar wander), or each bin's span of directions (vector wander)."""
        if self.proj is not None:
            return self.proj @ Y
        out = np.zeros((len(self.root_cnt), Y.shape[1]))
        np.add.at(out, self.bins, Y)
        return out / self.root_cnt[:, None]


def _vector_part(sid: int, idx: np.ndarray, t: np.ndarray, span: float, D: np.ndarray) -> _Part | None:
    """The series' part of a vector wander (``D``: its rows' weighted directions, rows × d, in time
    order), or None where the directions have no energy. ``MAX_BINS`` coordinates at most: bins of
    consecutive rows, each the orthonormal span of its rows' directions (≤ d coordinates), the
    wander constant within a bin; the kernel between coordinates ``exp(−|Δt|/τ) (C Cᵀ)``, C each
    coordinate's loading on the d components."""
    scale = float(np.mean(np.sum(D * D, axis=1)))
    if not scale > 0:
        return None
    D = D / np.sqrt(scale)
    n, d = D.shape
    nb = max(1, min(n, MAX_BINS // d))
    bins = (np.arange(n) * nb) // n
    cnt = np.bincount(bins, minlength=nb).astype(float)
    tbin = np.bincount(bins, weights=t, minlength=nb) / cnt
    rows, loads, tc = [], [], []
    for b in range(nb):
        sel = np.flatnonzero(bins == b)
        U, sv, Vt = np.linalg.svd(D[sel], full_matrices=False)
        keep = sv > (sv[0] if sv.size else 0.0) * 1e-6
        for j in np.flatnonzero(keep):
            row = np.zeros(n)
            row[sel] = U[:, j]
            rows.append(row)
            loads.append(sv[j] * Vt[j])  # the coordinate's loading on the d components (Uᵀ D)
            tc.append(tbin[b])
    if not rows:
        return None
    P, C, tc = np.asarray(rows), np.asarray(loads), np.asarray(tc)
    dt = np.abs(tc[:, None] - tc[None, :])
    G = C @ C.T
    eig = []
    for tau in span * np.geomspace(*TAU_PER_SPAN, TAU_STEPS):
        lam, V = np.linalg.eigh(np.exp(-dt / tau) * G)
        eig.append((float(tau), np.maximum(lam, 0.0), V))
    return _Part(sid, idx, bins, np.sqrt(cnt), eig, tc, D, proj=P, bin_times=tbin)


def _reml_fit(part: _Part, ll: np.ndarray, rss: np.ndarray, dof: int) -> tuple[float, float, float, float]:
    """(λ, τ_s, s², LR over white noise) at the REML optimum of one series' grid (one draw)."""
    i, j = np.unravel_index(int(np.argmax(ll[..., 0])), ll.shape[:2])
    best = float(ll[i, j, 0])
    return float(LAMBDA_GRID[j]), part.eig[i][0], float(rss[i, j, 0] / dof), 2.0 * (best - float(ll[0, 0, 0]))


def _part_loglik(part: _Part, X: np.ndarray, E: np.ndarray):
    """(ML log-likelihood, REML log-likelihood, weighted RSS, REML degrees of freedom) of
    residuals ``E`` (rows × draws) of a model with columns ``X`` on one series, per τ and λ of
    the grid: shapes (τ, λ, draws). The rows split into the bins' mean directions, where the
    wander lives, and what is within the bins (white); the model's coefficients are fitted by GLS
    over both. The ML likelihood profiles ``s²`` over ``n`` rows, REML over ``n − p`` with the
    model's information ``log det M`` added (the likelihood of the part outside its columns)."""
    Xm, Em = _cols(X[part.idx]), E[part.idx]
    n, p = Xm.shape
    Xb, Eb = part.project(Xm), part.project(Em)
    Gw, gw = Xm.T @ Xm - Xb.T @ Xb, Xm.T @ Em - Xb.T @ Eb  # within the bins
    qw = np.sum(Em * Em, axis=0) - np.sum(Eb * Eb, axis=0)
    L = len(LAMBDA_GRID)
    ll = np.empty((len(part.eig), L, Em.shape[1]))
    ll_r, rss_all = np.empty_like(ll), np.empty_like(ll)
    for i, (_, lam, V) in enumerate(part.eig):
        Xt, Et = V.T @ Xb, V.T @ Eb
        W = 1.0 / (1.0 + LAMBDA_GRID[:, None] * lam[None, :])  # (λ, bins)
        rss = qw[None, :] + W @ (Et * Et)
        logdet = np.sum(np.log1p(LAMBDA_GRID[:, None] * lam[None, :]), axis=1)
        logdet_m = np.zeros(L)
        if p:
            # Σ_n W[l, n] Xt[n, p] Xt[n, q] as one matrix product (a plain einsum loops in Python
            # order over l, n, p, q: most of an LDV diagnosis with a dozen columns)
            M = Gw[None] + (W @ (Xt[:, :, None] * Xt[:, None, :]).reshape(len(Xt), p * p)).reshape(L, p, p)
            b = gw[None] + (W @ (Xt[:, :, None] * Et[:, None, :]).reshape(len(Xt), -1)).reshape(L, p, Et.shape[1])
            rss = rss - np.einsum("lpb,lpb->lb", b, np.linalg.solve(M + 1e-12 * np.eye(p), b))
            logdet_m = np.linalg.slogdet(M)[1]
        rss = np.maximum(rss, 1e-300)
        ll[i] = -0.5 * (logdet[:, None] + n * np.log(rss / n))
        ll_r[i] = -0.5 * (logdet[:, None] + logdet_m[:, None] + (n - p) * np.log(rss / (n - p)))
        rss_all[i] = rss
    return ll, ll_r, rss_all, n - p
