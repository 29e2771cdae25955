"""Gyro triad forward error model (P4 and its diagnose effects).

Forward, true body rate ``ω`` [rad/s] (rows) to output ``y`` [rad/s after the unit
factor; the model works in rad/s]::

    y = K ω + ε + b_T (T − T_ref) + b_t (t − t_ref) + G f

- baseline: ``eps`` [3] the drift (bias) ε of source 003; ``K`` [3x3] optional scale and
  misalignment (identity when absent, as P4 assumes).
- effects (diagnose.md): ``temperature_bias`` → ``bT`` [3] (rad/s/°C); ``time_drift`` →
  ``bt`` [3] (rad/s²); ``g_sensitivity`` → ``G`` [3x3] (rad/s per m/s², needs
  ``cond.f_mps2``).
- ``earth_rate`` is not a block: it is part of the true input. On a static base
  ``ω = C_b_n ω_ie^n`` (:func:`earth_rate_body`); the mode-B baseline includes it, and
  diagnosis names it when a plain constant-bias model was fitted to multi-position data.
"""

from __future__ import annotations

import math

import numpy as np

from solvers.frames import earth_rate_nue
from solvers.models import Conditions, additive_terms, random_signs

BASELINE = ("eps",)
EFFECTS = {
    "temperature_bias": ("bT",),
    "time_drift": ("bt",),
    "g_sensitivity": ("G",),
    "earth_rate": (),
}
SHAPES = {"eps": (3,), "K": (3, 3), "bT": (3,), "bt": (3,), "G": (3, 3)}


def forward(omega_rad_s, params: dict, cond: Conditions | None = None) -> np.ndarray:
    """True body rate (N, 3) rad/s → gyro output (N, 3) rad/s."""
    w = np.atleast_2d(np.asarray(omega_rad_s, dtype=float))
    y = w @ np.asarray(params["K"]).T if "K" in params else w.copy()
    y = y + np.asarray(params["eps"]) + additive_terms(params, cond, len(w))
    if "G" in params:
        if cond is None or cond.f_mps2 is None:
            raise ValueError("g_sensitivity needs the specific force (cond.f_mps2)")
        y = y + np.asarray(cond.f_mps2, dtype=float) @ np.asarray(params["G"]).T
    return y


def inverse(y, params: dict, cond: Conditions | None = None) -> np.ndarray:
    """Gyro output (N, 3) → true body rate: ``ω = K⁻¹ (y − ε − …)`` (P4's compensation)."""
    y = np.atleast_2d(np.asarray(y, dtype=float))
    r = y - np.asarray(params["eps"]) - additive_terms(params, cond, len(y))
    if "G" in params:
        r = r - np.asarray(cond.f_mps2, dtype=float) @ np.asarray(params["G"]).T
    return np.linalg.solve(np.asarray(params["K"]), r.T).T if "K" in params else r


def earth_rate_body(latitude_deg: float, C_n_b: np.ndarray) -> np.ndarray:
    """Earth rate in P4's body frame (x fwd, y up, z right): ``C_b_n ω_ie^n`` (NUE)."""
    return project_nav_rate(np.asarray(C_n_b).T, earth_rate_nue(latitude_deg))


def project_nav_rate(C_b_n: np.ndarray, omega_nav_rad_s) -> np.ndarray:
    """``C_b_n ω^n``: a navigation-frame rate seen by the body, for one (3x3) or many
    (N, 3, 3) attitudes. With ``ω^n = ω_ie^n`` it is the Earth rate the gyros see; with
    ``ω^n`` fitted (latitude unknown) it is diagnosis's ``earth_rate`` candidate."""
    C = np.asarray(C_b_n, dtype=float)
    w = np.asarray(omega_nav_rad_s, dtype=float)
    return C @ w if C.ndim == 2 else np.einsum("nij,j->ni", C, w)


def effect_blocks(name: str, size: float, rng: np.random.Generator, params: dict) -> dict:
    """Effect blocks of magnitude ``size``: temperature_bias rad/s per °C; time_drift rad/s
    per hour; g_sensitivity rad/s per m/s²."""
    if name == "temperature_bias":
        return {"bT": size * random_signs(rng, 3)}
    if name == "time_drift":
        return {"bt": size * random_signs(rng, 3) / 3600.0}
    if name == "g_sensitivity":
        return {"G": size * random_signs(rng, (3, 3))}
    if name == "earth_rate":
        return {}
    raise KeyError(f"unknown gyro effect {name!r}; known: {', '.join(EFFECTS)}")


# ----------------------------------------------------------------- integration (rotations)


def rotvec_matrices(phi) -> np.ndarray:
    """``exp([φ]×)`` for rotation vectors (..., 3) → (..., 3, 3) (Rodrigues, exact)."""

    def coefficients(th, ths, small):
        return np.where(small, 1.0 - th**2 / 6.0, np.sin(ths) / ths), _one_minus_cos_over_th2(th, ths, small)

    return _so3_series(phi, 1e-8, coefficients)


def right_jacobian(phi) -> np.ndarray:
    """SO(3) right Jacobian ``J_r(φ)``: ``exp([φ + δ]×) ≈ exp([φ]×) exp([J_r δ]×)``, (..., 3, 3)."""

    def coefficients(th, ths, small):
        b = np.where(small, 1.0 / 6.0 - th**2 / 120.0, (ths - np.sin(ths)) / ths**3)
        return -_one_minus_cos_over_th2(th, ths, small), b

    return _so3_series(phi, 1e-6, coefficients)


def _so3_series(phi, small_rad: float, coefficients) -> np.ndarray:
    """``I + a [φ]× + b [φ]×²`` for rotation vectors (..., 3), the scalars ``(a, b) =
    coefficients(θ, θ_safe, small)`` of ``θ = |φ|``: below ``small_rad`` they take their
    Taylor series in θ (``small`` is True there and ``θ_safe`` 1, so the closed forms stay
    finite)."""
    phi = np.asarray(phi, dtype=float)
    th2 = np.einsum("...i,...i->...", phi, phi)[..., None, None]
    th = np.sqrt(th2)
    small = th < small_rad
    ths = np.where(small, 1.0, th)
    a, b = coefficients(th, ths, small)
    # I + a [φ]× + b (φφᵀ − θ² I), entry by entry ([φ]×² = φφᵀ − θ² I)
    a, b, th2 = a[..., 0, 0], b[..., 0, 0], th2[..., 0, 0]
    out = np.empty((*phi.shape[:-1], 3, 3))
    bp = b[..., None] * phi
    for i in range(3):
        out[..., i, :] = bp * phi[..., i, None]
        out[..., i, i] += 1.0 - b * th2
    ap = a[..., None] * phi
    out[..., 0, 1] -= ap[..., 2]
    out[..., 0, 2] += ap[..., 1]
    out[..., 1, 0] += ap[..., 2]
    out[..., 1, 2] -= ap[..., 0]
    out[..., 2, 0] -= ap[..., 1]
    out[..., 2, 1] += ap[..., 0]
    return out


def _one_minus_cos_over_th2(th, ths, small):
    """``(1 − cos θ) / θ²`` (its series ``1/2 − θ²/24`` where ``small``)."""
    return np.where(small, 0.5 - th**2 / 24.0, (1.0 - np.cos(ths)) / ths**2)


def integrate_rates(omega_rad_s, t_s, *, with_jacobian: bool = False):
    """Body rotation over a stretch of body rates: ``R = Π_j exp([φ_j]×)``, ``φ_j`` the
    trapezoid ``(ω_j + ω_{j+1}) (t_{j+1} − t_j) / 2``.

    ``R`` maps the end frame's coordinates to the start frame's (``C_end = C_start R``), so a
    vector fixed in the world, ``v_start`` at the start, reads ``Rᵀ v_start`` at the end.
    Batched: ``omega_rad_s`` (m, n, 3), ``t_s`` (m, n); shorter stretches padded with repeated
    times (zero steps). With ``with_jacobian`` also returns ``Q`` (m, n−1, 3, 3) with
    ``δθ = Σ_j Q_j δφ_j``: a change ``δφ_j`` of step j rotates the result by ``R exp([δθ]×)``
    (``Q_j = P_jᵀ J_r(φ_j)``, ``P_j`` the product of the steps after j).
    """
    w = np.asarray(omega_rad_s, dtype=float)
    t = np.asarray(t_s, dtype=float)
    single = w.ndim == 2
    if single:
        w, t = w[None], t[None]
    dt = np.diff(t, axis=1)[..., None]
    phi = 0.5 * (w[:, 1:] + w[:, :-1]) * dt
    S = rotvec_matrices(phi)  # (m, n-1, 3, 3)
    if not with_jacobian:
        R = _product(S)
        return R[0] if single else R
    R, P = _suffix_products(S)
    Q = np.swapaxes(P, -1, -2) @ right_jacobian(phi)
    return (R[0], Q[0]) if single else (R, Q)


def _product(S: np.ndarray) -> np.ndarray:
    """``S_0 S_1 … S_{n−1}`` for matrices ``S`` (m, n, 3, 3), in order, by pairs (about log₂ n
    batched products)."""
    m = S.shape[0]
    while S.shape[1] > 1:
        if S.shape[1] % 2:
            S = np.concatenate([S, np.broadcast_to(np.eye(3), (m, 1, 3, 3))], axis=1)
        S = S[:, 0::2] @ S[:, 1::2]
    if S.shape[1] == 0:
        return np.broadcast_to(np.eye(3), (m, 3, 3)).copy()
    return S[:, 0].copy()


def _suffix_products(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For matrices ``S`` (m, n, 3, 3): the products ``S_0 S_1 … S_{n−1}`` (m, 3, 3) and, per j,
    ``P_j = S_{j+1} … S_{n−1}`` (m, n, 3, 3; ``P_{n−1} = I``). In blocks of about √n steps:
    the suffix products within each block, then across the blocks' own products, then the two
    composed, so the Python loops run about 2√n times rather than n."""
    m, n = S.shape[:2]
    if n == 0:
        return np.broadcast_to(np.eye(3), (m, 3, 3)).copy(), S.copy()
    b = max(1, math.isqrt(n - 1) + 1)  # steps per block
    c = -(-n // b)  # blocks
    padded = np.broadcast_to(np.eye(3), (m, c * b, 3, 3)).copy()  # identity steps after the last
    padded[:, :n] = S
    blocks = padded.reshape(m, c, b, 3, 3)
    local = np.empty_like(blocks)  # within a block: the product of its steps after i
    acc = np.broadcast_to(np.eye(3), (m, c, 3, 3)).copy()
    for i in range(b - 1, -1, -1):
        local[:, :, i] = acc
        acc = blocks[:, :, i] @ acc
    after = np.empty_like(acc)  # the product of the blocks after block k
    tail = np.broadcast_to(np.eye(3), (m, 3, 3)).copy()
    for k in range(c - 1, -1, -1):
        after[:, k] = tail
        tail = acc[:, k] @ tail
    P = (local @ after[:, :, None]).reshape(m, c * b, 3, 3)[:, :n]
    return tail, P


def rotation_from_output(y, t_s, params: dict, cond: Conditions | None = None) -> np.ndarray:
    """The rotation (``integrate_rates``) a gyro triad's raw output ``y`` (n, 3) implies under
    ``params``: ω = :func:`inverse` (y), then integrated over ``t_s``."""
    return integrate_rates(inverse(y, params, cond), t_s)
