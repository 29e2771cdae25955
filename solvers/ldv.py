"""P5 (source 004, CN102706365A): three-beam laser Doppler velocimeter calibration.

Per beam j, with the body-frame reference velocity ``v`` (rows, m/s)::

    V_Lj = (1 + δK_j)(v_x cos α_j + v_y cos β_j + v_z cos γ_j) = v · X_j

(:mod:`solvers.models.ldv` is the model; :func:`solvers.models.ldv.angles_from_X` the
source's read-out ``1 + δK = |X|``, ``cos α = X_1/|X|``, ...). ``X_j`` by linear least
squares over the epochs (:func:`solvers.fit.linear_fit`); the evaluation σ is the standard
deviation of ``V̂_L − V_L`` (the source's step 7); the covariance of ``X_j`` is
``σ̂_j² (HᵀH)⁻¹`` with ``σ̂_j`` from the residuals, so it holds the reference velocity's
noise too (it enters the residual as ``|X_j|² σ_ref²``). Ordinary least squares with a
noisy reference is biased (errors-in-variables attenuation, ``≈ −σ_ref² n (HᵀH)⁻¹ X``):
at the simulator's levels (σ_ref 5 mm/s, vertical spread ~1 m/s) that is ~0.1σ on the
vertical cosine, under 1 % of the RMS error. When the reference noise ``σ_ref`` is known
the moment-corrected estimator ``X̂ = (HᵀH − n σ_ref² I)⁻¹ Hᵀ V_L`` (Fuller 1987, §1.2)
removes it (``ref_sigma_mps``); the bias OLS would have had is reported (``eiv_bias_X``).

Conditioning: ``κ = cond(HᵀH)`` of the body velocity set (m/s, all columns the same unit,
so κ is physical). A vehicle that only drives straight has ``κ`` in the millions: the
angles cannot be separated; :func:`calibrate_ldv` raises :class:`NotIdentifiable` above
``KAPPA_REFUSE`` unless ``force`` (then it warns loudly), and warns above ``KAPPA_WARN``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from solvers import linalg
from solvers.errors import NotIdentifiable, TooFewPositions
from solvers.fit import linear_fit
from solvers.models import ldv as ldv_model

KAPPA_WARN = 1.0e3
KAPPA_REFUSE = 1.0e4
ANGLE_NAMES = ("alpha_deg", "beta_deg", "gamma_deg")


@dataclass
class BeamResult:
    X: np.ndarray  # (3,)
    cov_X: np.ndarray  # (3, 3)
    dK: float
    angles_deg: np.ndarray  # α, β, γ
    sigma_dK: float
    sigma_angles_deg: np.ndarray
    sigma_mps: float  # evaluation σ of V̂_L − V_L
    residuals: np.ndarray
    eiv_bias_X: np.ndarray  # expected OLS bias from the reference noise (given σ_ref)


@dataclass
class LdvResult:
    beams: list[BeamResult]
    condition_number: float
    n: int
    warnings: list[str] = field(default_factory=list)


def angle_jacobian(X) -> np.ndarray:
    """d(δK, α°, β°, γ°)/dX for one beam (4, 3)."""
    X = np.asarray(X, dtype=float)
    nrm = float(np.linalg.norm(X))
    u = X / nrm
    J = np.empty((4, 3))
    J[0] = u
    du = (np.eye(3) - np.outer(u, u)) / nrm  # d u / d X
    for i in range(3):
        s = math.sqrt(max(1.0 - u[i] ** 2, 1e-300))
        J[1 + i] = -np.degrees(du[i] / s)
    return J


EXCESS_WARN = 1.3


def residual_excess(r) -> float:
    """std(r) over its white part std(Δ²r)/sqrt(6): 1 for white residuals, larger when the
    residual holds a slowly varying misfit the model does not explain."""
    r = np.asarray(r, dtype=float)
    if len(r) < 8:
        return 1.0
    white = float(np.std(np.diff(r, 2))) / math.sqrt(6.0)
    return float(np.std(r)) / white if white > 0 else math.inf


def hac_covariance(H, r, HtH_inv, max_lag: int | None = None) -> np.ndarray:
    """Newey-West (Bartlett) covariance of a least-squares estimate with serially correlated
    residuals: ``(HᵀH)⁻¹ S (HᵀH)⁻¹``, ``S = Σ_l w_l Σ_t (h_t r_t)(h_{t−l} r_{t−l})ᵀ + transpose``.
    The bandwidth is 3x the lag where the residual autocorrelation first drops below 0.05
    (at least 4, at most n/10)."""
    H = np.asarray(H, dtype=float)
    r = np.asarray(r, dtype=float)
    n = len(r)
    if max_lag is None:
        rc = r - r.mean()
        f = np.fft.rfft(rc, 2 * n)
        acf = np.fft.irfft(f * np.conj(f))[: n // 10 + 1]
        acf = acf / acf[0] if acf[0] > 0 else acf
        below = np.flatnonzero(acf < 0.05)
        max_lag = int(np.clip(3 * (below[0] if len(below) else n // 10), 4, max(4, n // 10)))
    g = H * r[:, None]
    S = g.T @ g
    for lag in range(1, max_lag + 1):
        w = 1.0 - lag / (max_lag + 1.0)
        G = g[lag:].T @ g[:-lag]
        S += w * (G + G.T)
    return HtH_inv @ S @ HtH_inv


def velocity_condition(v_body_mps) -> float:
    """cond(HᵀH) of the body velocity set."""
    H = np.asarray(v_body_mps, dtype=float)
    s = linalg.svd(H, compute_uv=False)
    return float((s[0] / s[-1]) ** 2) if s[-1] > 0 else math.inf


# The attitude noise is read from the attitude's high-frequency part only where that part is noise:
# white noise gives the same σ from second and third differences; motion resolved by the rate makes
# the third-difference figure smaller (slow motion) and motion near the Nyquist rate a little larger
# (up to 1.1x): outside this band the figure is motion, not noise, and is not used.
ATT_NOISE_RATIO = (0.85, 1.15)


def attitude_noise_rad(C_n_b) -> float | None:
    """White attitude noise σ [rad per axis] of an attitude series ``C_n_b`` (n, 3, 3), time
    ordered at a steady rate: the body-frame turns ``C_kᵀ C_k+1`` of consecutive samples, whose
    differences hold a white per-sample rotation noise ``δθ`` (``C = C_true R(δθ)``) with variance
    6σ² (second differences of the attitude) and their second differences with 20σ² (third),
    read with the MAD so that manoeuvres do not count. None when the two disagree
    (``ATT_NOISE_RATIO``: the high-frequency part is motion) or there are too few samples."""
    C = np.asarray(C_n_b, float)
    C = C[np.all(np.isfinite(C), axis=(1, 2))]
    if len(C) < 20:
        return None
    from solvers import frames

    step = np.einsum("nji,njk->nik", C[:-1], C[1:])
    s = np.stack([frames.matrix_to_rotvec(m) for m in step])

    def mad_sigma(d, var_factor):
        return float(np.sqrt(np.mean((1.4826 * np.median(np.abs(d - np.median(d, axis=0)), axis=0)) ** 2) / var_factor))

    s2 = mad_sigma(np.diff(s, 1, axis=0), 6.0)
    s3 = mad_sigma(np.diff(s, 2, axis=0), 20.0)
    if not (s2 > 0 and ATT_NOISE_RATIO[0] <= s3 / s2 <= ATT_NOISE_RATIO[1]):
        return None
    return min(s2, s3)


def reference_noise_cov(v_body_mps, sigma_v_mps: float | None, sigma_att_rad: float | None) -> np.ndarray | None:
    """Per-epoch covariance (n, 3, 3) [m²/s²] of the body-frame reference velocity's noise: the
    velocity noise ``σ_v² I`` (per axis) and a white attitude noise ``δθ`` (σ per axis) turning
    ``v_b = C_n_bᵀ v_n`` by ``v_b × δθ``: ``σ_att² (|v|² I − v vᵀ)``. None when both are 0/None."""
    v = np.asarray(v_body_mps, float)
    if not sigma_v_mps and not sigma_att_rad:
        return None
    cov = np.zeros((len(v), 3, 3))
    if sigma_v_mps:
        cov += sigma_v_mps**2 * np.eye(3)
    if sigma_att_rad:
        cov += sigma_att_rad**2 * (
            np.einsum("ni,ni->n", v, v)[:, None, None] * np.eye(3) - np.einsum("ni,nj->nij", v, v)
        )
    return cov


# a reference noise that puts less than this share of a beam's residual variance in it is not
# modelled (a simulator's attitude rounded to 1e-6°: its rounding is white, and nothing to correct)
REF_NOISE_NEGLIGIBLE = 1e-3


def reference_noise_share(v_body_mps, vl_mps, ref_cov_mps2) -> np.ndarray:
    """Per beam, the share of its least-squares residual variance that the reference noise
    ``ref_cov_mps2`` puts in it: ``mean Xᵀ cov X / mean r²``. Above 1: more than the whole
    residual, a noise figure read from the reference's high-frequency part that is really
    motion (a car's attitude at 1 Hz)."""
    H = np.asarray(v_body_mps, float)
    Y = np.asarray(vl_mps, float)
    X, *_ = np.linalg.lstsq(H, Y, rcond=None)  # (3, beams)
    r = Y - H @ X
    ref_var = np.einsum("ij,nik,kj->j", X, np.asarray(ref_cov_mps2, float), X) / len(H)
    return ref_var / np.maximum(np.mean(r**2, axis=0), 1e-300)


def instrumented_by_neighbours(v_body_mps) -> np.ndarray:
    """The reference velocity predicted from its neighbours: the least-squares projection of
    ``v_t`` on ``[1, v_t−1, v_t+1]`` (instrumental variables, two-stage least squares:
    Fuller 1987 §1.4, Wooldridge 2010 §5.2). A white reference noise at epoch t is independent
    of the neighbours' noise, while a motion smooth on the scale of one sample is carried by
    them: a fit of the beams on the projection (beside any error-free column: an offset, a
    drift, ω × r, a function of time or |ω|) is free of the errors-in-variables attenuation,
    which plain least squares on the noisy ``v`` turned into an offset-like misfit. No noise
    figure is needed; the first and last epochs repeat their one neighbour."""
    v = np.asarray(v_body_mps, float)
    if len(v) < 8:
        return v
    prev = np.vstack([v[1:2], v[:-1]])
    nxt = np.vstack([v[1:], v[-2:-1]])
    Z = np.column_stack([np.ones(len(v)), prev, nxt])
    B, *_ = np.linalg.lstsq(Z, v, rcond=None)
    return Z @ B


def calibrate_ldv(
    v_body_mps, vl_mps, *, ref_sigma_mps: float | None = None, ref_cov_mps2=None, force: bool = False
) -> LdvResult:
    """Per-beam least squares (module docstring). ``v_body_mps`` (N, 3), ``vl_mps`` (N, k).

    ``ref_sigma_mps``: the reference velocity's noise (m/s, per axis); ``ref_cov_mps2``: the
    reference's per-epoch noise covariance (N, 3, 3) (:func:`reference_noise_cov`: velocity
    and attitude noise). When either is given, the moment-corrected (errors-in-variables)
    estimator ``(HᵀH − Σ cov)⁻¹ Hᵀ V_L`` is used instead of plain OLS, its covariance the
    sandwich ``σ̂² A⁻¹ HᵀH A⁻¹`` (``A = HᵀH − Σ cov``).
    Raises TooFewPositions (n < 3 epochs, or fewer than 4 for a σ) and NotIdentifiable
    (ill-conditioned velocity set, unless ``force``).
    """
    H = np.asarray(v_body_mps, dtype=float)
    Y = np.asarray(vl_mps, dtype=float)
    if Y.ndim == 1:
        Y = Y[:, None]
    n = len(H)
    if n < 4:
        raise TooFewPositions(
            f"ldv: {n} epoch{'' if n == 1 else 's'}: 3 determine each beam's X (P5's n >= 3) but leave "
            "nothing to estimate its uncertainty; record at least 4 epochs in different motion states"
        )
    kappa = velocity_condition(H)
    warnings: list[str] = []
    if kappa > KAPPA_REFUSE:
        msg = (
            f"velocity set ill-conditioned: cond(HᵀH) = {kappa:.3g} > {KAPPA_REFUSE:.0e}; the body "
            "velocity hardly changes direction (driving straight?), so the beam angles cannot be "
            "separated: drive turns, slopes, braking"
        )
        if not force:
            raise NotIdentifiable(msg)
        warnings.append("FORCED: " + msg + "; the numbers below are NOT trustworthy")
    elif kappa > KAPPA_WARN:
        warnings.append(f"velocity set poorly conditioned: cond(HᵀH) = {kappa:.3g}; angles weakly determined")
    HtH_inv = np.linalg.pinv(H.T @ H)
    S = np.zeros((3, 3))  # Σ over epochs of the reference noise covariance
    if ref_sigma_mps:
        S += n * ref_sigma_mps**2 * np.eye(3)
    if ref_cov_mps2 is not None:
        S += np.sum(np.asarray(ref_cov_mps2, float), axis=0)
    eiv = bool(np.any(S))
    A_inv = np.linalg.pinv(H.T @ H - S) if eiv else HtH_inv
    beams = []
    for j in range(Y.shape[1]):
        fr = linear_fit(H, Y[:, j], sigma=None, names=["X1", "X2", "X3"])
        X = np.asarray(fr.params["x"], dtype=float)
        bias = -HtH_inv @ S @ X if eiv else np.zeros(3)
        if eiv:
            X = A_inv @ (H.T @ Y[:, j])
        r = Y[:, j] - H @ X  # V_L − V̂_L
        s2 = float(r @ r) / max(n - 3, 1)
        cov = s2 * (A_inv @ (H.T @ H) @ A_inv if eiv else HtH_inv)
        excess = residual_excess(r)
        if excess > EXCESS_WARN:
            cov_hac = hac_covariance(H, r, A_inv)
            if np.trace(cov_hac) > np.trace(cov):
                cov = cov_hac
            warnings.append(
                f"beam{j + 1}: residuals are {excess:.2f}x their sample-to-sample noise (correlated in "
                "time): the model does not explain everything (time delay, lever arm, offset or "
                "drift?); uncertainties from a correlation-robust (Newey-West) covariance"
            )
        a = ldv_model.angles_from_X(X[None, :])
        J = angle_jacobian(X)
        cov_a = J @ cov @ J.T
        sa = np.sqrt(np.clip(np.diag(cov_a), 0.0, None))
        beams.append(
            BeamResult(
                X=X,
                cov_X=cov,
                dK=float(a["dK"][0]),
                angles_deg=np.array([a[k][0] for k in ANGLE_NAMES]),
                sigma_dK=float(sa[0]),
                sigma_angles_deg=sa[1:],
                sigma_mps=float(np.std(r, ddof=3)),
                residuals=r,
                eiv_bias_X=bias,
            )
        )
    return LdvResult(beams, kappa, n, warnings)


def crlb_X(v_true_mps, X, beam_sigma_mps: float, ref_sigma_mps: float) -> np.ndarray:
    """Cramér-Rao bound on one beam's X with white beam noise σ_b and white reference
    velocity noise σ_ref (the true velocities H are nuisance parameters, one per epoch):
    ``(σ_b² + |X|² σ_ref²) (Hᵀ H)⁻¹``.

    Derivation: per epoch the information on (X, v_i) from the reference (I/σ_ref²) and
    the three beams; eliminating v_i (Schur complement) leaves, for all nine X elements,
    ``kron(σ_b² I + σ_ref² X Xᵀ, (HᵀH)⁻¹)`` by Woodbury, whose beam-j block is the formula.
    The per-beam OLS uses the *noisy* H: its extra variance and bias are O(σ_ref²/spread²)."""
    H = np.asarray(v_true_mps, dtype=float)
    s2 = beam_sigma_mps**2 + float(np.dot(X, X)) * ref_sigma_mps**2
    return s2 * np.linalg.inv(H.T @ H)
