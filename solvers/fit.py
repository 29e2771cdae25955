"""One fitting engine: weighted nonlinear least squares over named parameter blocks.

``fit(residual_fn, initial, free=..., sigma=...)`` minimises ``Σ (r_i / σ_i)²`` where
``residual_fn(params) -> r`` returns model minus data (any units; ``σ`` in the same).
It returns a :class:`FitResult` with the parameters, 1-sigma uncertainties from the
covariance ``(Jᵀ W J)⁻¹``, the residuals, convergence status and message (scipy's), the
condition number of the column-scaled Jacobian, and the parameters the data cannot
identify (reported by name, their uncertainty NaN, instead of noise).

Gauge freedom (a norm condition cannot see rotations, a scale can trade against a
field magnitude, ...) is handled explicitly by the caller through ``free``: fix the
elements that define the gauge. Whatever null space remains is detected from the
singular values and reported in ``null_space``.

Misfit: when the weighted residuals exceed what ``σ`` allows (reduced χ² significantly
above 1: beyond 1 + 3·sqrt(2/dof)), the covariance is scaled by the reduced χ², so
uncertainties account for the misfit (calibrate.md). Without ``sigma`` the noise is
estimated from the residuals (covariance always scaled by the reduced χ²).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from solvers import linalg
from solvers.errors import NotFinite
from solvers.params import Packer, Params


@dataclass
class FitResult:
    """What a fit found, and how far to trust it. Every array is a plain numpy array."""

    params: Params  # all blocks (fixed ones as given)
    sigma: Params  # 1-sigma, same shapes; 0 fixed, NaN unidentifiable
    names: list[str]  # names of the free scalar elements, in x order
    x: np.ndarray  # free elements
    cov: np.ndarray  # covariance of x (scaled as documented)
    residuals: np.ndarray  # r = model − data at the solution (unweighted)
    weighted_residuals: np.ndarray  # r / σ
    chi2: float  # Σ (r/σ)²
    dof: int  # len(r) − identifiable free parameters
    reduced_chi2: float
    misfit_scaled: bool  # covariance scaled by reduced χ²
    condition_number: float  # of the column-scaled weighted Jacobian
    unidentifiable: list[str]
    null_space: list[dict[str, float]]  # unit null directions over free names (large parts only)
    success: bool
    status: int
    message: str
    nfev: int
    singular_values: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.residuals**2))) if self.residuals.size else 0.0

    def correlation(self) -> np.ndarray:
        d = np.sqrt(np.diag(self.cov))
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.cov / np.outer(d, d)

    def sigma_of(self, name: str) -> float:
        return float(np.sqrt(self.cov[self.names.index(name), self.names.index(name)]))


def fit(
    residual_fn: Callable[[Params], np.ndarray],
    initial: Mapping[str, object],
    *,
    free: Mapping[str, object] | None = None,
    sigma: float | np.ndarray | None = None,
    jac: Callable[[Params], np.ndarray] | None = None,
    loss: str = "linear",
    max_nfev: int | None = None,
    ident_rtol: float = 1e-8,
    scale_on_misfit: bool = True,
    method: str | None = None,
) -> FitResult:
    """Weighted least squares; see the module docstring.

    ``free`` maps block name → bool (or bool array of the block's shape); blocks not in
    it are fixed. ``None`` frees everything. ``jac``, if given, returns d r / d x for the
    free elements (N, n_free) at ``params``.
    """
    packer = Packer.build(initial, free)
    x0 = packer.pack(packer.template)
    weights = None
    if sigma is not None:
        weights = 1.0 / np.asarray(sigma, dtype=float)

    def fun(x: np.ndarray) -> np.ndarray:
        r = np.asarray(residual_fn(packer.unpack(x)), dtype=float).ravel()
        return r * weights if weights is not None else r

    jac_arg: object = "2-point"
    if jac is not None:

        def jac_arg(x: np.ndarray) -> np.ndarray:  # noqa: F811 - a closure, by design
            J = np.asarray(jac(packer.unpack(x)), dtype=float)
            return J * np.reshape(weights, (-1, 1)) if weights is not None else J

    r0 = fun(x0)
    if not np.all(np.isfinite(r0)):
        raise NotFinite(
            "the residual is not finite at the starting point: values beyond what the model can "
            "carry (overflowing or absurd readings)"
        )
    n, p = r0.size, x0.size
    if method is None:
        method = "lm" if (n >= p and loss == "linear") else "trf"
    if p == 0:
        sol_x, status, message, nfev, success = x0, 1, "nothing to fit", 1, True
    else:
        if max_nfev is None:  # bounded: well-posed fits here converge in under (p + 1) evaluations;
            max_nfev = MAX_NFEV_PER_PARAM * (p + 1)  # absurd data no longer iterate for minutes
        sol = least_squares(
            fun,
            x0,
            jac=jac_arg,
            method=method,
            loss=loss,
            x_scale="jac",
            max_nfev=max_nfev,
            xtol=1e-12,
            ftol=1e-12,
            gtol=1e-12,
        )
        sol_x, status, message, nfev, success = sol.x, sol.status, sol.message, sol.nfev, bool(sol.success)
    return summarise(
        packer,
        sol_x,
        fun,
        jac_arg,
        status=status,
        message=message,
        nfev=nfev,
        success=success,
        weights=weights,
        ident_rtol=ident_rtol,
        scale_on_misfit=scale_on_misfit,
        sigma_given=sigma is not None,
    )


# Residual evaluations allowed per free parameter (+1) when the caller gives no max_nfev: the
# station's fits on real and simulated data converge in at most ~0.7 (p + 1) (measured on the
# five procedures' captures); scipy's own default for 'lm' with a numeric Jacobian is
# 100 p (p + 1), minutes on a capture whose columns were swapped.
MAX_NFEV_PER_PARAM = 20


def _numeric_jacobian(fun, x: np.ndarray) -> np.ndarray:
    f0 = fun(x)
    J = np.empty((f0.size, x.size))
    for k in range(x.size):
        h = 1e-7 * max(1.0, abs(x[k]))
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        J[:, k] = (fun(xp) - fun(xm)) / (2 * h)
    return J


def summarise(
    packer: Packer,
    x: np.ndarray,
    fun,
    jac_arg,
    *,
    status: int,
    message: str,
    nfev: int,
    success: bool,
    weights,
    ident_rtol: float,
    scale_on_misfit: bool,
    sigma_given: bool,
) -> FitResult:
    """Covariance, identifiability and misfit at the solution ``x``."""
    rw = fun(x)
    p = x.size
    J = jac_arg(x) if callable(jac_arg) else _numeric_jacobian(fun, x) if p else np.zeros((rw.size, 0))
    names = packer.names
    colnorm = np.linalg.norm(J, axis=0) if p else np.zeros(0)
    dead = colnorm <= 1e-300
    safe = np.where(dead, 1.0, colnorm)
    Js = J / safe
    if p:
        U, s, Vt = linalg.svd(Js, full_matrices=False)
    else:
        s, Vt = np.zeros(0), np.zeros((0, 0))
    smax = float(s.max()) if s.size else 0.0
    keep = s > ident_rtol * smax if smax > 0 else np.zeros_like(s, dtype=bool)
    cond = float(smax / s[keep].min()) if keep.any() else math.inf
    if p and not keep.all():
        cond = math.inf
    null_vecs = Vt[~keep] if p else np.zeros((0, 0))
    unident_mask = dead.copy()
    null_space: list[dict[str, float]] = []
    for v in null_vecs:
        big = np.abs(v) > 0.1
        unident_mask |= big
        null_space.append({names[i]: float(v[i]) for i in np.flatnonzero(big)})
    # Covariance on the identifiable subspace (pseudo-inverse), scaled back.
    if p:
        inv_s2 = np.where(keep, 1.0 / np.where(keep, s, 1.0) ** 2, 0.0)
        cov_s = (Vt.T * inv_s2) @ Vt
        cov = cov_s / np.outer(safe, safe)
    else:
        cov = np.zeros((0, 0))
    n_ident = int(keep.sum())
    chi2 = float(rw @ rw)
    dof = max(rw.size - n_ident, 0)
    red = chi2 / dof if dof > 0 else math.nan
    scaled = False
    if dof > 0:
        if not sigma_given:
            cov = cov * red
            scaled = True
        elif scale_on_misfit and red > 1.0 + 3.0 * math.sqrt(2.0 / dof):
            cov = cov * red
            scaled = True
    sig = np.sqrt(np.clip(np.diag(cov), 0.0, None)) if p else np.zeros(0)
    sig = np.where(unident_mask, np.nan, sig)
    r = rw / weights if weights is not None else rw
    return FitResult(
        params=packer.unpack(x),
        sigma=packer.unpack_sigma(sig),
        names=names,
        x=x,
        cov=cov,
        residuals=r,
        weighted_residuals=rw,
        chi2=chi2,
        dof=dof,
        reduced_chi2=red,
        misfit_scaled=scaled,
        condition_number=cond,
        unidentifiable=[names[i] for i in np.flatnonzero(unident_mask)],
        null_space=null_space,
        success=success,
        status=int(status),
        message=str(message),
        nfev=int(nfev),
        singular_values=s,
    )


def linear_fit(
    H: np.ndarray, y: np.ndarray, sigma: float | np.ndarray | None = None, names: list[str] | None = None, **kw
) -> FitResult:
    """Ordinary/weighted linear least squares ``y ≈ H x`` through the same engine (one
    result type, one identifiability test): ``x`` comes back as block ``'x'``."""
    H = np.asarray(H, dtype=float)
    y = np.asarray(y, dtype=float)
    x_ls, *_ = linalg.lstsq(H, y, rcond=None)
    res = fit(lambda p: H @ p["x"] - y, {"x": x_ls}, sigma=sigma, jac=lambda p: H, **kw)
    if names is not None:
        res.names = list(names)
        res.unidentifiable = [names[int(n[2:-1])] for n in res.unidentifiable]
    return res
