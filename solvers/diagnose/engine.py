"""The generic diagnosis engine: baseline vs candidate extensions of a shared forward model.

A :class:`Problem` is what a procedure hands over: ``residual(params) -> model − data``
(flat, in the data's unit) built on the shared forward model, its per-row noise ``sigma``,
a CV ``groups`` label per row (position, epoch or time block), the baseline blocks with
their free mask, and the :class:`Candidate` effects (the extra blocks of
``solvers.models.*.EFFECTS``, at their null values).

Method (docs/diagnose.md):

1. Fit the baseline (``solvers.fit.fit``), then linearise the weighted residual at the
   solution: ``r ≈ r0 + J0 δ``; each candidate adds columns ``Jc`` (its blocks' Jacobian at
   their null values; a scalar that cannot be linearised, the hard-iron step time, is
   scanned on a grid).
2. A candidate's columns that the baseline already spans (projected norm below
   ``DEAD_RTOL`` of their own) are not identifiable from this capture: when none is left
   the candidate is *unresolvable* and reported with the reason, never as absent.
3. Information criterion: Gaussian BIC with unknown noise scale,
   ``BIC = n ln(RSS/n) + k ln n`` on the weighted residual, so correlated noise that makes
   the stated ``sigma`` optimistic does not make every effect look significant.
4. Held-out validation: the linearised least-squares problem is solved leaving out one
   fold of groups at a time and the held-out rows are predicted; ``cv_rms`` is the RMS of
   those predictions (data units). For a linear model this is exact refitting.
5. Greedy forward selection: a candidate with ``k`` identifiable parameters, one of ``m``,
   is selected when ``ΔBIC < k ln n − F·χ²_k(1 − α/m)`` (a deviance test at level α/m
   written as a ΔBIC bound; ``F``, the procedure's ``threshold``, is measured on null
   simulations: ``THRESHOLDS`` in ``solvers.diagnose.problems``) *and* it lowers
   ``cv_rms`` *and* leaves at least MIN_DOF degrees of freedom. Other candidates that also
   pass and whose fitted signatures correlate with the chosen one's by more than
   ``CONFUSION_CORR`` are reported with it (``confused_with``) and not fitted on top.
6. The extended model is refitted nonlinearly (``solvers.fit``) with the selected blocks;
   its residuals are tested for whiteness (Ljung–Box on time-ordered rows) or against χ².
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.special import gammaincc, gammainccinv

from solvers.fit import FitResult, fit
from solvers.params import Packer, as_params

DEAD_RTOL = 1e-2          # a column whose part outside the baseline's span is below this fraction: not identifiable
CONFUSION_CORR = 0.9      # |corr| of fitted signatures above this: the data cannot tell the two apart
MAX_FOLDS = 10
ALPHA = 0.05              # family-wise level the per-candidate deviance quantiles start from
MIN_DOF = 3               # an extension must leave this many degrees of freedom


@dataclass
class Candidate:
    """One effect: its null-valued blocks, which elements are free, an optional scanned scalar
    (``scan = (block, grid)``), or ``reason`` when the capture cannot resolve it at all."""

    name: str
    blocks: dict = field(default_factory=dict)
    free: dict | None = None
    scan: tuple[str, np.ndarray] | None = None
    reason: str | None = None


@dataclass
class Problem:
    procedure: str
    model: str
    residual: Callable[[dict], np.ndarray]
    sigma: np.ndarray
    groups: np.ndarray
    baseline: dict
    free: dict
    candidates: list[Candidate]
    threshold: float
    unit: str = ""
    time_ordered: bool = False           # rows are a time series (Ljung–Box) or averages (χ²)
    row_labels: list[str] | None = None  # a name per row for quality findings
    extended_model: Callable[[list[str]], str] | None = None
    row_types: np.ndarray | None = None
    drivers: dict = field(default_factory=dict)  # name → per-row value (time, temperature, input …) for plots
    channels: int = 1                       # time-ordered rows interleave this many channels (axes, beams)     # rows of different kinds get their own noise scale


@dataclass
class Diagnosis:
    procedure: str
    baseline: FitResult
    baseline_cv_rms: float
    candidates: list[dict]
    effects: list[dict]
    verdict: list[str]
    extended: FitResult
    extended_cv_rms: float
    extended_names: list[str]
    residual_test: dict
    studentized: np.ndarray               # extended residual / (sigma · noise scale)
    model: str
    extended_model: str
    problem: Problem
    deviance: dict = field(default_factory=dict)   # first round: {name: {D, k, q, cv_lower}} (benchmark)

    def rms(self, fitres: FitResult) -> float:
        """Residual RMS in data units over the primary rows (all rows of one kind)."""
        r = fitres.residuals
        if self.problem.row_types is not None:
            r = r[np.asarray(self.problem.row_types) == 0]
        return float(np.sqrt(np.mean(r ** 2))) if r.size else 0.0


# ---------------------------------------------------------------- linear algebra helpers

def _weighted(problem: Problem, params: dict) -> np.ndarray:
    return np.asarray(problem.residual(params), dtype=float).ravel() / problem.sigma


def jacobian(problem: Problem, params: dict, free: dict) -> tuple[np.ndarray, list[str], Packer]:
    """Central-difference Jacobian of the weighted residual w.r.t. the free elements."""
    packer = Packer.build(params, free)
    x0 = packer.pack(packer.template)
    J = np.empty((problem.sigma.size, x0.size))
    for k in range(x0.size):
        h = 1e-6 * max(1.0, abs(x0[k]))
        xp, xm = x0.copy(), x0.copy()
        xp[k] += h
        xm[k] -= h
        J[:, k] = (_weighted(problem, packer.unpack(xp)) - _weighted(problem, packer.unpack(xm))) / (2 * h)
    return J, packer.names, packer


def _solve_normal(G: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Minimum-norm solution of ``G x = b`` (G a Gram matrix), columns scaled first."""
    d = np.sqrt(np.clip(np.diag(G), 0.0, None))
    d = np.where(d > 0, d, 1.0)
    x, *_ = np.linalg.lstsq(G / np.outer(d, d), b / d, rcond=1e-12)
    return x / d


def _lstsq_rss(A: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, float]:
    """``d`` minimising ``|r + A d|²`` and that minimum."""
    if A.shape[1] == 0:
        return np.zeros(0), float(r @ r)
    d = _solve_normal(A.T @ A, -(A.T @ r))
    e = r + A @ d
    return d, float(e @ e)


def folds_of(groups: np.ndarray) -> np.ndarray:
    """Fold index per row: each group its own fold, or groups dealt into MAX_FOLDS folds in order."""
    uniq, inv = np.unique(np.asarray(groups), return_inverse=True)
    if len(uniq) <= MAX_FOLDS:
        return inv
    return (inv * MAX_FOLDS) // len(uniq)


def cv_rms(A: np.ndarray, r: np.ndarray, sigma: np.ndarray, folds: np.ndarray, primary=None) -> float:
    """RMS (data units) of held-out predictions of the linearised model ``r + A d``, over the
    ``primary`` rows (all when None; auxiliary rows of other units still help the fit)."""
    out = r.copy()
    if A.shape[1]:
        G, b = A.T @ A, A.T @ r
        for f in np.unique(folds):
            test = folds == f
            At, rt = A[test], r[test]
            d = _solve_normal(G - At.T @ At, -(b - At.T @ rt))
            out[test] = rt + At @ d
    if primary is not None:
        # rows of several kinds: weighted residuals in noise-equivalent units of the primary rows
        e = out * float(np.median(sigma[primary]))
    else:
        e = out * sigma
    return float(np.sqrt(np.mean(e ** 2)))


def chi2_isf(p: float, k: int) -> float:
    """Upper-tail quantile of χ²_k."""
    return 2.0 * float(gammainccinv(k / 2.0, p))


def selection_threshold(problem: "Problem", k: int, n: int, m: int) -> float:
    """ΔBIC below which a k-parameter candidate (one of m) is selected:
    ``k ln n − F·χ²_k(1 − α/m)`` — a deviance test at level α/m whose scale ``F`` (the
    procedure's ``threshold``) is measured on null simulations, written as a ΔBIC bound."""
    return k * math.log(n) - problem.threshold * chi2_isf(ALPHA / max(m, 1), max(k, 1))


def bic(rss: float, n: int, k: int) -> float:
    return n * math.log(max(rss, 1e-300) / n) + k * math.log(n)


def typed_fit_term(e: np.ndarray, types) -> float:
    """``Σ_t n_t ln(RSS_t / n_t)``: the Gaussian profile likelihood term with an unknown noise
    scale per kind of row (one kind when ``types`` is None)."""
    if types is None:
        return bic(float(e @ e), e.size, 0)
    return sum(bic(float(e[types == t] @ e[types == t]), int((types == t).sum()), 0) for t in np.unique(types))


def _orth(A: np.ndarray) -> np.ndarray:
    """Orthonormal basis of A's column space (through the scaled Gram matrix)."""
    if A.shape[1] == 0:
        return np.zeros((A.shape[0], 0))
    d = np.linalg.norm(A, axis=0)
    d = np.where(d > 0, d, 1.0)
    As = A / d
    w, V = np.linalg.eigh(As.T @ As)
    keep = w > 1e-12 * max(w.max(), 1e-300)
    return (As @ V[:, keep]) / np.sqrt(w[keep])


def ljung_box(x: np.ndarray, lags: int = 20) -> dict:
    """Ljung–Box portmanteau test of whiteness on a time-ordered series."""
    x = np.asarray(x, float) - np.mean(x)
    n = len(x)
    lags = max(1, min(lags, n // 5))
    den = float(x @ x)
    if n < 10 or den <= 0:
        return {"test": "ljung-box", "n": n, "statistic": None, "p_value": None, "white": None}
    q = 0.0
    for k in range(1, lags + 1):
        rho = float(x[k:] @ x[:-k]) / den
        q += rho * rho / (n - k)
    q *= n * (n + 2)
    p = float(gammaincc(lags / 2.0, q / 2.0))
    return {"test": "ljung-box", "lags": lags, "n": n, "statistic": q, "p_value": p, "white": bool(p > 0.01)}


def chi2_test(rw: np.ndarray, dof: int) -> dict:
    c = float(rw @ rw)
    dof = max(int(dof), 1)
    p = float(gammaincc(dof / 2.0, c / 2.0))
    return {"test": "chi-square", "chi2": c, "dof": dof, "reduced_chi2": c / dof, "p_value": p,
            "white": bool(p > 0.01)}


# ---------------------------------------------------------------- candidates

@dataclass
class _Cand:
    cand: Candidate
    params: dict          # null blocks (with the best scanned value)
    free: dict
    J: np.ndarray         # weighted Jacobian columns (identifiable ones)
    names: list[str]
    reason: str | None = None


def _free_of(c: Candidate) -> dict:
    if c.free is not None:
        return dict(c.free)
    return {k: True for k in c.blocks if not (c.scan and k == c.scan[0])}


def _candidate_columns(problem: Problem, base_params: dict, c: Candidate, Q: np.ndarray,
                       r0: np.ndarray) -> _Cand:
    """Jacobian columns of ``c`` at ``base_params`` (best grid value when scanned), with the
    columns the baseline already spans removed (fixed at their null values)."""
    grid = [None] if c.scan is None else list(c.scan[1])
    best = None
    if c.scan is not None and len(grid) > 2:
        # coarse grid, then a fine one around the best coarse value
        step = float(grid[1] - grid[0])
        scores = []
        for value in grid:
            blocks = as_params(c.blocks)
            blocks[c.scan[0]] = np.array(float(value))
            params = {**base_params, **blocks}
            free = {k: False for k in base_params}
            free.update(_free_of(c))
            J, _, _ = jacobian(problem, params, free)
            perp = J - Q @ (Q.T @ J)
            scores.append(_lstsq_rss(perp, r0 - Q @ (Q.T @ r0))[1])
        v0 = float(grid[int(np.argmin(scores))])
        grid = list(np.linspace(v0 - step, v0 + step, 21))
    for value in grid:
        blocks = as_params(c.blocks)
        if value is not None:
            blocks[c.scan[0]] = np.array(float(value))
        params = {**base_params, **blocks}
        free = {k: False for k in base_params}
        free.update(_free_of(c))
        J, names, _ = jacobian(problem, params, free)
        if J.shape[1] == 0:
            continue
        perp = J - Q @ (Q.T @ J)
        _, rss = _lstsq_rss(perp, r0 - Q @ (Q.T @ r0))
        if best is None or rss < best[0]:
            best = (rss, blocks, J, perp, names, free)
    if best is None:
        return _Cand(c, {}, {}, np.zeros((len(r0), 0)), [], "no free parameter")
    _, blocks, J, perp, names, free = best
    norm = np.linalg.norm(J, axis=0)
    pnorm = np.linalg.norm(perp, axis=0)
    keep = (norm > 0) & (pnorm > DEAD_RTOL * np.where(norm > 0, norm, 1.0))
    if not keep.any():
        return _Cand(c, blocks, free, J[:, :0], [], "its signature is indistinguishable from the baseline "
                     "parameters in this capture (the data do not vary its driver independently)")
    # fix the dead elements at their null values
    packer = Packer.build({**{k: v for k, v in blocks.items()}}, {k: free.get(k, False) for k in blocks})
    dead = [n for n, k in zip(names, keep) if not k]
    if dead:
        mask = {k: np.array(packer.free[k]) for k in blocks}
        for name in dead:
            block, idx = _split_name(name)
            if block in mask:
                m = mask[block]
                if m.ndim == 0:
                    mask[block] = np.array(False)
                else:
                    m[idx] = False
        free = {**{k: False for k in base_params}, **mask}
    return _Cand(c, blocks, free, J[:, keep], [n for n, k in zip(names, keep) if k])


def _split_name(name: str):
    if "[" not in name:
        return name, ()
    block = name[: name.index("[")]
    idx = tuple(int(p) for p in name[name.index("[") + 1 : -1].split("]["))
    return block, idx


# ---------------------------------------------------------------- the engine

def diagnose(problem: Problem, baseline_fit: FitResult | None = None) -> Diagnosis:
    """Run steps 1–6 of the module docstring on ``problem``."""
    sigma = np.asarray(problem.sigma, dtype=float).ravel()
    problem.sigma = sigma
    n = sigma.size
    folds = folds_of(problem.groups)
    primary = None if problem.row_types is None else (np.asarray(problem.row_types) == 0)
    if baseline_fit is None:
        baseline_fit = fit(problem.residual, problem.baseline, free=problem.free, sigma=sigma)
    if problem.row_types is not None:
        # variance components: auxiliary rows (prior σ) get the noise scale their baseline residuals show
        rw = baseline_fit.weighted_residuals
        for k in np.unique(problem.row_types):
            if k == 0:
                continue  # the primary rows keep their measured noise (the χ² test is about them)
            sel = problem.row_types == k
            s = math.sqrt(float(np.mean(rw[sel] ** 2))) if sel.any() else 1.0
            if s > 0:
                sigma[sel] *= s
        problem.sigma = sigma
        baseline_fit = fit(problem.residual, baseline_fit.params, free=problem.free, sigma=sigma)
    base_params = baseline_fit.params
    r0 = _weighted(problem, base_params)
    J0, _, _ = jacobian(problem, base_params, problem.free)
    Q0 = _orth(J0)
    rss0 = float(r0 @ r0)
    cv0 = cv_rms(J0, r0, sigma, folds, primary)

    cands = [_candidate_columns(problem, base_params, c, Q0, r0) if c.reason is None
             else _Cand(c, {}, {}, np.zeros((n, 0)), [], c.reason) for c in problem.candidates]
    entries: dict[str, dict] = {}
    for cc in cands:
        if cc.reason is not None:
            entries[cc.cand.name] = {"name": cc.cand.name, "delta_bic": None, "cv_rms": None, "selected": False,
                                     "resolvable": False, "reason": cc.reason}

    # greedy forward selection on the linearised problem
    A = J0
    rss_cur, cv_cur = rss0, cv0
    types = None if problem.row_types is None else np.asarray(problem.row_types)
    term_cur = typed_fit_term(r0, types)
    selected: list[_Cand] = []
    effects: list[dict] = []
    verdict: list[str] = []
    remaining = [c for c in cands if c.reason is None]
    first_round = True
    first_dev: dict | None = {}
    deviance = first_dev
    while remaining:
        rows = []
        for cc in remaining:
            Ac = np.hstack([A, cc.J])
            d, rss = _lstsq_rss(Ac, r0)
            k = np.linalg.matrix_rank(Ac) - np.linalg.matrix_rank(A) if A.shape[1] else np.linalg.matrix_rank(Ac)
            if cc.cand.scan is not None and k > 0:
                k += 1  # the scanned scalar (hard-iron step time) is a parameter too
            db = typed_fit_term(r0 + Ac @ d, types) - term_cur + max(k, 0) * math.log(n)
            cvc = cv_rms(Ac, r0, sigma, folds, primary)
            sig = cc.J @ d[A.shape[1]:]
            sig = sig - _orth(A) @ (_orth(A).T @ sig)
            rows.append((cc, db, cvc, sig, k))
            if first_round:
                entries[cc.cand.name] = {"name": cc.cand.name, "delta_bic": db, "cv_rms": cvc, "selected": False}
        first_round = False
        rank_cur = np.linalg.matrix_rank(A) if A.shape[1] else 0
        m = len(rows)
        for r in rows:
            if first_dev is not None and r[0].cand.name not in first_dev:
                q = chi2_isf(ALPHA / max(m, 1), max(r[4], 1))
                first_dev[r[0].cand.name] = {"D": max(r[4], 0) * math.log(n) - r[1], "k": int(r[4]), "q": q,
                                             "cv_lower": bool(r[2] < cv_cur)}
        first_dev = None
        passing = [r for r in rows if r[4] > 0 and r[1] < selection_threshold(problem, r[4], n, m)
                   and r[2] < cv_cur and n - rank_cur - r[4] >= MIN_DOF]
        if not passing:
            break
        best = min(passing, key=lambda r: r[1])
        confused = []
        for r in passing:
            if r is best:
                continue
            a, b = best[3], r[3]
            den = float(np.linalg.norm(a) * np.linalg.norm(b))
            corr = float(a @ b) / den if den > 0 else 0.0
            if abs(corr) > CONFUSION_CORR:
                confused.append({"name": r[0].cand.name, "correlation": corr})
        cc = best[0]
        entries[cc.cand.name]["selected"] = True
        effects.append({"name": cc.cand.name, "_cand": cc, "cv_rms_before": cv_cur, "cv_rms_after": best[2],
                        "gain": 1.0 - best[2] / cv_cur if cv_cur > 0 else 0.0, "confused_with": confused})
        verdict.append(cc.cand.name)
        for c in confused:
            verdict.append(c["name"])
        selected.append(cc)
        A = np.hstack([A, cc.J])
        cv_cur = best[2]
        d_cur, rss_cur = _lstsq_rss(A, r0)
        term_cur = typed_fit_term(r0 + A @ d_cur, types)
        drop = {cc.cand.name} | {c["name"] for c in confused}
        remaining = [c for c in remaining if c.cand.name not in drop]

    # extended model: nonlinear refit with the selected blocks
    ext_params = dict(base_params)
    ext_free = dict(problem.free)
    for cc in selected:
        ext_params.update(cc.params)
        ext_free.update({k: v for k, v in cc.free.items() if k in cc.params})
    if selected:
        # start from the linearised solution
        Jx, names, packer = jacobian(problem, ext_params, ext_free)
        d, _ = _lstsq_rss(Jx, _weighted(problem, ext_params))
        start = packer.unpack(packer.pack(packer.template) + d)
        try:
            ext = fit(problem.residual, start, free=ext_free, sigma=sigma)
            if ext.chi2 > float(np.sum(_weighted(problem, start) ** 2)) * 1.0001:
                raise ValueError("refit worse than its start")
        except Exception:
            ext = fit(problem.residual, start, free=ext_free, sigma=sigma, max_nfev=1)
        Je, _, _ = jacobian(problem, ext.params, ext_free)
        cv_ext = cv_rms(Je, ext.weighted_residuals, sigma, folds, primary)
    else:
        ext, cv_ext = baseline_fit, cv0
    for e in effects:
        cc = e.pop("_cand")
        e["params"] = {k: ext.params[k] for k in cc.params}
        e["uncertainty"] = {k: ext.sigma[k] for k in cc.params}
    rw = ext.weighted_residuals
    scale = math.sqrt(ext.chi2 / ext.dof) if ext.dof > 0 else 1.0
    stud = rw / max(scale, 1e-300)
    if problem.time_ordered:
        ch = max(1, int(problem.channels))
        tests = [ljung_box(rw.reshape(-1, ch)[:, j]) for j in range(ch)]
        test = min(tests, key=lambda x: x["p_value"] if x["p_value"] is not None else 1.0)
        if test["p_value"] is not None:
            test = dict(test, p_value=min(1.0, test["p_value"] * ch), channels=ch)
            test["white"] = bool(test["p_value"] > 0.01)
    else:
        test = chi2_test(rw, ext.dof)
    cand_list = [entries[c.name] for c in problem.candidates]
    ext_model = problem.extended_model([e["name"] for e in effects]) if (problem.extended_model and effects) \
        else problem.model
    return Diagnosis(problem.procedure, baseline_fit, cv0, cand_list, effects, verdict, ext, cv_ext,
                     [e["name"] for e in effects], test, stud, problem.model, ext_model, problem, deviance)
