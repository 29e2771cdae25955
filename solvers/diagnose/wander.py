"""A slow noise of time-ordered rows: white plus a first-order Gauss–Markov wander (bias instability).

Per time-ordered series of weighted rows (``w = 1/σ``: white noise of unit variance), the noise
covariance is modelled as ``s² (I + λ K_τ)``, ``K_τ[i, j] = w_i w_j exp(−|t_i − t_j| / τ) / w̄²``:
the wander's variance relative to the white part ``λ`` and its correlation time ``τ``, on a grid
(``K_τ``'s eigenvectors are computed once per series and ``τ``, so each likelihood is a few
weighted sums).

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

    def __init__(self, t_s: np.ndarray, series: np.ndarray, w: np.ndarray):
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
    w_rel: np.ndarray  # per row: its weight over the series' mean weight

    def draw(self, tau: float, rng, draws: int) -> np.ndarray:
        """Rows × draws of a unit Gauss–Markov wander of correlation time ``tau`` (s), constant
        within a bin, in weighted rows (the ``K_τ`` of the model)."""
        rho = np.exp(-np.diff(self.t_bin) / tau)
        x = np.empty((len(self.t_bin), draws))
        x[0] = rng.standard_normal(draws)
        for i, r in enumerate(rho):
            x[i + 1] = r * x[i] + np.sqrt(1.0 - r * r) * rng.standard_normal(draws)
        return self.w_rel[:, None] * x[self.bins]


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
    nb = len(part.root_cnt)

    def binned(Y):
        out = np.zeros((nb, Y.shape[1]))
        np.add.at(out, part.bins, Y)
        return out / part.root_cnt[:, None]

    Xb, Eb = binned(Xm), binned(Em)
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
