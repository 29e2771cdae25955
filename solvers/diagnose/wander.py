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

import numpy as np

TAU_PER_SPAN = (0.02, 3.0)  # correlation times scanned, as fractions of the series' span
TAU_STEPS = 10
LAMBDA_GRID = np.concatenate([[0.0], np.logspace(-4, 3, 36)])  # wander variance / white variance per row
MIN_ROWS = 16  # a shorter series is left white
MAX_ROWS = 800  # a longer one too (dense eigenvectors: memory and time go as rows² and rows³)
# twice the REML log-likelihood ratio of the wander over white noise (λ, τ: two parameters, τ
# undefined under white) above which a series is taken to wander: white nulls of the independent
# generator stay below 2.5, its 3.5σ effects below 14; the blind generator's bias instability 20-580
EVIDENT_LR = 16.0


class WanderModel:
    """Per series (``series`` ids ≥ 0, time ``t_s`` per row, weights ``w``): the eigenvectors of
    ``K_τ`` on a grid of ``τ``, computed once."""

    def __init__(self, t_s: np.ndarray, series: np.ndarray, w: np.ndarray):
        t_s, series, w = np.asarray(t_s, float), np.asarray(series), np.asarray(w, float)
        self.parts = []
        for sid in np.unique(series):
            if sid < 0:
                continue
            idx = np.flatnonzero(series == sid)
            if not MIN_ROWS <= idx.size <= MAX_ROWS:
                continue
            t = t_s[idx]
            span = float(t.max() - t.min())
            if span <= 0:
                continue
            ww = w[idx] / float(np.mean(w[idx]))
            dt = np.abs(t[:, None] - t[None, :])
            eig = []
            for tau in span * np.geomspace(*TAU_PER_SPAN, TAU_STEPS):
                lam, V = np.linalg.eigh(ww[:, None] * np.exp(-dt / tau) * ww[None, :])
                eig.append((float(tau), np.maximum(lam, 0.0), V))
            self.parts.append((idx, eig))

    def fit(self, X: np.ndarray, e: np.ndarray) -> list[tuple[float, float, float, float]]:
        """Per series: (λ, τ_s, s², LR) maximising the REML likelihood of residual ``e`` (weighted
        rows) of a model with columns ``X``; LR: twice its log-likelihood over white noise's (λ = 0)."""
        out = []
        for idx, eig in self.parts:
            Xm, em = _cols(X[idx]), e[idx]
            n, p = Xm.shape
            best = (-np.inf, 0.0, eig[0][0], 1.0)
            white = None
            for tau, lam, V in eig:
                Xt, et = V.T @ Xm, V.T @ em
                W = 1.0 / (1.0 + LAMBDA_GRID[:, None] * lam[None, :])  # (L, n)
                M = np.einsum("ln,np,nq->lpq", W, Xt, Xt)
                b = np.einsum("ln,np,n->lp", W, Xt, et)
                q = W @ (et * et)
                if p:
                    sol = np.linalg.solve(M + 1e-12 * np.eye(p), b[..., None])[..., 0]
                    rss = q - np.einsum("lp,lp->l", b, sol)
                    logdet_m = np.linalg.slogdet(M)[1]
                else:
                    rss, logdet_m = q, np.zeros(len(LAMBDA_GRID))
                rss = np.maximum(rss, 1e-300)
                ll = -0.5 * (
                    np.sum(np.log1p(LAMBDA_GRID[:, None] * lam[None, :]), axis=1)
                    + logdet_m
                    + (n - p) * np.log(rss / (n - p))
                )
                i = int(np.argmax(ll))
                white = float(ll[0])  # λ = 0: the same at every τ
                if ll[i] > best[0]:
                    best = (float(ll[i]), float(LAMBDA_GRID[i]), tau, float(rss[i] / (n - p)))
            out.append(best[1:] + (2.0 * (best[0] - white),))
        return out

    def profile(self, X: np.ndarray, E: np.ndarray) -> np.ndarray:
        """Per series: the Gaussian log-likelihood, maximised over ``(s², λ, τ)`` and the model's
        coefficients (GLS), of residual(s) ``E`` (weighted rows; one column per draw) of a model
        with columns ``X``: shape (series, draws)."""
        E = E.reshape(len(E), -1)
        out = []
        for idx, eig in self.parts:
            Xm, Em = _cols(X[idx]), E[idx]
            n, p = Xm.shape
            best = np.full(Em.shape[1], -np.inf)
            for _, lam, V in eig:
                Xt, Et = V.T @ Xm, V.T @ Em
                W = 1.0 / (1.0 + LAMBDA_GRID[:, None] * lam[None, :])  # (L, n)
                rss = W @ (Et * Et)  # (L, B)
                if p:
                    M = np.einsum("ln,np,nq->lpq", W, Xt, Xt)
                    b = np.einsum("ln,np,nb->lpb", W, Xt, Et)
                    rss = rss - np.einsum("lpb,lpb->lb", b, np.linalg.solve(M + 1e-12 * np.eye(p), b))
                logdet = np.sum(np.log1p(LAMBDA_GRID[:, None] * lam[None, :]), axis=1)
                ll = -0.5 * (logdet[:, None] + n * np.log(np.maximum(rss, 1e-300) / n))
                best = np.maximum(best, ll.max(axis=0))
            out.append(best)
        return np.asarray(out)

    def lr(self, A: np.ndarray, J: np.ndarray, e0: np.ndarray, e1: np.ndarray, cache: dict) -> float | None:
        """The likelihood-ratio statistic of columns ``J`` beside ``A`` with the slow noise profiled
        out under both (``e0``, ``e1``: the residuals of ``A`` and of ``[A J]``), or None when the
        residual of ``[A J]`` shows no wander (REML's ratio over white noise below ``EVIDENT_LR`` in
        every series: the white-noise deviance stands). ``cache`` holds what depends on ``A`` only."""
        AJ = np.hstack([A, J])
        if max((f[3] for f in self.fit(AJ, e1)), default=0.0) < EVIDENT_LR:
            return None
        if "ll0" not in cache:
            cache["ll0"] = float(np.sum(self.profile(A, e0)))
        return max(0.0, 2.0 * (float(np.sum(self.profile(AJ, e1))) - cache["ll0"]))


def _cols(X: np.ndarray) -> np.ndarray:
    """The columns of ``X`` that have any energy on these rows, orthonormalised to their rank."""
    if X.shape[1] == 0:
        return X
    X = X[:, np.sum(X**2, axis=0) > 0]
    if X.shape[1] == 0:
        return X
    U, s, _ = np.linalg.svd(X, full_matrices=False)
    return U[:, s > s[0] * 1e-9]
