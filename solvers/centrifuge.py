"""P2: centrifuge calibration with the norm-observation method (source 001, Wang & Li 2021).

Model (``solvers.models.accel``): ``N = S Φ(γ) [f + D f∘f] + b``, ``f`` in g, ``N`` in the
output unit. On a centrifuge at ``ω`` with radius ``R`` the specific force satisfies
``|f|² = A² + 1``, ``A = ω²R/g`` (:func:`norm_target` gives ``ρ = sqrt(A² + 1)``).

Two estimators on the same rows:

- :func:`exact_fit` (the station's default): weighted nonlinear least squares on
  ``|inverse(N)| − ρ`` (the exact inverse of the model, ``accel.inverse``), each row weighted
  by its noise propagated to ``|f|``. Optional installation angles: a norm cannot see a
  rotation of the whole triad *except* through the quadratic term, which acts on the
  sensor's own axes; at centrifuge levels (tens of g) that makes all 6 γ identifiable
  (σ ~ 1e-4 rad in the paper's design), and all 6 are fitted. When they are not (small D or
  g), the gauge ``γxy = γxz = γyz = 0`` (frame x = the x accelerometer's input axis, frame y
  in the plane of the x and y input axes) leaves ``γyx, γzx, γzy``.
- :func:`paper_fit` (the paper's eqs 13-22, re-derived): invert each axis' quadratic
  ``x = f + D f²`` with ``x = (N − b)/S`` by series reversion, ``f = x − D x² + 2D² x³ − …``,
  so ``f² = x² − 2D x³ + 5D² x⁴ + O(D³x⁵)``. Expanding ``x = (N − b)/S`` gives a polynomial in
  ``N`` up to the 4th power, linear in 13 lumped coefficients (``C0`` shared, ``C1i..C4i``
  per axis), fitted by ordinary least squares to ``ρ²``. With ``s = 1/S`` and ``K = D b s``:

      consistent third order          the paper's printed eq. 14
      C4 = 5 D² s⁴                     5 D² s⁴
      C3 = −2 D s³ (1 + 10K)           −2 D s³ (1 + 2K)
      C2 = s² (1 + 6K + 30K²)          s² (1 + 6K + 6K²)
      C1 = −2 b s² (1 + 3K + 10K²)     −2 b s² (1 + K)(1 + 2K)
      C0 = Σ s² b² (1 + 2K + 5K²)      Σ s² b² (1 + K)²

  The paper's column is the *second*-order expansion (``f² = x² − 2Dx³ + D²x⁴``) with only the
  ``N⁴`` coefficient patched to 5; the two differ by O(K) ≈ 10⁻⁵ relative. Closed forms
  (both variants): ``R = (C4/C3)(C1/C2)`` is a function of ``K`` alone (paper: ``5K(1+K)/(1+6K+6K²)``,
  its eq. 17-18) → ``K`` (the root that vanishes with ``D``; the printed eq. 19 takes the
  other root, ``K ≈ −1``) → ``S`` from ``C2`` (eq. 20) → ``D = sqrt(C4 S⁴/5)`` with the sign of
  ``−C3`` (eq. 21 loses the sign) → ``b = −C1 (…)/(2 C2 (…))`` (the printed eq. 22 has the
  ratio ``C1/C2`` upside down). The printed eq. 14 also writes ``C4i`` with a stray ``N⁴``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from solvers import linalg
from solvers.errors import NotIdentifiable, TooFewPositions
from solvers.fit import FitResult, fit, linear_fit
from solvers.models import accel
from solvers.tabletop import NORM_NOISE_FLOOR_G

GAMMA_FREE = np.array([False, False, True, False, True, True])  # γyx, γzx, γzy (see module doc)
AXES = "xyz"


def norm_target(speed_rad_s, radius_m: float, g_mps2: float) -> np.ndarray:
    """``ρ = |f|`` in g on a centrifuge: ``sqrt(A² + 1)``, ``A = ω²R/g`` (:func:`accel.centrifuge_input_g`)."""
    A = accel.centrifuge_input_g(speed_rad_s, radius_m, g_mps2)
    return np.sqrt(A * A + 1.0)


@dataclass
class P2Result:
    params: dict  # S, b, D (and gamma)
    sigma: dict
    method: str
    residuals: np.ndarray  # |f| − ρ per used row (g)
    used: np.ndarray  # bool mask of rows used
    residual_rms: float
    fit: FitResult | None
    noise_known: bool
    extra: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


def norm_residual(N: np.ndarray, rho: np.ndarray, params: dict) -> np.ndarray:
    """``|f(N)| − ρ`` with ``f`` the exact inverse of the model."""
    return np.linalg.norm(accel.inverse(N, params), axis=1) - rho


def norm_gradient(N: np.ndarray, params: dict) -> np.ndarray:
    """∂|f|/∂N (rows, (n, 3)): ``ûᵀ diag(1/(1 + 2 D f)) K⁻¹``."""
    f = accel.inverse(N, params)
    u = f / np.linalg.norm(f, axis=1, keepdims=True)
    D = np.asarray(params.get("D", np.zeros(3)))
    w = u / (1.0 + 2.0 * D * f)
    return w @ np.linalg.inv(accel.K_matrix(params))


def row_sigma(N, params, sigma_N) -> np.ndarray:
    """σ of ``|f|`` per row from the per-axis output noise ``sigma_N`` ((n, 3) or scalar)."""
    G = norm_gradient(N, params)
    sN = np.broadcast_to(np.asarray(sigma_N, dtype=float), N.shape)
    return np.sqrt(np.sum((G * sN) ** 2, axis=1))


def initial_guess(N: np.ndarray, rho: np.ndarray) -> dict:
    """Linear start: ``Σ_i (C2i N_i² + C1i N_i) + C0 = ρ²`` (an axis-aligned ellipsoid)."""
    H = np.column_stack([N**2, N, np.ones(len(N))])
    c, *_ = linalg.lstsq(H, rho**2, rcond=None)
    c2 = np.where(c[:3] > 0, c[:3], np.nan)
    S = 1.0 / np.sqrt(c2)
    b = -c[3:6] / (2.0 * c2)
    S = np.where(np.isfinite(S), S, 1.0)
    b = np.where(np.isfinite(b), b, 0.0)
    return {"S": S, "b": b, "D": np.zeros(3)}


def exact_fit(N, rho, *, sigma_N=None, gamma: bool = False, initial: dict | None = None) -> P2Result:
    """Weighted nonlinear least squares on ``|inverse(N)| = ρ`` (see module docstring).

    sigma_N: per-axis output noise, scalar or (n, 3); None = unknown (estimated from the
    residuals). gamma: also fit the installation angles: all 6 when the data identify them
    (the quadratic term is defined on the sensor's axes, so with enough g a rotation of the
    whole triad *is* visible, weakly), else the 3 of the triangular gauge (``extra['gamma_gauge']``)."""
    N = np.asarray(N, dtype=float)
    rho = np.asarray(rho, dtype=float)
    if not gamma:
        return _exact(N, rho, sigma_N, None, initial)
    try:
        res = _exact(N, rho, sigma_N, np.ones(6, bool), initial)
        if res.fit.condition_number < GAMMA_CONDITION_MAX and np.all(res.sigma["gamma"] < GAMMA_SIGMA_MAX):
            res.extra["gamma_gauge"] = "all"
            return res
    except NotIdentifiable:
        pass
    res = _exact(N, rho, sigma_N, GAMMA_FREE, initial)
    res.extra["gamma_gauge"] = "triangular"
    return res


GAMMA_SIGMA_MAX = 1e-2  # rad: a γ known worse than this is not worth reporting as determined
GAMMA_CONDITION_MAX = 1e6  # all six angles are fitted only where the fit is conditioned better than this


def _exact(N, rho, sigma_N, gamma_free, initial) -> P2Result:
    n_par = 9 + (0 if gamma_free is None else int(gamma_free.sum()))
    if len(N) <= n_par:
        raise TooFewPositions(f"{len(N)} rows; the exact fit of {n_par} coefficients needs more than {n_par}")
    if initial is not None:
        return _exact_from(N, rho, sigma_N, gamma_free, initial)
    # Two starts: the paper's closed forms can land the fit in a far local minimum (or a
    # degenerate point) when the data hold more than the model; keep the smaller |f| misfit.
    best, first_error = None, None
    for p0 in (paper_or_linear_start(N, rho), initial_guess(N, rho)):
        try:
            with np.errstate(over="ignore", invalid="ignore"):  # a far start may step through huge values
                res = _exact_from(N, rho, sigma_N, gamma_free, p0)
        except NotIdentifiable as exc:
            first_error = first_error or exc
            continue
        if not np.isfinite(res.residual_rms):
            continue
        if best is None or res.residual_rms < best.residual_rms:
            best = res
    if best is None:
        raise first_error or NotIdentifiable("the fit diverged from both starts (paper's closed forms and linear)")
    return best


def _exact_from(N, rho, sigma_N, gamma_free, p0) -> P2Result:
    p0 = {k: np.asarray(p0[k], dtype=float) for k in ("S", "b", "D")}
    free = {"S": True, "b": True, "D": True}
    if gamma_free is not None:
        p0["gamma"] = np.zeros(6)
        free["gamma"] = gamma_free
    noise_known = sigma_N is not None

    resid, jac = _residual_and_jacobian(N, rho, gamma_free)
    # Weights at the start (the paper's closed forms are close: the weights change by far
    # less than their own uncertainty at the solution).
    if noise_known:
        res = fit(resid, p0, free=free, sigma=row_sigma(N, p0, sigma_N), jac=jac)
    else:
        res = fit(resid, p0, free=free, sigma=row_sigma(N, p0, 1.0), jac=jac, scale_on_misfit=False)
        if res.dof > 0:  # relative weights: the noise scale is what the residuals say
            s = math.sqrt(res.reduced_chi2)
            res.cov = res.cov * s * s
            res.sigma = {k: v * s for k, v in res.sigma.items()}
            res.misfit_scaled = True
    if res.unidentifiable:
        raise NotIdentifiable(
            f"the rows cannot determine {', '.join(res.unidentifiable)} (condition number "
            f"{res.condition_number:.3g}): more orientations or speeds are needed"
        )
    out = {k: res.params[k] for k in p0}
    sig_out = {k: res.sigma[k] for k in p0}
    if gamma_free is not None:
        sig_out["gamma"] = np.where(gamma_free, sig_out["gamma"], 0.0)
    r = res.residuals
    return P2Result(
        out,
        sig_out,
        "exact" if gamma_free is None else "exact-gamma",
        r,
        np.ones(len(N), bool),
        float(np.sqrt(np.mean(r**2))),
        res,
        noise_known,
        extra={"reduced_chi2": res.reduced_chi2, "condition_number": res.condition_number},
    )


def _residual_and_jacobian(N, rho, gamma_free):
    cols = np.ones(9, bool) if gamma_free is None else np.r_[np.ones(9, bool), gamma_free]

    def resid(p):
        return norm_residual(N, rho, p)

    def jac(p):
        return accel.p2_norm_jacobian(N, p)[1][:, cols]

    return resid, jac


def paper_or_linear_start(N, rho) -> dict:
    """Start for the exact fit: the paper's closed forms when they give finite values, else linear."""
    try:
        p = paper_closed_form(paper_coefficients(N, rho)[0], variant="third-order")
        if all(np.all(np.isfinite(p[k])) for k in ("S", "b", "D")) and np.all(p["S"] > 0):
            return p
    except (ValueError, np.linalg.LinAlgError, FloatingPointError):
        pass
    return initial_guess(N, rho)


# ------------------------------------------------------------------- the paper's method


def paper_design(N: np.ndarray) -> np.ndarray:
    """Eq. 15's design matrix: ``[1, N_x, N_y, N_z, N_x², …, N_z⁴]`` (n, 13)."""
    N = np.asarray(N, dtype=float)
    return np.column_stack([np.ones(len(N))] + [N[:, i] ** k for k in (1, 2, 3, 4) for i in range(3)])


def paper_coefficients(N, rho) -> tuple[np.ndarray, FitResult]:
    """Eq. 16: ordinary least squares of the 13 lumped coefficients on ``ρ²``, columns
    scaled for conditioning; returns ``q = (C0, C11, C12, C13, C21, …, C43)`` and the fit."""
    H = paper_design(N)
    scale = np.abs(H).max(axis=0)
    scale[scale == 0] = 1.0
    res = linear_fit(H / scale, np.asarray(rho, dtype=float) ** 2)
    q = res.params["x"] / scale
    res.cov = res.cov / np.outer(scale, scale)
    return q, res


def _k_functions(variant: str):
    """(c1, c2, c3) factors of K in C1, C2, C3 (see module docstring)."""
    if variant == "paper":
        return (lambda K: (1 + K) * (1 + 2 * K), lambda K: 1 + 6 * K + 6 * K * K, lambda K: 1 + 2 * K)
    if variant == "third-order":
        return (lambda K: 1 + 3 * K + 10 * K * K, lambda K: 1 + 6 * K + 30 * K * K, lambda K: 1 + 10 * K)
    raise ValueError(f"unknown variant {variant!r}")


def paper_closed_form(q: np.ndarray, variant: str = "paper") -> dict:
    """Eqs. 17-22: S, b, D per axis from the 13 coefficients (typos corrected, see module doc)."""
    c1f, c2f, c3f = _k_functions(variant)
    S, b, D = np.zeros(3), np.zeros(3), np.zeros(3)
    for i in range(3):
        C1, C2, C3, C4 = q[1 + i], q[4 + i], q[7 + i], q[10 + i]
        ratio = (C4 / C3) * (C1 / C2)  # = 5 K c1(K) / (c3(K) c2(K))
        K = ratio / 5.0
        for _ in range(50):  # fixed point; K is ~1e-5 in practice
            K_new = ratio * c3f(K) * c2f(K) / (5.0 * c1f(K))
            if abs(K_new - K) <= 1e-16 + 1e-14 * abs(K):
                K = K_new
                break
            K = K_new
        if C2 <= 0:
            raise ValueError(f"C2{i + 1} = {C2:.3g} is not positive: no real scale factor")
        S[i] = math.sqrt(c2f(K) / C2)
        D[i] = -math.copysign(1.0, C3) * math.sqrt(max(C4, 0.0) * S[i] ** 4 / 5.0)
        b[i] = -C1 * c2f(K) / (2.0 * C2 * c1f(K))
    return {"S": S, "b": b, "D": D}


def paper_fit(N, rho, variant: str = "paper") -> P2Result:
    """The paper's method: eq. 16 then eqs. 17-22; σ by propagating the coefficients'
    covariance (scaled by the residual variance) through the closed forms."""
    N = np.asarray(N, dtype=float)
    rho = np.asarray(rho, dtype=float)
    if len(N) < 14:
        raise TooFewPositions(
            f"{len(N)} rows; the paper's 13-coefficient least squares needs more than 13 (it asks for at least 54)"
        )
    q, res = paper_coefficients(N, rho)
    if res.unidentifiable:
        raise NotIdentifiable(
            "the rows cannot determine the paper's 13 coefficients: the outputs need more "
            "spread (orientations and speeds)"
        )
    p = paper_closed_form(q, variant)
    x0 = np.concatenate([p["S"], p["b"], p["D"]])
    J = np.zeros((9, 13))
    for j in range(13):
        h = 1e-6 * max(abs(q[j]), 1e-30)
        qp, qm = q.copy(), q.copy()
        qp[j] += h
        qm[j] -= h
        a, c = paper_closed_form(qp, variant), paper_closed_form(qm, variant)
        J[:, j] = (np.concatenate([a["S"], a["b"], a["D"]]) - np.concatenate([c["S"], c["b"], c["D"]])) / (2 * h)
    cov = J @ res.cov @ J.T
    sg = np.sqrt(np.clip(np.diag(cov), 0, None))
    r = norm_residual(N, rho, p)
    return P2Result(
        p,
        {"S": sg[0:3], "b": sg[3:6], "D": sg[6:9]},
        "paper" if variant == "paper" else "paper-3rd",
        r,
        np.ones(len(N), bool),
        float(np.sqrt(np.mean(r**2))),
        None,
        False,
        extra={"coefficients": q, "polynomial_rms": float(np.sqrt(np.mean(res.residuals**2))), "x0": x0},
    )


# ------------------------------------------------------------------- screening rows


@dataclass
class Screen:
    used: np.ndarray  # bool: rows that agree with the model
    residuals: np.ndarray  # |f| − ρ of every row at the inlier fit (g)
    scale: float  # robust scale of the inliers' residuals (g)
    hints: dict  # row → text (e.g. a sign that would make it agree)


def screen_rows(N, rho, *, gamma: bool = False, threshold: float = 8.0) -> Screen:
    """Find rows that disagree with the model far beyond the others, without changing any.

    Annealed robust fit: start from the least-squares fit of every row; repeatedly fit with a
    Cauchy loss whose scale is the current robust spread of the residuals (1.4826 × median),
    until the set of rows beyond ``threshold`` × that spread stops changing. A row far off
    then has no pull on the fit, however many there are (up to about half). For each
    rejected row, say whether flipping the sign of one output would make it agree (a lost
    minus sign in a transcribed table)."""
    N = np.asarray(N, dtype=float)
    rho = np.asarray(rho, dtype=float)
    first = exact_fit(N, rho, gamma=gamma)
    p = first.params
    gfree = None
    free = {"S": True, "b": True, "D": True}
    if gamma:
        gfree = np.ones(6, bool) if first.extra.get("gamma_gauge") == "all" else GAMMA_FREE
        free["gamma"] = gfree
    resid, jac = _residual_and_jacobian(N, rho, gfree)
    prev, prev_s = None, math.inf
    rel = row_sigma(N, p, 1.0)
    z = norm_residual(N, rho, p) / rel
    # the spread is at least the noise floor of any real average (0.1 µg, as P1's calibration):
    # an exact table's rounding spreads 1.3e-15 g, and a row 1.4e-14 g off was left out as 8σ
    floor = NORM_NOISE_FLOOR_G / float(np.median(rel))
    s = max(1.4826 * float(np.median(np.abs(z))), floor, 1e-300)
    if np.all(np.abs(z) <= threshold * s):  # the least-squares fit already explains every row
        return Screen(np.ones(len(N), bool), z * rel, s * float(np.median(rel)), {})
    for _ in range(15):
        rel = row_sigma(N, p, 1.0)
        z = norm_residual(N, rho, p) / rel
        s = max(1.4826 * float(np.median(np.abs(z))), NORM_NOISE_FLOOR_G / float(np.median(rel)), 1e-300)
        out = np.abs(z) > threshold * s
        if prev is not None and np.array_equal(out, prev) and s > 0.5 * prev_s:
            break
        prev, prev_s = out, s
        p = fit(resid, p, free=free, sigma=rel * s, jac=jac, loss="cauchy").params
    used = ~out
    rel = row_sigma(N, p, 1.0)
    r = norm_residual(N, rho, p)
    hints = {}
    for k in np.flatnonzero(~used):
        for i in range(3):
            M2 = N[k].copy()
            M2[i] = -M2[i]
            rk = float(norm_residual(M2[None], rho[k : k + 1], p)[0] / rel[k])
            if abs(rk) <= threshold * s:
                hints[int(k)] = f"would agree with a{AXES[i]} = {M2[i]:.6g} (a lost minus sign?)"
                break
    return Screen(used, r, s * float(np.median(rel)), hints)
