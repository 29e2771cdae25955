"""Gyro triad calibration from the rotations between static poses (the gyro half of P1).

After Tedaldi, Pretto & Menegatti (ICRA 2014, imu_tk), derived here for the station's one
gyro model (``solvers.models.gyro``): raw output ``y = K ω + ε + G f`` (``K`` [3x3] raw units
per rad/s: scale factors on the diagonal, misalignment off it; ``ε`` [3] bias in raw units;
``G`` [3x3] g-sensitivity, raw units per m/s² of specific force ``f``).

Two kinds of rows, fitted together by weighted least squares (``solvers.fit``):

- **holds** (3 rows each): the hold's mean output ``ȳ_k = K ω_e,k + ε + G f_k``, σ the mean's
  standard error (correlated noise included). ``f_k`` is the calibrated specific force (the
  accelerometer calibration applied), ``ω_e,k`` the Earth rate: its vertical part
  ``Ω sin L u_k`` along the hold's up direction ``u_k = f_k/|f_k|`` (known with a latitude;
  without one ``w_U`` is fitted with its physical bound ``0 ± Ω/√3`` as a weak prior), its
  horizontal part (``Ω cos L``, heading unknown) as noise in σ. The holds give ε and, when
  they span enough orientations, ``G`` (imucal/Ferraris style, but from every hold).
- **rotations** (2 rows each): the motion between hold k and hold k+1 is integrated with the
  candidate model (``ω = K⁻¹(y − ε − G f)``, ``models.gyro.integrate_rates``) and must carry
  hold k's gravity direction into hold k+1's: ``E_{k+1} Rᵀ u_k = 0``, ``E_{k+1}`` the two unit
  vectors perpendicular to ``u_{k+1}``. σ² = angle random walk over the motion
  (``σ_ω² Σ dt²``) + both holds' direction noise + the horizontal Earth rate over its time.
  The rotations give ``K``: 9 parameters, relative to the accelerometer's frame (whatever
  gauge its calibration used), which is the frame the directions are in.

Analytic Jacobian: a change ``δω_j`` of the rate at step j turns the result by
``R exp([δθ]×)``, ``δθ = Σ Q_j δφ_j`` (``integrate_rates``), and the residual by
``E [v]× δθ``, ``v = Rᵀ u_k``; ``δω = −K⁻¹ (δK ω + δε + δG f)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from solvers.errors import NotIdentifiable, SolverError, TooFewPositions
from solvers.fit import FitResult, fit
from solvers.frames import OMEGA_EARTH_RAD_S, skew
from solvers.models import Conditions, gyro

MIN_MOTIONS = 5  # rotations needed for 9 scale/misalignment parameters (2 rows each)
G_MIN_ORIENTATIONS = 6  # distinct hold directions before g-sensitivity is fitted
# the fitted rotations carry gravity from hold to hold within a fraction of a degree (simulated
# < 0.1°, imu_tk's Xsens session 0.2°): a fit that misses by this much RMS describes no gyro
MAX_DIRECTION_RMS_DEG = 10.0
# evaluations per free parameter (+1) before a fit still that far off is given up: well-posed
# fits converge in under one (solvers.fit); a gyro record that is not this accelerometer's ran
# to the full bound (20 (p + 1), ten seconds) and stopped at a degenerate K
FIRST_NFEV_PER_PARAM = 5


@dataclass
class Hold:
    """One static pose: raw gyro mean (3,) and its standard error (3,), the calibrated
    specific force (3,) m/s², its direction's 1σ per component (rad)."""

    label: str
    y_mean: np.ndarray
    y_se: np.ndarray
    f_mps2: np.ndarray
    dir_sigma_rad: float
    t_start_s: float | None = None
    t_stop_s: float | None = None

    @property
    def u(self) -> np.ndarray:
        return self.f_mps2 / np.linalg.norm(self.f_mps2)


@dataclass
class Motion:
    """The samples between hold ``k0``'s last and hold ``k1``'s first sample (inclusive):
    times (n,) s, raw gyro (n, 3), calibrated specific force (n, 3) m/s²."""

    k0: int
    k1: int
    t_s: np.ndarray
    y: np.ndarray
    f_mps2: np.ndarray


@dataclass
class GyroResult:
    K: np.ndarray
    eps: np.ndarray
    G: np.ndarray | None
    sigma_K: np.ndarray
    sigma_eps: np.ndarray
    sigma_G: np.ndarray | None
    earth_rate_up_rad_s: float
    sigma_earth_rate_up_rad_s: float
    direction_residual_rad: np.ndarray  # angle between predicted and measured u_{k1}, per motion
    direction_sigma_rad: np.ndarray  # the σ used per motion (per component)
    hold_residual: np.ndarray  # (n_holds, 3) raw units
    fit: FitResult
    latitude_deg: float | None
    warnings: list[str] = field(default_factory=list)

    @property
    def direction_rms_rad(self) -> float:
        return float(np.sqrt(np.mean(self.direction_residual_rad**2)))

    def params(self) -> dict:
        out = {"K": self.K, "eps": self.eps}
        if self.G is not None:
            out["G"] = self.G
        return out


def _perp_basis(u: np.ndarray) -> np.ndarray:
    a = np.eye(3)[int(np.argmin(np.abs(u)))]
    e1 = np.cross(u, a)
    e1 /= np.linalg.norm(e1)
    return np.vstack([e1, np.cross(u, e1)])


class Batch:
    """The motions padded to one length for batched integration."""

    def __init__(self, motions: list[Motion]):
        n = max(len(m.t_s) for m in motions)
        self.m = len(motions)
        self.t = np.empty((self.m, n))
        self.y = np.empty((self.m, n, 3))
        self.f = np.empty((self.m, n, 3))
        for i, mo in enumerate(motions):
            k = len(mo.t_s)
            self.t[i, :k], self.t[i, k:] = mo.t_s, mo.t_s[-1]
            self.y[i, :k], self.y[i, k:] = mo.y, mo.y[-1]
            self.f[i, :k], self.f[i, k:] = mo.f_mps2, mo.f_mps2[-1]
        self.dt = np.diff(self.t, axis=1)
        self.duration = self.t[:, -1] - self.t[:, 0]

    def rates(self, p: dict) -> np.ndarray:
        """ω (m, n, 3) rad/s under the model ``p`` (``models.gyro.inverse``)."""
        flat = self.y.reshape(-1, 3)
        cond = Conditions(f_mps2=self.f.reshape(-1, 3)) if "G" in p else None
        return gyro.inverse(flat, p, cond).reshape(self.y.shape)


def direction_residuals(params: dict, holds: list[Hold], motions: list[Motion]) -> np.ndarray:
    """Angle (rad) between hold k1's measured gravity direction and hold k0's carried across
    the motion by ``params`` (``K``, ``eps``, optional ``G``): the figure of merit, in sample
    or on held-out motions."""
    if not motions:
        return np.zeros(0)
    b = Batch(motions)
    R = gyro.integrate_rates(b.rates(params), b.t)
    out = []
    for i, mo in enumerate(motions):
        v = R[i].T @ holds[mo.k0].u
        out.append(math.atan2(np.linalg.norm(np.cross(v, holds[mo.k1].u)), float(v @ holds[mo.k1].u)))
    return np.array(out)


def scale_search(holds: list[Hold], motions: list[Motion], lo: float = 1e-2, hi: float = 1e6) -> float:
    """An isotropic starting scale (raw units per rad/s) when the unit does not say: the one of a
    log grid whose integrated rotations best carry the gravity directions, then refined by
    golden section (on motions thinned to ~25 Hz: a start, not the answer)."""
    eps = np.mean([h.y_mean for h in holds], axis=0)
    rate = np.median([len(m.t_s) / max(m.t_s[-1] - m.t_s[0], 1e-9) for m in motions])
    step = max(1, int(rate // 25))
    b = Batch([Motion(m.k0, m.k1, m.t_s[::step], m.y[::step], m.f_mps2[::step]) for m in motions])
    U0 = np.array([holds[m.k0].u for m in motions])
    U1 = np.array([holds[m.k1].u for m in motions])

    def cost(s):
        R = gyro.integrate_rates((b.y - eps) / s, b.t)
        return float(np.mean(np.sum((np.einsum("mji,mj->mi", R, U0) - U1) ** 2, axis=1)))

    grid = np.exp(np.linspace(math.log(lo), math.log(hi), 81))
    j = int(np.argmin([cost(s) for s in grid]))
    a, c = grid[max(j - 1, 0)], grid[min(j + 1, len(grid) - 1)]
    for _ in range(30):  # golden section on log s
        m1, m2 = a * (c / a) ** 0.382, a * (c / a) ** 0.618
        if cost(m1) < cost(m2):
            c = m2
        else:
            a = m1
    return math.sqrt(a * c)


def calibrate(
    holds: list[Hold],
    motions: list[Motion],
    K0,
    *,
    noise_raw,
    latitude_deg: float | None = None,
    fit_g: bool | None = None,
) -> GyroResult:
    """Fit ``K``, ``ε`` (and ``G``) to the holds and the rotations (module docstring).

    ``K0`` the starting gain (raw units per rad/s, e.g. ``I / unit factor``); ``noise_raw`` the
    gyro's per-sample noise (3,) in raw units (the holds' scatter); ``fit_g`` None: fit the
    g-sensitivity when the holds span at least ``G_MIN_ORIENTATIONS`` directions in 3-D.
    Raises TooFewPositions / NotIdentifiable with the reason."""
    if len(motions) < MIN_MOTIONS:
        raise TooFewPositions(f"{len(motions)} rotations between holds; the gyro fit needs at least {MIN_MOTIONS}")
    W = OMEGA_EARTH_RAD_S
    warnings: list[str] = []
    U = np.array([h.u for h in holds])
    F = np.array([h.f_mps2 for h in holds])
    n_dirs = _distinct(U)
    spans = np.linalg.matrix_rank(np.column_stack([np.ones(len(F)), F]), tol=1e-3 * np.abs(F).max()) == 4
    if fit_g is None:
        fit_g = n_dirs >= G_MIN_ORIENTATIONS and spans
        if not fit_g:
            warnings.append(
                f"g-sensitivity not fitted: the holds span {n_dirs} distinct directions "
                f"(needs {G_MIN_ORIENTATIONS} in 3-D); the bias then contains G·f averaged over them"
            )
    K0 = np.asarray(K0, dtype=float)
    scale0 = np.abs(np.diag(K0))
    if latitude_deg is not None:
        lat = math.radians(latitude_deg)
        w_up0, horiz = W * math.sin(lat), W * abs(math.cos(lat))
    else:
        w_up0, horiz = 0.0, W
    # hold rows: σ² = se² + horizontal Earth rate (unknown direction) through the scale
    sig_h = np.sqrt(np.array([h.y_se**2 for h in holds]) + 0.5 * (scale0 * horiz) ** 2).ravel()
    b = Batch(motions)
    E = np.array([_perp_basis(holds[m.k1].u) for m in motions])  # (m, 2, 3)
    u0 = np.array([holds[m.k0].u for m in motions])
    sig_w = float(np.mean(np.asarray(noise_raw, dtype=float) / scale0))  # rad/s per sample
    arw2 = sig_w**2 * np.sum(b.dt**2, axis=1)
    dir2 = np.array([holds[m.k0].dir_sigma_rad ** 2 + holds[m.k1].dir_sigma_rad ** 2 for m in motions])
    sig_r = np.sqrt(arw2 + dir2 + 0.5 * (horiz * b.duration) ** 2)
    sigma = np.concatenate([sig_h, np.repeat(sig_r, 2)] + ([[1.0]] if latitude_deg is None else []))
    eps0 = np.mean([h.y_mean for h in holds], axis=0) - K0 @ (w_up0 * U.mean(axis=0))
    init = {"K": K0, "eps": eps0, "G": np.zeros((3, 3)), "wU": np.array(w_up0)}
    free = {"K": True, "eps": True, "G": bool(fit_g), "wU": latitude_deg is None}
    Ybar = np.array([h.y_mean for h in holds])
    nh = len(holds)

    def model(p):
        m = {"K": p["K"], "eps": p["eps"]}
        if fit_g:
            m["G"] = p["G"]
        return m

    hold_cond = Conditions(f_mps2=F)

    def resid(p):
        hold = gyro.forward(U * p["wU"], model(p), hold_cond) - Ybar  # K ω + ε (+ G f) at each hold
        R = gyro.integrate_rates(b.rates(model(p)), b.t)
        v = np.einsum("mji,mj->mi", R, u0)  # Rᵀ u_k0
        rot = np.einsum("mci,mi->mc", E, v).ravel()
        out = [hold.ravel(), rot]
        if latitude_deg is None:
            out.append([p["wU"] / (W / math.sqrt(3.0))])
        return np.concatenate(out)

    def jac(p):
        K, G = p["K"], p["G"]  # noqa: F841
        A = np.linalg.inv(K)
        cols = []
        # holds: d/dK_ab = e_a (wU u)[b]; d/deps = I; d/dG_ab = e_a f[b]; d/dwU = K u
        Jh_K = np.einsum("ac,kb->kcab", np.eye(3), U * p["wU"]).reshape(3 * nh, 9)
        Jh_e = np.tile(np.eye(3), (nh, 1))
        Jh_G = np.einsum("ac,kb->kcab", np.eye(3), F).reshape(3 * nh, 9)
        Jh_w = (U @ K.T).reshape(3 * nh, 1)
        # rotations
        w = b.rates(model(p))
        R, Q = gyro.integrate_rates(w, b.t, with_jacobian=True)
        v = np.einsum("mji,mj->mi", R, u0)
        Ev = np.einsum("mci,mij->mcj", E, skew(v))  # E [v]×  (m, 2, 3)
        Bj = b.dt[..., None, None] * (Q @ A)  # (m, n-1, 3, 3)
        wm = 0.5 * (w[:, 1:] + w[:, :-1])
        fm = 0.5 * (b.f[:, 1:] + b.f[:, :-1])
        dK = -np.einsum("mjca,mjb->mcab", Bj, wm).reshape(len(motions), 3, 9)
        de = -Bj.sum(axis=1)
        dG = -np.einsum("mjca,mjb->mcab", Bj, fm).reshape(len(motions), 3, 9)
        Jr_K = np.einsum("mcj,mjk->mck", Ev, dK).reshape(-1, 9)
        Jr_e = np.einsum("mcj,mjk->mck", Ev, de).reshape(-1, 3)
        Jr_G = np.einsum("mcj,mjk->mck", Ev, dG).reshape(-1, 9)
        Jr_w = np.zeros((len(Jr_K), 1))
        blocks = [("K", Jh_K, Jr_K), ("eps", Jh_e, Jr_e), ("G", Jh_G, Jr_G), ("wU", Jh_w, Jr_w)]
        for name, jh, jr in blocks:
            if free[name]:
                col = np.vstack([jh, jr])
                if latitude_deg is None:
                    prior = np.zeros((1, col.shape[1]))
                    if name == "wU":
                        prior[0, 0] = math.sqrt(3.0) / W
                    col = np.vstack([col, prior])
                cols.append(col)
        return np.hstack(cols)

    n_free = sum(int(np.size(v)) for k, v in init.items() if free[k])
    res = fit(resid, init, free=free, sigma=sigma, jac=jac, max_nfev=FIRST_NFEV_PER_PARAM * (n_free + 1))
    if res.status == 0 and _rms_deg(direction_residuals(model(res.params), holds, motions)) <= MAX_DIRECTION_RMS_DEG:
        res = fit(resid, res.params, free=free, sigma=sigma, jac=jac)  # slow but on its way: the full bound
    p = res.params
    dres = direction_residuals(model(p), holds, motions)
    miss_deg = _rms_deg(dres)
    if not miss_deg <= MAX_DIRECTION_RMS_DEG:
        raise SolverError(
            f"the rotations the gyro integrates do not carry gravity from one hold to the next: the best "
            f"fit misses by {miss_deg:.0f}° RMS over {len(motions)} rotations (a calibration misses by well "
            "under 1°); check that the gyro columns are this unit's, recorded with the accelerometer, in "
            "the stated unit and at the stated sample times"
        )
    if res.unidentifiable and fit_g and any(n.startswith("G") for n in res.unidentifiable):
        out = calibrate(holds, motions, K0, noise_raw=noise_raw, latitude_deg=latitude_deg, fit_g=False)
        out.warnings[:0] = ["g-sensitivity not identifiable from these holds: not fitted"]
        return out
    if res.unidentifiable:
        raise NotIdentifiable(
            f"the rotations between the holds cannot determine {', '.join(res.unidentifiable)} "
            "(turn the unit about all three axes between holds)"
        )
    hold_r = res.residuals[: 3 * nh].reshape(nh, 3)
    if res.misfit_scaled:
        warnings.append(
            f"gyro: the residuals are {math.sqrt(res.reduced_chi2):.1f}× their expected size (reduced "
            f"χ² {res.reduced_chi2:.3g}): the holds' bias or the rotations are not explained to the "
            "noise (bias drifting between holds, a motion partly inside a hold?); uncertainties scaled up"
        )
    zr = dres / sig_r
    med = float(np.median(np.abs(zr)))
    for i in np.flatnonzero(np.abs(zr) > 5 * max(med, 1.0) * 1.4826):
        mo = motions[i]
        warnings.append(
            f"gyro: the rotation from hold {holds[mo.k0].label} to {holds[mo.k1].label} misses by "
            f"{math.degrees(dres[i]):.2f}° ({zr[i]:.0f}σ): clipped rate, or moved during a hold? (kept)"
        )
    sig = res.sigma
    return GyroResult(
        K=p["K"],
        eps=p["eps"],
        G=p["G"] if fit_g else None,
        sigma_K=sig["K"],
        sigma_eps=sig["eps"],
        sigma_G=sig["G"] if fit_g else None,
        earth_rate_up_rad_s=float(p["wU"]),
        sigma_earth_rate_up_rad_s=float(sig["wU"]),
        direction_residual_rad=dres,
        direction_sigma_rad=sig_r,
        hold_residual=hold_r,
        fit=res,
        latitude_deg=latitude_deg,
        warnings=warnings,
    )


def _rms_deg(direction_residual_rad: np.ndarray) -> float:
    """RMS in degrees of the per-rotation direction residuals (``direction_residuals``)."""
    d = direction_residual_rad
    return math.degrees(float(np.sqrt(np.mean(d**2)))) if d.size else 0.0


def _distinct(U: np.ndarray, max_angle_deg: float = 7.0) -> int:
    cos_t = math.cos(math.radians(max_angle_deg))
    centres: list[np.ndarray] = []
    for u in U:
        if not any(float(u @ c) >= cos_t for c in centres):
            centres.append(u)
    return len(centres)
