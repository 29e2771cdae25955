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


# Neighbours on each side whose reference samples predict an epoch's (instrumental variables):
# the prediction shrinks what their noise blurs by noise over spread, and that shrinkage stays in
# the residual; averaging more neighbours makes it smaller, as far as the motion is a straight
# line over them: at most IV_NEIGHBOURS, and no farther than IV_SPAN_S on each side (at 5 Hz four
# neighbours on each side spanned 0.8 s, whose turns the prediction missed: `residual:rate` on
# two nulls of QA s27d, s700812 and s700827)
IV_NEIGHBOURS = 4
IV_SPAN_S = 0.1


def iv_neighbours(dt_s: float) -> int:
    """The neighbours on each side for epochs ``dt_s`` apart (at least one)."""
    return int(np.clip(round(IV_SPAN_S / dt_s), 1, IV_NEIGHBOURS)) if dt_s > 0 else 1


def instrument_coefficients(v_body_mps, constant: bool = False, K: int = IV_NEIGHBOURS):
    """The first stage of :func:`instrumented_by_neighbours`: ``(idx, G, B0)``, the reference
    at epoch t predicted as ``Σ_k G[k, t] v[idx[k, t]] + B0`` over the ``K`` neighbours on each
    side (``G[k, t] = B_kᵀ``, ``B0`` zero unless ``constant``), fitted on the epochs that have
    them all; the first and last ``K`` epochs keep their own sample (``G[0, t] = I`` at
    ``idx[0, t] = t``: a one-sided prediction misses the motion's slope). None under ``4K + 4``
    epochs."""
    v = np.asarray(v_body_mps, float)
    m = len(v)
    if m < 4 * K + 4:
        return None
    t = np.arange(m)
    offs = [*range(-K, 0), *range(1, K + 1)]
    idx = np.array([np.clip(t + o, 0, m - 1) for o in offs])
    inner = (t >= K) & (t < m - K)
    Z = np.column_stack([v[i[inner]] for i in idx] + ([np.ones(int(inner.sum()))] if constant else []))
    B, *_ = np.linalg.lstsq(Z, v[inner], rcond=None)
    G = np.zeros((2 * K, m, 3, 3))
    G[:, inner] = np.transpose(B[: 6 * K].reshape(2 * K, 3, 3), (0, 2, 1))[:, None]
    idx[0, ~inner] = t[~inner]
    G[0, ~inner] = np.eye(3)
    return idx, G, (B[6 * K] if constant else np.zeros(3)) * inner[:, None]


def instrumented_by_neighbours(v_body_mps, constant: bool = False, K: int = IV_NEIGHBOURS) -> np.ndarray:
    """The reference velocity predicted from its neighbours: the least-squares projection of
    ``v_t`` on ``v_t−K … v_t−1, v_t+1 … v_t+K`` (instrumental variables, two-stage least
    squares: Fuller 1987 §1.4, Wooldridge 2010 §5.2). A white reference noise at epoch t is
    independent of the neighbours' noise, while a motion smooth on the scale of a few samples is
    carried by them: a fit of the beams on the projection is free of the errors-in-variables
    attenuation, which plain least squares on the noisy ``v`` turned into an offset-like misfit.
    No noise figure is needed.

    The projection shrinks what the neighbours' noise blurs, by noise over spread, toward what
    else it holds, and the shrinkage stays in the fit's residual (it is what cancels the
    attenuation). Toward a constant in the first stage (``constant``), an aircraft's body
    ``v_z`` (angle of attack: 0.15 m/s about 9 m/s) came out 1 % short about its mean with one
    neighbour on each side: 1e-3 m/s of misfit in step with the flight's slow phases, and a null
    drive named ``residual:time`` (QA s27d s700040). Without it the shrinkage is toward zero, and
    with ``K`` neighbours on each side (:func:`iv_neighbours`) the noise it follows is ``1/K``:
    with one, a model with an offset put 0.01-0.02 m/s into it on records of noise alone (an
    aircraft at 50 Hz, s700823: its deviance 16 on average over fresh attitude noise, 3.3 with
    four)."""
    v = np.asarray(v_body_mps, float)
    coef = instrument_coefficients(v, constant, K)
    if coef is None:
        return v
    idx, G, B0 = coef
    return sum(np.einsum("nij,nj->ni", g, v[i]) for i, g in zip(idx, G)) + B0


def whitened_rows(X, own_var, ref_cov_mps2, coef=None):
    """The beam rows' noise (rows epoch-major, ``3t + j``) and how to whiten it: the beams'
    own white noise ``own_var`` (k,) and the reference's noise ``ref_cov_mps2`` (m, 3, 3)
    through ``X`` (k, 3), which every beam of an epoch shares: rows of one epoch are
    correlated. Fitted on the neighbours' prediction (``coef``: :func:`instrument_coefficients`)
    a row holds ``X Σ_k G[k, t] δ_idx[k,t]`` instead of ``X δ_t``, which rows up to 2K epochs
    apart share. Returns ``(sigma, whiten)``: each row's σ (the diagonal) and ``whiten(r)`` of a
    flat residual, ``D L⁻¹ D⁻¹ r`` with ``L Lᵀ`` the rows' correlation (banded Cholesky): rows
    independent, each with the σ given (a row still mostly its own beam at its own epoch).
    ``own_var`` None: the reference's part of σ alone, and no ``whiten``."""
    from scipy.linalg import cholesky_banded
    from scipy.linalg.lapack import dtbtrs

    X = np.asarray(X, float)
    cov = np.asarray(ref_cov_mps2, float)
    m, k = len(cov), len(X)
    if coef is None:
        idx, G = np.arange(m)[None], np.broadcast_to(np.eye(3), (1, m, 3, 3))
        lags = 1
    else:
        idx, G, _ = coef
        lags = len(idx) + 1  # epochs up to 2K apart share a neighbour
    XG = np.einsum("ai,kmij->kmaj", X, G)  # (terms, m, k, 3)
    blocks = np.zeros((lags, m, k, k))  # blocks[d, t]: covariance of epoch t+d's rows with epoch t's
    for d in range(lags):
        t = np.arange(m - d)
        for a_t, XG_t in zip(idx, XG):
            for a_s, XG_s in zip(idx, XG):
                hit = t[a_t[t] == a_s[t + d]]
                if hit.size:
                    blocks[d, hit] += np.einsum("nai,nij,nbj->nab", XG_s[hit + d], cov[a_t[hit]], XG_t[hit])
    if own_var is None:
        return np.sqrt(np.einsum("njj->nj", blocks[0]).ravel()), None
    blocks[0] += np.diag(np.asarray(own_var, float))[None]
    n = m * k
    sig = np.sqrt(np.einsum("njj->nj", blocks[0]).ravel())
    bw = lags * k - 1
    ab = np.zeros((bw + 1, n))  # lower band: ab[i − c, c] = C[i, c]
    for d in range(lags):
        for a in range(k):  # row epoch t+d beam a
            for b in range(k):  # column epoch t beam b
                off = d * k + a - b
                if 0 <= off <= bw:
                    cols = np.arange(m - d) * k + b
                    ab[off, cols] = blocks[d, : m - d, a, b] / (sig[cols + off] * sig[cols])
    L = cholesky_banded(ab, lower=True)

    def whiten(r):
        x, info = dtbtrs(L, (np.asarray(r, float) / sig)[:, None], uplo="L")
        return sig * x[:, 0]

    return sig, whiten


# the least share of each beam's noise variance taken as its own (not shared with the other beams
# of the epoch) when the shared part is measured from the residual: as ``whitened_rows``' callers
# keep at least a quarter of a beam's variance as its own noise
OWN_NOISE_MIN_SHARE = 0.25


def shared_noise_correlation(r) -> np.ndarray:
    """The correlation (k, k) of the beams' noise within an epoch, read from the residual ``r``
    (m, k; time-ordered epochs) of a fit: from its first differences, whose covariance is twice
    the noise's where the noise is white in time, and which a slow misfit (an offset, a drift, a
    temperature bias) hardly moves. The reference's noise ``X δv`` is common to every beam of an
    epoch: three beams that all look down (``X_j3`` ≈ 0.9) share its vertical part, and a
    reference as noisy as the beams makes their residuals correlated by 0.5 or more; counted as
    independent, a line in time that the reference's noise holds in all beams at once was taken
    at twice its χ² (QA s31 null s744031: ``time_drift``). Its eigenvalues are held to at least
    ``OWN_NOISE_MIN_SHARE`` (shrunk toward the identity): each beam keeps some noise of its own."""
    d = np.diff(np.asarray(r, float), axis=0)
    k = d.shape[1] if d.ndim == 2 else 1
    if d.ndim != 2 or len(d) < 4 * k:
        return np.eye(k)
    C = d.T @ d
    s = np.sqrt(np.diag(C))
    if not np.all(s > 0):
        return np.eye(k)
    R = C / np.outer(s, s)
    lo = float(np.linalg.eigvalsh(R)[0])
    if lo < OWN_NOISE_MIN_SHARE:
        lam = (OWN_NOISE_MIN_SHARE - lo) / (1.0 - lo)
        R = (1.0 - lam) * R + lam * np.eye(k)
    return R


def epoch_whitener(sigma, corr):
    """``whiten(r)`` of a flat residual (rows epoch-major, ``k t + j``) whose rows of one epoch
    have the σ ``sigma`` (k,) and the correlation ``corr`` (k, k), epochs independent:
    ``D L⁻¹ D⁻¹`` per epoch (``L Lᵀ = corr``, ``D = diag σ``), rows independent with the σ given,
    as :func:`whitened_rows` does for a modelled reference noise."""
    sig = np.asarray(sigma, float)
    M = (np.linalg.inv(np.linalg.cholesky(np.asarray(corr, float))) * (1.0 / sig)[None, :]) * sig[:, None]
    k = len(sig)

    def whiten(r):
        return (np.asarray(r, float).reshape(-1, k) @ M.T).ravel()

    return whiten


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
