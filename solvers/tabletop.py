"""P1: accelerometer calibration on a level table (source 000, CN102636665A), re-done soundly.

Calibration ``A = B + M V`` (``solvers.models.accel.p1_apply``; ``V`` raw, ``A`` m/s²).
Input: static positions (mean raw output, its per-axis standard deviation and sample count,
and, where the operator was told, the known specific-force direction).

Two stages, as the source has them:

- **Step 8** (:func:`step8`): at positions whose gravity direction ``u`` is known (the six
  ±axis positions, or any label of ``solvers.positions.P1_POSITIONS``) ``B + M V_k = g u_k``:
  3 linear equations per position, 12 unknowns, weighted least squares. Its error is
  dominated by how well the operator placed the device (``σ = g·σ_place``).
- **Step 10** (:func:`calibrate`): the norm condition ``|B + M V_k| = g`` over *all*
  positions, Gauss-Newton (``solvers.fit``) from the step-8 values, each row weighted by the
  measured noise of its average (``σ_k² = ûᵀ M Σ_V M ᵀû``, ``Σ_V = diag(std²/n)``).

Gauge. ``|R(B + M V)| = |B + M V|`` for every rotation ``R``: the norm cannot see 3 of the
12 coefficients (the source's Newton step on 12 equations is singular). Two gauges:

- ``table`` (when labelled positions fix it): the orientation is the one the labelled
  positions define. Each labelled position adds its two vector components *perpendicular*
  to the expected direction, ``e₁·A_k = e₂·A_k = 0``, weighted by the placement error
  (default σ 0.4° per component on flat faces, 1.1° on the 45°/135° blocks). The norm rows
  (σ ~ 10⁻⁴ m/s²) fix everything else, the vector rows (σ ~ 0.07 m/s²) only the rotation,
  so this is the statistically weighted union of steps 8 and 10 and all 12 parameters are
  identifiable.
- ``upper-triangular`` (no labels, or asked for): ``M`` is upper triangular (imu_tk's
  convention: the frame's z axis is the sensor's z sensing axis, its y axis lies in the
  sensor's y-z plane); 9 free parameters.

Everything here is pure numerics; :mod:`station.procedures.tabletop` reads captures.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from solvers import linalg
from solvers.errors import NotIdentifiable, TooFewPositions
from solvers.fit import FitResult, fit, linear_fit
from solvers.models import accel
from solvers.positions import P1_POSITIONS

# Placement error per perpendicular component (rad): flat face on a table that is level to
# ~0.5°, and a hand-held 45°/135° block (±3°).
PLACEMENT_SIGMA_AXIS_RAD = math.radians(0.4)
PLACEMENT_SIGMA_TILTED_RAD = math.radians(1.1)
DISTINCT_ANGLE_DEG = 7.0  # two positions closer than this are one orientation
MIN_DISTINCT = 9  # the norm fit's 9 identifiable parameters
# The smallest norm noise (as a fraction of g) an estimate from the residuals may give: 0.1 µg,
# below any real average (a navigation-grade accelerometer, 10 µg/√Hz held 5 min, averages to
# ~0.6 µg). Noise-free simulated holds written at full precision left residuals of ~1e-15 m/s²;
# weighted against the placement σ of the labelled directions (0.07 m/s²) the rotation columns
# fell 1e14 below the norm rows and the fit called the off-diagonal of M undeterminable.
NORM_NOISE_FLOOR_G = 1e-7
CONDITION_WARN = 30.0  # position-set condition above this: warn "too alike"
# A label whose direction lies further than this from its position's reading (after the one
# rotation that best matches all labelled readings to their directions) does not describe it;
# beyond any placement error, and the P1 set's positions lie 45° or more apart
LABEL_AGREEMENT_DEG = 20.0
LABEL_CHECK_MIN_POSITIONS = 12  # 3 degrees of freedom beyond the norm fit's 9 parameters

# Source numbering (positions 1-6) and the station's order for 7-12; imucal's names.
_ORDER = list(P1_POSITIONS)
_ALIASES = {
    "x_p": "x_up",
    "x_a": "x_down",
    "y_p": "y_up",
    "y_a": "y_down",
    "z_p": "z_up",
    "z_a": "z_down",
    "+x": "x_up",
    "-x": "x_down",
    "+y": "y_up",
    "-y": "y_down",
    "+z": "z_up",
    "-z": "z_down",
    "x+": "x_up",
    "x-": "x_down",
    "y+": "y_up",
    "y-": "y_down",
    "z+": "z_up",
    "z-": "z_down",
}


def known_direction(label: str | None) -> tuple[np.ndarray | None, float]:
    """Unit specific-force direction and placement σ (rad) for a position label, or (None, nan).

    Labels: the names of ``P1_POSITIONS``, integers 1-12 in that order (1-6 are the
    source's X up, X down, Y up, Y down, Z up, Z down; '3.0' is 3, as pandas writes an integer
    column with gaps), and imucal's ``x_p``/``x_a``/….
    """
    if not label:
        return None, math.nan
    key = str(label).strip().lower()
    whole = re.fullmatch(r"([0-9]+)\.0*", key)  # '3.0': an integer as a float column writes it
    if whole:
        key = whole.group(1)
    if key.isdigit() and 1 <= int(key) <= len(_ORDER):
        key = _ORDER[int(key) - 1]
    key = _ALIASES.get(key, key)
    if key not in P1_POSITIONS:
        return None, math.nan
    tilted = key[:2] in ("xy", "yz", "xz")
    return P1_POSITIONS[key].copy(), PLACEMENT_SIGMA_TILTED_RAD if tilted else PLACEMENT_SIGMA_AXIS_RAD


@dataclass
class Position:
    """One static position: raw mean (3,), per-axis sample std (3,) or None, sample count."""

    label: str
    mean: np.ndarray
    std: np.ndarray | None = None
    n: int = 1
    t_start_s: float | None = None
    t_stop_s: float | None = None
    direction: np.ndarray | None = None  # known unit specific-force direction
    placement_sigma_rad: float = math.nan
    se: np.ndarray | None = None  # standard error of the mean (3,), correlated noise included; None: std/sqrt(n)


@dataclass
class P1Result:
    B: np.ndarray
    M: np.ndarray
    sigma_B: np.ndarray
    sigma_M: np.ndarray
    method: str  # 'norm' or 'six-position'
    gauge: str  # 'table', 'upper-triangular' or 'none' (step 8 only)
    gauge_text: str
    norm_residuals: np.ndarray  # |A_k| − g per position (m/s²)
    norm_sigma: np.ndarray  # the σ_k used (m/s²)
    residual_rms: float  # RMS of norm_residuals
    n_distinct: int
    clusters: np.ndarray  # orientation cluster index per position
    position_condition: float  # condition of the norm Jacobian of the position set (P1's 12: 1.6)
    fit: FitResult | None
    step8: dict | None  # {'B','M','sigma_B','sigma_M','residual_rms'} when computed
    noise_known: bool
    warnings: list[str] = field(default_factory=list)
    outliers: list[int] = field(default_factory=list)
    labels_used: bool = True  # False: the labels contradicted the data and fixed nothing (upper-triangular)


# ----------------------------------------------------------------------------- helpers


def _cross(a, b) -> np.ndarray:
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def perp_basis(u: np.ndarray) -> np.ndarray:
    """Two unit vectors (2, 3) perpendicular to ``u`` and to each other."""
    a = np.eye(3)[int(np.argmin(np.abs(u)))]
    e1 = _cross(u, a)
    e1 /= np.linalg.norm(e1)
    return np.vstack([e1, _cross(u, e1)])


def _pack(B, M) -> dict:
    return {"B": np.asarray(B, dtype=float), "M": np.asarray(M, dtype=float)}


def step8(positions: list[Position], g_mps2: float) -> dict:
    """Step 8: weighted linear least squares ``B + M V_k = g u_k`` over the labelled positions.

    Returns B, M, their σ, the fit and the vector residual RMS (m/s²). Raises TooFewPositions
    when the labelled positions cannot determine the 12 coefficients (fewer than 4 with
    independent readings)."""
    known = [p for p in positions if p.direction is not None]
    if len(known) < 4:
        raise TooFewPositions(
            f"{len(known)} positions with a known gravity direction; step 8 needs at least 4 (the six ±axis positions)"
        )
    V = np.array([p.mean for p in known])
    H1 = np.hstack([np.ones((len(known), 1)), V])
    if np.linalg.matrix_rank(H1, tol=1e-9 * np.abs(H1).max()) < 4:
        raise TooFewPositions("the labelled positions' readings do not span 3 axes: step 8 cannot solve")
    # unknowns x = (B0, M00, M01, M02, B1, M10, ..., ) per axis blocks
    H = np.zeros((3 * len(known), 12))
    y = np.zeros(3 * len(known))
    sig = np.zeros(3 * len(known))
    for k, p in enumerate(known):
        for i in range(3):
            H[3 * k + i, 4 * i : 4 * i + 4] = H1[k]
            y[3 * k + i] = g_mps2 * p.direction[i]
            sig[3 * k + i] = g_mps2 * p.placement_sigma_rad
    res = linear_fit(H, y, sigma=sig)
    x = res.params["x"]
    sx = res.sigma["x"]
    B = x[[0, 4, 8]]
    M = np.vstack([x[1:4], x[5:8], x[9:12]])
    sB = sx[[0, 4, 8]]
    sM = np.vstack([sx[1:4], sx[5:8], sx[9:12]])
    return {
        "B": B,
        "M": M,
        "sigma_B": sB,
        "sigma_M": sM,
        "fit": res,
        "residual_rms": float(np.sqrt(np.mean(res.residuals**2))),
    }


def ellipsoid_initial(V: np.ndarray, g_mps2: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Algebraic ellipsoid fit ``|B + M V|² = g²`` (10 linear coefficients; ≥ 10 positions),
    returned in the upper-triangular gauge, or None when it is not a real ellipsoid."""
    if len(V) < 10:
        return None
    x, y, z = V.T
    H = np.column_stack([x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z, 2 * x, 2 * y, 2 * z, np.ones(len(V))])
    scale = np.abs(H).max(axis=0)
    scale[scale == 0] = 1.0
    th, *_ = linalg.lstsq(H / scale, np.full(len(V), g_mps2**2), rcond=None)
    th = th / scale
    Q = np.array([[th[0], th[3], th[4]], [th[3], th[1], th[5]], [th[4], th[5], th[2]]])
    q = th[6:9]
    try:
        v0 = -np.linalg.solve(Q, q)
        r = g_mps2**2 - th[9] + q @ np.linalg.solve(Q, q)
        if r <= 0:
            return None
        L = np.linalg.cholesky(Q * g_mps2**2 / r)
    except np.linalg.LinAlgError:
        return None
    M = L.T
    return -M @ v0, M


def minmax_initial(V: np.ndarray, g_mps2: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis scale and offset from the extreme readings (each axis assumed to see ≈ ±g)."""
    hi, lo = V.max(axis=0), V.min(axis=0)
    half = np.where(hi - lo > 0, (hi - lo) / 2.0, 1.0)
    s = g_mps2 / half
    return -s * (hi + lo) / 2.0, np.diag(s)


def to_upper(B, M) -> tuple[np.ndarray, np.ndarray]:
    """The same norm model in the upper-triangular gauge: ``M = Q R`` → ``(Qᵀ B, R)``, diag(R) > 0."""
    Q, R = np.linalg.qr(np.asarray(M, dtype=float))
    s = np.sign(np.diag(R))
    s[s == 0] = 1.0
    Q, R = Q * s, (R.T * s).T
    return Q.T @ np.asarray(B, dtype=float), R


def label_angles_deg(V: np.ndarray, B, M, directions: np.ndarray) -> np.ndarray:
    """Per labelled position (rows of ``V`` with ``directions``): the angle (°) between its label's
    direction and its reading ``B + M V`` turned by the rotation that best matches all of them
    (Kabsch). ``B, M`` in any gauge: the norm fit leaves the rotation free, the labels fix it."""
    A = accel.p1_apply(V, B, M)
    a = A / np.maximum(np.linalg.norm(A, axis=1, keepdims=True), 1e-300)
    d = directions / np.maximum(np.linalg.norm(directions, axis=1, keepdims=True), 1e-300)
    U, _, Wt = np.linalg.svd(d.T @ a)
    R = U @ np.diag([1.0, 1.0, float(np.sign(np.linalg.det(U @ Wt))) or 1.0]) @ Wt  # a → d
    cos = np.clip(np.sum((a @ R.T) * d, axis=1), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def orientation_clusters(A: np.ndarray, max_angle_deg: float = DISTINCT_ANGLE_DEG) -> np.ndarray:
    """Cluster index per position: directions of ``A`` within ``max_angle_deg`` are one orientation."""
    norm = np.linalg.norm(A, axis=1, keepdims=True)
    d = A / np.where(norm > 0, norm, 1.0)  # zero vectors stay zero: together one orientation
    cos_t = math.cos(math.radians(max_angle_deg))
    labels = -np.ones(len(d), dtype=int)
    centres: list[np.ndarray] = []
    for k in range(len(d)):
        best, best_c = -1, cos_t
        for j, c in enumerate(centres):
            nc = np.linalg.norm(c)
            cc = float(d[k] @ c / nc) if nc > 0 else (1.0 if not d[k].any() else 0.0)
            if cc >= best_c:
                best, best_c = j, cc
        if best < 0:
            centres.append(d[k].copy())
            labels[k] = len(centres) - 1
        else:
            centres[best] = centres[best] + d[k]
            labels[k] = best
    return labels


def position_condition(V: np.ndarray, B, M) -> float:
    """Condition number of the column-scaled norm Jacobian in the upper-triangular gauge (9
    parameters): how well the set of positions determines the calibration (∞ = cannot).
    Computed on readings centred on their mean (``B + M V = (B + M V̄) + M (V − V̄)``), so that a
    large offset (unsigned counts) does not count as a badly placed set."""
    V = np.asarray(V, dtype=float)
    Vbar = V.mean(axis=0)
    B = np.asarray(B, dtype=float) + np.asarray(M, dtype=float) @ Vbar
    V = V - Vbar
    Bu, Mu = to_upper(B, M)
    _, J = accel.p1_norm_jacobian(V, Bu, Mu)
    keep = [0, 1, 2, 3, 4, 5, 7, 8, 11]  # B, M00 M01 M02, M11 M12, M22
    J = J[:, keep]
    J = J / np.linalg.norm(J, axis=0)
    s = linalg.svd(J, compute_uv=False)
    if len(V) < 9 or s[-1] <= 1e-12 * s[0]:
        return math.inf
    return float(s[0] / s[-1])


def norm_sigma(positions: list[Position], B, M, noise_known: bool) -> np.ndarray:
    """σ of ``|A_k|`` per position from the measured noise of each average (m/s²); ones when
    the noise is unknown (the fit then takes its scale from the residuals)."""
    if not noise_known:
        return np.ones(len(positions))
    return accel.p1_norm_sigma(np.array([p.mean for p in positions]), B, M, mean_variance(positions))


def mean_variance(positions: list[Position]) -> np.ndarray:
    """The variance (m, 3) of each position's mean: its standard error ``se`` squared (bias
    instability included, from the Allan deviation) when measured, else ``std² / n``."""
    return np.array([(p.se**2 if p.se is not None else p.std**2 / max(p.n, 1)) for p in positions])


# ----------------------------------------------------------------------------- the fit


def _joint_residual_builder(V: np.ndarray, g: float, sig_n: np.ndarray, known: list[tuple[int, np.ndarray, float]]):
    """Residual and Jacobian over blocks B, M: norm rows, then two rows per labelled position
    (the vector components perpendicular to its expected direction, target 0)."""
    m = len(known)
    E = np.array([perp_basis(u) for _, u, _ in known]).reshape(2 * m, 3)  # (2m, 3)
    Vk = np.repeat(np.array([V[k] for k, _, _ in known]).reshape(m, 3), 2, axis=0)  # (2m, 3)
    sig_v = np.repeat(np.array([s for _, _, s in known], dtype=float), 2)
    Jv = np.hstack([E, (E[:, :, None] * Vk[:, None, :]).reshape(2 * m, 9)])

    def resid(p):
        A = accel.p1_apply(V, p["B"], p["M"])
        nrm = np.sqrt(np.einsum("ij,ij->i", A, A)) - g
        if not m:
            return nrm
        Ak = accel.p1_apply(Vk, p["B"], p["M"])
        return np.concatenate([nrm, np.einsum("ij,ij->i", E, Ak)])

    def jac(p, free_idx):
        Jn = accel.p1_norm_jacobian(V, p["B"], p["M"])[1]
        return (np.vstack([Jn, Jv]) if m else Jn)[:, free_idx]

    sigma = np.concatenate([sig_n, sig_v]) if m else sig_n
    return resid, jac, sigma


def estimate_norm_noise(positions: list[Position], g_mps2: float, B0, M0) -> float | None:
    """σ of ``|A_k|`` (m/s²) from the residuals of a norm-only fit (upper-triangular gauge),
    for data without per-position noise; None when there are no degrees of freedom."""
    res = refine(positions, g_mps2, B0, M0, gauge="upper-triangular", sig_n=np.ones(len(positions)))
    if res.dof <= 0:
        return None
    return math.sqrt(max(float(res.residuals @ res.residuals) / res.dof, 1e-30))


def refine(positions: list[Position], g_mps2: float, B0, M0, *, gauge: str, sig_n: np.ndarray) -> FitResult:
    """Step 10: the norm condition over all positions (σ ``sig_n``), plus, in the table gauge,
    the perpendicular vector rows of the labelled positions (σ from placement), Gauss-Newton
    from ``(B0, M0)`` through ``solvers.fit``."""
    V = np.array([p.mean for p in positions])
    if gauge == "table":
        known = [
            (k, p.direction, math.hypot(g_mps2 * p.placement_sigma_rad, float(sig_n[k])))
            for k, p in enumerate(positions)
            if p.direction is not None
        ]
        free = {"B": True, "M": True}
        idx = list(range(12))
    else:
        known = []
        B0, M0 = to_upper(B0, M0)
        free = {"B": True, "M": np.triu(np.ones((3, 3), dtype=bool))}
        idx = [0, 1, 2, 3, 4, 5, 7, 8, 11]
    resid, jac, sigma = _joint_residual_builder(V, g_mps2, sig_n, known)
    return fit(resid, _pack(B0, M0), free=free, sigma=sigma, jac=lambda p: jac(p, idx))


def _studentized(positions, B, M, res: FitResult, gauge: str, s_n) -> np.ndarray:
    """Norm residuals over σ and sqrt(1 − leverage): a position the others pin down less is
    not blamed for the fit bending towards it."""
    V = np.array([p.mean for p in positions])
    idx = list(range(12)) if gauge == "table" else [0, 1, 2, 3, 4, 5, 7, 8, 11]
    Jw = accel.p1_norm_jacobian(V, B, M)[1][:, idx] / s_n[:, None]
    cov_u = res.cov / (res.reduced_chi2 if res.misfit_scaled else 1.0)
    h = np.clip(np.sum((Jw @ cov_u) * Jw, axis=1), 0.0, 1.0)
    z = res.residuals[: len(positions)] / s_n
    return z / np.sqrt(np.maximum(1.0 - h, 1e-3))


def find_outliers(positions, g_mps2, res: FitResult, gauge: str, s_n, threshold: float = 5.0):
    """Positions that disagree with the rest: repeatedly take the worst studentized residual
    beyond ``threshold`` × the others' robust spread, refit without it, and judge it against
    the others' fit. Returns ``[(index, z, residual_mps2)]``; needs ≥ 10 positions."""
    n = len(positions)
    active = list(range(n))
    out = []
    cur = res
    while len(active) >= 10 and len(out) < n // 4:
        pa = [positions[k] for k in active]
        zd = _studentized(pa, cur.params["B"], cur.params["M"], cur, gauge, s_n[active])
        j = int(np.argmax(np.abs(zd)))
        scale = max(1.0, 1.4826 * float(np.median(np.delete(np.abs(zd), j))))
        if abs(zd[j]) <= threshold * scale:
            break
        k = active.pop(j)
        pa = [positions[i] for i in active]
        try:
            cur = refine(pa, g_mps2, cur.params["B"], cur.params["M"], gauge=gauge, sig_n=s_n[active])
        except Exception:
            break
        rk = float(
            np.linalg.norm(accel.p1_apply(positions[k].mean[None], cur.params["B"], cur.params["M"]))[()] - g_mps2
        )
        out.append((k, rk / s_n[k], rk))
    return out


def rotation_covariance(positions, B, M, g_mps2, sig_n) -> np.ndarray:
    """Covariance (3x3, rad²) of the frame rotation the labelled positions fix: the vector rows'
    information ``Σ (A_k × e)(A_k × e)ᵀ / σ_v²`` (``e·(ω × A) = ω·(A × e)``)."""
    info = np.zeros((3, 3))
    for k, p in enumerate(positions):
        if p.direction is None:
            continue
        A = accel.p1_apply(p.mean[None], B, M)[0]
        var = (g_mps2 * p.placement_sigma_rad) ** 2 + float(sig_n[k]) ** 2
        for e in perp_basis(p.direction):
            j = _cross(A, e)
            info += np.outer(j, j) / var
    return np.linalg.inv(info)


def debias_rotation(B, M, cov_w) -> tuple[np.ndarray, np.ndarray]:
    """Remove the second-order bias an uncertain rotation puts on (B, M): with the frame
    rotation error ε ~ (0, Σ), ``E[R(ε)] = I + (Σ − tr Σ I)/2``, so every estimate is shrunk
    on average (e.g. the diagonal of M by ``M_ii (Σ_jj + Σ_kk)/2``); undo that on average."""
    corr = np.eye(3) - (cov_w - np.trace(cov_w) * np.eye(3)) / 2.0
    return corr @ B, corr @ M


def calibrate(
    positions: list[Position], g_mps2: float, *, method: str = "norm", gauge: str = "auto", noise_known: bool = True
) -> P1Result:
    """The P1 calibration of ``positions`` (see the module docstring).

    method: ``'norm'`` (step 8 when possible, then step 10) or ``'six-position'`` (step 8
    only). gauge: ``'auto'`` (``table`` when at least 3 labelled positions with independent
    directions, else ``upper-triangular``), ``'table'`` or ``'upper-triangular'``.
    Raises TooFewPositions / NotIdentifiable with a message an operator can act on.
    """
    if method not in ("norm", "six-position"):
        raise ValueError(f"unknown method {method!r}")
    V = np.array([p.mean for p in positions], dtype=float).reshape(-1, 3)
    warnings: list[str] = []
    known = [p for p in positions if p.direction is not None]
    s8 = None
    if len(known) >= 4:
        try:
            s8 = step8(positions, g_mps2)
        except TooFewPositions as exc:
            warnings.append(f"step 8 not possible: {exc}")
    if method == "six-position":
        if s8 is None:
            raise TooFewPositions(
                f"the six-position (step 8) solution needs the ±axis positions labelled; "
                f"this capture has {len(known)} positions with a known direction"
            )
        return _step8_result(positions, g_mps2, s8, warnings, noise_known)

    # provisional calibration, for clustering and the start
    if s8 is not None:
        B0, M0 = s8["B"], s8["M"]
    else:
        init = ellipsoid_initial(V, g_mps2)
        B0, M0 = init if init is not None else minmax_initial(V, g_mps2)
    clusters = orientation_clusters(accel.p1_apply(V, B0, M0))
    n_distinct = int(clusters.max() + 1) if len(clusters) else 0
    labels_suspect = False
    if n_distinct < MIN_DISTINCT and s8 is not None:
        # the labels' step 8 as the start can merge orientations the data hold apart (holds
        # numbered 1..N in the bench's own order): counted from a start without them, and the
        # labels then checked against the fit whatever the count
        init = ellipsoid_initial(V, g_mps2)
        Bu, Mu = init if init is not None else minmax_initial(V, g_mps2)
        free_clusters = orientation_clusters(accel.p1_apply(V, Bu, Mu))
        sv = np.linalg.svd(V - V.mean(axis=0), compute_uv=False) if len(V) >= 3 else np.zeros(1)
        spread = len(sv) == 3 and sv[0] > 0 and sv[2] > 0.1 * sv[0]  # the readings span three directions
        if spread and len(free_clusters) and int(free_clusters.max() + 1) >= MIN_DISTINCT:
            B0, M0, clusters = Bu, Mu, free_clusters
            n_distinct, labels_suspect = int(free_clusters.max() + 1), True
    if n_distinct < MIN_DISTINCT:
        hint = ""
        if s8 is not None and len({tuple(np.round(p.direction, 3)) for p in known}) >= 6:
            hint = "; the labelled ±axis positions allow the six-position linear solution (--method six-position)"
        raise TooFewPositions(
            f"{n_distinct} distinct orientation{'' if n_distinct == 1 else 's'} in {len(positions)} static "
            f"position{'' if len(positions) == 1 else 's'}; the "
            f"norm-condition fit needs at least {MIN_DISTINCT}{hint}",
            alternative="six-position" if hint else None,
        )
    dirs = np.array([p.direction for p in known]) if known else np.zeros((0, 3))
    rank_known = int(np.linalg.matrix_rank(dirs, tol=0.1)) if len(known) else 0
    auto = gauge == "auto"
    if auto:
        gauge = "table" if (len(known) >= 3 and rank_known >= 2) else "upper-triangular"
    if gauge == "table" and (len(known) < 2 or rank_known < 2):
        raise NotIdentifiable("the table gauge needs at least two labelled positions with different known directions")
    cond = position_condition(V, B0, M0)
    if not math.isfinite(cond):
        raise NotIdentifiable(
            f"the {len(positions)} positions cannot determine the calibration (the norm "
            "condition's Jacobian is singular): the orientations are too alike; add positions "
            "spread over all directions"
        )

    def run(gauge: str, B0, M0):
        notes = []
        if noise_known:
            sig_n = norm_sigma(positions, B0, M0, True)
        else:
            s_est = estimate_norm_noise(positions, g_mps2, B0, M0)
            if s_est is not None and s_est < NORM_NOISE_FLOOR_G * g_mps2:
                notes.append(
                    f"the residuals ({s_est:.3g} m/s^2) are below any real sensor's noise (noise-free data?): "
                    f"uncertainties assume a norm noise of {NORM_NOISE_FLOOR_G * g_mps2:.3g} m/s^2 "
                    f"({NORM_NOISE_FLOOR_G:g} g)"
                )
                s_est = NORM_NOISE_FLOOR_G * g_mps2
            if s_est is None:
                s_est = 1e-3 * g_mps2
                notes.append(
                    "no per-position noise and no redundancy (exactly 9 positions): uncertainties assume "
                    f"a norm noise of {s_est:.3g} m/s^2"
                )
            sig_n = np.full(len(positions), s_est)
        res = refine(positions, g_mps2, B0, M0, gauge=gauge, sig_n=sig_n)
        if noise_known:  # weights at the solution; refit only if they moved (a far start)
            sig_new = norm_sigma(positions, res.params["B"], res.params["M"], True)
            if np.max(np.abs(sig_new / sig_n - 1.0)) > 0.05:
                res = refine(positions, g_mps2, res.params["B"], res.params["M"], gauge=gauge, sig_n=sig_new)
            sig_n = sig_new
        n_after = int(orientation_clusters(accel.p1_apply(V, res.params["B"], res.params["M"])).max() + 1)
        return res, sig_n, notes, n_after

    res, sig_n, notes, n_after = run(gauge, B0, M0)
    labels_used = True
    # with fewer positions the check can take right labels for wrong (no redundancy), but a fit the
    # labels collapsed is no calibration: then the fit without them is tried whatever the count
    if (
        gauge == "table"
        and auto
        and (len(positions) >= LABEL_CHECK_MIN_POSITIONS or n_after < MIN_DISTINCT or labels_suspect)
    ):
        # labels that do not describe the data (holds numbered 1..N in the bench's own order)
        # pull the fit away or collapse it: then the fit without them, if it holds
        idx = [k for k, p in enumerate(positions) if p.direction is not None]
        angles = label_angles_deg(V[idx], res.params["B"], res.params["M"], dirs)
        agree = int(np.sum(angles <= LABEL_AGREEMENT_DEG))
        if n_after < MIN_DISTINCT or labels_suspect or agree < max(3, (len(idx) + 1) // 2):
            init = ellipsoid_initial(V, g_mps2)
            Bu, Mu = init if init is not None else minmax_initial(V, g_mps2)
            try:
                alt = run("upper-triangular", Bu, Mu)
            except (ArithmeticError, ValueError, np.linalg.LinAlgError, NotIdentifiable):
                alt = None
            if alt is not None and alt[3] >= MIN_DISTINCT and not alt[0].unidentifiable:
                res, sig_n, notes, n_after = alt
                gauge, labels_used, s8, known = "upper-triangular", False, None, []
                warnings.append(
                    f"the position labels do not describe these positions: {len(idx) - agree} of {len(idx)} "
                    f"labelled positions read more than {LABEL_AGREEMENT_DEG:g}° from their label's direction "
                    "(holds numbered in another order than P1's positions?); the labels are not used for the "
                    "orientation (upper-triangular gauge)"
                )
    warnings += notes
    if res.unidentifiable:
        raise NotIdentifiable(
            f"the positions cannot determine {', '.join(res.unidentifiable)} "
            f"(condition number {res.condition_number:.3g})"
        )
    B, M = res.params["B"], res.params["M"]
    if n_after < MIN_DISTINCT:  # M ≈ 0, |B| ≈ g satisfies every norm row: a collapse, not a calibration
        raise NotIdentifiable(
            f"the fit collapsed: the {n_distinct} distinct orientations of the data come out as {n_after} "
            f"after it (M's singular values {', '.join(f'{x:.3g}' for x in np.linalg.svd(M, compute_uv=False))}); "
            "check the position labels and accel_unit, or leave the labels out"
        )
    rotation_cov = None
    if gauge == "table":
        rotation_cov = rotation_covariance(positions, B, M, g_mps2, sig_n)
        B, M = debias_rotation(B, M, rotation_cov)
    cond = position_condition(V, B, M)
    if cond > CONDITION_WARN:
        warnings.append(
            f"the positions are too alike (condition number {cond:.0f} > {CONDITION_WARN:.0f}): "
            "some coefficients are poorly determined; add positions with gravity along other directions"
        )
    n = len(positions)
    if n <= MIN_DISTINCT:  # as many norm rows as the norm's parameters: they are met exactly
        warnings.append(
            f"{n} positions for the norm condition's {MIN_DISTINCT} parameters: no degree of freedom is "
            "left, so |A| − g is 0 by construction and the residual checks nothing (neither the model "
            "nor a position that moved); add positions (P1 asks 12)"
        )
    r_n = res.residuals[:n]
    s_n = sig_n
    z = r_n / s_n  # noqa: F841
    outliers = find_outliers(positions, g_mps2, res, gauge, s_n)
    for k, zk, rk in outliers:
        p = positions[k]
        when = f" (t {p.t_start_s:.1f}–{p.t_stop_s:.1f} s)" if p.t_start_s is not None else ""
        warnings.append(
            f"position {p.label or k + 1}{when} disagrees with the rest: |A| − g = {rk:+.3g} m/s^2 "
            f"against the fit of the others, {abs(zk):.0f}σ; was it still, or touching something? "
            "(it is kept in the fit)"
        )
    outliers = [k for k, _, _ in outliers]
    if noise_known and res.misfit_scaled:
        warnings.append(
            f"the residuals are {math.sqrt(res.reduced_chi2):.1f}× the measured noise (reduced χ² "
            f"{res.reduced_chi2:.3g}): A = B + M V does not explain everything (temperature, "
            "non-linearity, moving positions?); uncertainties are scaled up by that factor"
        )
    if not noise_known and not any("uncertainties assume a norm noise" in w for w in warnings):
        warnings.append(
            f"no per-position noise given: the norm noise is estimated from the residuals "
            f"({s_n[0]:.3g} m/s^2), so uncertainties include any model misfit"
        )
    if gauge == "table":
        sig_deg = sorted({round(math.degrees(p.placement_sigma_rad), 2) for p in known})
        gauge_text = (
            "table: the rotation the norm cannot see is fixed by the labelled positions' known gravity "
            f"directions (vector condition, placement σ {'/'.join(str(s) for s in sig_deg)}° per "
            "component), everything else by the norm condition"
        )
    else:
        gauge_text = (
            "upper-triangular: M[1][0] = M[2][0] = M[2][1] = 0 (imu_tk's convention: frame z = the "
            "sensor's z axis, frame y in its y-z plane); no labelled positions fix the orientation"
        )
    return P1Result(
        B=B,
        M=M,
        sigma_B=res.sigma["B"],
        sigma_M=res.sigma["M"],
        method="norm",
        gauge=gauge,
        gauge_text=gauge_text,
        norm_residuals=r_n,
        norm_sigma=s_n,
        residual_rms=float(np.sqrt(np.mean(r_n**2))),
        n_distinct=n_distinct,
        clusters=clusters,
        position_condition=cond,
        fit=res,
        step8=_s8_summary(s8),
        noise_known=noise_known,
        warnings=warnings,
        outliers=outliers,
        labels_used=labels_used,
    )


def _s8_summary(s8):
    if s8 is None:
        return None
    return {k: s8[k] for k in ("B", "M", "sigma_B", "sigma_M", "residual_rms")}


def _step8_result(positions, g_mps2, s8, warnings, noise_known) -> P1Result:
    V = np.array([p.mean for p in positions])
    B, M = s8["B"], s8["M"]
    r = np.linalg.norm(accel.p1_apply(V, B, M), axis=1) - g_mps2
    clusters = orientation_clusters(accel.p1_apply(V, B, M))
    warnings = warnings + [
        "six-position (step 8) linear solution only: its accuracy is limited by how well the "
        "device was placed (σ ≈ 0.4° → ~0.07 m/s^2), not by the sensor noise; the norm-condition "
        f"refinement needs at least {MIN_DISTINCT} distinct orientations"
    ]
    return P1Result(
        B=B,
        M=M,
        sigma_B=s8["sigma_B"],
        sigma_M=s8["sigma_M"],
        method="six-position",
        gauge="none",
        gauge_text="step 8: the labelled positions' known gravity directions define the frame",
        norm_residuals=r,
        norm_sigma=norm_sigma(positions, B, M, noise_known),
        residual_rms=float(np.sqrt(np.mean(r**2))),
        n_distinct=int(clusters.max() + 1),
        clusters=clusters,
        position_condition=position_condition(V, B, M),
        fit=s8["fit"],
        step8=_s8_summary(s8),
        noise_known=noise_known,
        warnings=warnings,
    )
