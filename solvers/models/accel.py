"""Accelerometer triad forward error model (P1, P2 and their diagnose effects).

Forward, specific force ``f`` (rows, in the model's input unit: m/s² for P1, g for P2)
to raw output ``y`` (V, counts, g, ...)::

    u = f + D∘f² + C3∘f³ + A∘min(f, 0) + L                 per-axis input terms
    y = K u + b + b_T (T − T_ref) + b_t (t − t_ref)

with ``L_i = ω² dr_i c_i / unit`` the lever-arm term (``c`` the centripetal direction).

Blocks:
- baseline: ``K`` [3x3] and ``b`` [3]; P2 writes ``K = diag(S) Φ(γ)`` with blocks ``S`` [3]
  and, for ``misalignment``, ``gamma`` [6] = (γxy, γxz, γyx, γyz, γzx, γzy),
  ``Φ = [[1, γxy, γxz], [γyx, 1, γyz], [γzx, γzy, 1]]`` (P2, source 001 eq. 2-3).
  P1 (source 000) writes the calibration ``A = B + M V``: the same model with
  ``M = K⁻¹`` and ``B = −M b`` (see :func:`p1_to_forward`).
- effects (diagnose.md): ``quadratic`` → ``D`` [3] (1/unit); ``cubic`` → ``C3`` [3]
  (1/unit²); ``scale_asymmetry`` → ``A`` [3] (extra relative scale on negative input);
  ``temperature_bias`` → ``bT`` [3] (output/°C); ``time_drift`` → ``bt`` [3] (output/s);
  ``misalignment`` → ``gamma`` [6] (rad); ``lever_arm`` → ``dr`` [3] (m).
"""

from __future__ import annotations

import numpy as np

from solvers.models import Conditions, additive_terms, random_signs

BASELINE = {"p1": ("K", "b"), "p2": ("S", "b", "D")}
EFFECTS = {
    "quadratic": ("D",),
    "cubic": ("C3",),
    "scale_asymmetry": ("A",),
    "temperature_bias": ("bT",),
    "time_drift": ("bt",),
    "misalignment": ("gamma",),
    "lever_arm": ("dr",),
}
SHAPES = {
    "K": (3, 3),
    "b": (3,),
    "S": (3,),
    "D": (3,),
    "C3": (3,),
    "A": (3,),
    "bT": (3,),
    "bt": (3,),
    "gamma": (6,),
    "dr": (3,),
}


def centrifuge_input_g(speed_rad_s, radius_m: float, g_mps2: float):
    """P2's centripetal input ``A = ω² R / g`` in g at table speed ω (rad/s), radius R (m),
    local gravity g (m/s²): the specific force is ``f = A c + up`` (c the centripetal
    direction, the unit vector from the triad toward the axis; source 001 eq. 6), so an axis
    ``dr`` farther out sees ``A (1 + dr/R) c`` (the ``lever_arm`` term)."""
    return np.asarray(speed_rad_s, dtype=float) ** 2 * radius_m / g_mps2


def centrifuge_specific_force_g(speed_rad_s, radius_m: float, g_mps2: float) -> np.ndarray:
    """P2's specific force at the triad in the table frame (radial outward, tangential, up), in
    g: ``f = (−A, 0, 1)``, the centripetal input of :func:`centrifuge_input_g` pointing inward
    plus the reaction to gravity, so ``|f|² = A² + 1``. (3,) for one speed, (N, 3) for N."""
    A = centrifuge_input_g(speed_rad_s, radius_m, g_mps2)
    return np.stack([-A, np.zeros_like(A), np.ones_like(A)], axis=-1)


def phi_matrix(gamma) -> np.ndarray:
    """Installation-error matrix Φ(γ), γ in the order γxy, γxz, γyx, γyz, γzx, γzy."""
    g = np.asarray(gamma, dtype=float)
    return np.array([[1.0, g[0], g[1]], [g[2], 1.0, g[3]], [g[4], g[5], 1.0]])


def K_matrix(params: dict) -> np.ndarray:
    """The 3x3 gain: ``K`` itself, or ``diag(S) Φ(γ)`` (Φ = I without ``gamma``)."""
    if "K" in params:
        return np.asarray(params["K"], dtype=float)
    S = np.asarray(params["S"], dtype=float)
    phi = phi_matrix(params["gamma"]) if "gamma" in params else np.eye(3)
    return S[:, None] * phi


def input_terms(f: np.ndarray, params: dict, cond: Conditions | None) -> np.ndarray:
    """``u`` of the module docstring: the per-axis input nonlinearity plus the lever arm."""
    f = np.atleast_2d(np.asarray(f, dtype=float))
    u = f.copy()
    if "D" in params:
        u += np.asarray(params["D"]) * f * f
    if "C3" in params:
        u += np.asarray(params["C3"]) * f**3
    if "A" in params:
        u += np.asarray(params["A"]) * np.minimum(f, 0.0)
    if "dr" in params:
        u += _lever_arm(params, cond, len(f))
    return u


def _lever_arm(params: dict, cond: Conditions | None, n: int) -> np.ndarray:
    if cond is None or cond.omega_rad_s is None or cond.centripetal_dir is None:
        raise ValueError("lever_arm needs the centrifuge speed and centripetal direction")
    w2 = np.asarray(cond.omega_rad_s, dtype=float) ** 2
    return (w2[:, None] * np.asarray(params["dr"]) * np.asarray(cond.centripetal_dir)) / cond.input_unit_mps2


def forward(f, params: dict, cond: Conditions | None = None) -> np.ndarray:
    """Specific force (N, 3) in input units → raw output (N, 3)."""
    u = input_terms(f, params, cond)
    return u @ K_matrix(params).T + np.asarray(params["b"]) + additive_terms(params, cond, len(u))


# Newton's stop in :func:`inverse`: the residual of ``f + D f² + C3 f³ + A min(f, 0) = u`` below
# this share of max |u| (a few units in the last place)
NEWTON_RTOL = 4.0 * np.finfo(float).eps


def inverse(y, params: dict, cond: Conditions | None = None, iterations: int = 8) -> np.ndarray:
    """Raw output (N, 3) → specific force (N, 3): the exact inverse of :func:`forward`.

    Linear part by solving with K; the per-axis polynomial by Newton's method from
    ``f = u`` (converges in a few steps for the small coefficients a sensor has).
    """
    y = np.atleast_2d(np.asarray(y, dtype=float))
    rhs = y - np.asarray(params["b"]) - additive_terms(params, cond, len(y))
    u = np.linalg.solve(K_matrix(params), rhs.T).T
    if "dr" in params:
        u = u - _lever_arm(params, cond, len(u))
    poly = [k for k in ("D", "C3", "A") if k in params]
    if not poly:
        return u
    D = np.asarray(params.get("D", np.zeros(3)))
    C3 = np.asarray(params.get("C3", np.zeros(3)))
    A = np.asarray(params.get("A", np.zeros(3)))
    f = u.copy()
    # converged: the equation's residual at the rounding of u (Newton's next step would move f
    # by less than that); at D = C3 = A = 0 (a candidate at its null value) that is the start
    tol = NEWTON_RTOL * float(np.max(np.abs(u), initial=0.0))
    for _ in range(iterations):
        fm = np.minimum(f, 0.0)
        g = f + (D * f + C3 * (f * f)) * f + A * fm - u
        if not np.max(np.abs(g), initial=0.0) > tol:
            break
        dg = 1.0 + (2.0 * D + 3.0 * C3 * f) * f + A * (f < 0.0)
        f = f - g / dg
    return f


def p1_to_forward(B, M) -> dict:
    """P1's ``A = B + M V`` → forward blocks ``K = M⁻¹``, ``b = −M⁻¹ B``."""
    M = np.asarray(M, dtype=float)
    K = np.linalg.inv(M)
    return {"K": K, "b": -K @ np.asarray(B, dtype=float)}


def forward_to_p1(params: dict) -> tuple[np.ndarray, np.ndarray]:
    """Forward ``K, b`` → P1's ``(B, M)`` with ``M = K⁻¹``, ``B = −M b``."""
    M = np.linalg.inv(K_matrix(params))
    return -M @ np.asarray(params["b"], dtype=float), M


def effect_blocks(name: str, size: float, rng: np.random.Generator, params: dict) -> dict:
    """Blocks for effect ``name`` with magnitude ``size``, pattern drawn from ``rng``.

    Units of ``size``: quadratic 1/input-unit; cubic 1/input-unit²; scale_asymmetry
    relative; temperature_bias input-units per °C; time_drift input-units per hour;
    misalignment rad; lever_arm m. Biases are mapped to the output through ``K``.
    """
    K = K_matrix(params)
    if name == "quadratic":
        return {"D": size * random_signs(rng, 3)}
    if name == "cubic":
        return {"C3": size * random_signs(rng, 3)}
    if name == "scale_asymmetry":
        return {"A": size * random_signs(rng, 3)}
    if name == "temperature_bias":
        return {"bT": K @ (size * random_signs(rng, 3))}
    if name == "time_drift":
        return {"bt": K @ (size * random_signs(rng, 3)) / 3600.0}
    if name == "misalignment":
        return {"gamma": size * random_signs(rng, 6)}
    if name == "lever_arm":
        return {"dr": size * random_signs(rng, 3)}
    raise KeyError(f"unknown accelerometer effect {name!r}; known: {', '.join(EFFECTS)}")


def p1_apply(V, B, M) -> np.ndarray:
    """P1's calibration ``A = B + M V`` on rows (N, 3): the exact inverse of :func:`forward`
    with ``K = M⁻¹``, ``b = −M⁻¹ B`` (no effect blocks), written directly for speed."""
    return np.asarray(B, dtype=float) + np.atleast_2d(np.asarray(V, dtype=float)) @ np.asarray(M, dtype=float).T


def p1_norm_sigma(V, B, M, var_V) -> np.ndarray:
    """The noise of ``|A|`` (:func:`p1_apply`) per row from the variances ``var_V`` (N, 3) of
    the raw components (independent axes; first order: ``∂|A|/∂V = ûᵀ M``), floored at
    1e-6 of the median ``|A|`` (quantisation and rounding)."""
    V = np.atleast_2d(np.asarray(V, dtype=float))
    A = p1_apply(V, B, M)
    norm = np.linalg.norm(A, axis=1)
    w = (A / norm[:, None]) @ np.asarray(M, dtype=float)
    s = np.sqrt(np.sum(w * w * np.asarray(var_V, dtype=float), axis=1))
    return np.maximum(s, 1e-6 * float(np.median(norm)))


def p1_norm_jacobian(V, B, M) -> tuple[np.ndarray, np.ndarray]:
    """``|A|`` of :func:`p1_apply` and its Jacobian (N, 12) w.r.t. ``(B[0..2], M[0][0], M[0][1], …, M[2][2])``
    (row-major, the order of ``solvers.params``): ``∂|A|/∂B = û``, ``∂|A|/∂M_ij = û_i V_j``."""
    V = np.atleast_2d(np.asarray(V, dtype=float))
    A = p1_apply(V, B, M)
    norm = np.linalg.norm(A, axis=1)
    u = A / norm[:, None]
    return norm, np.hstack([u, (u[:, :, None] * V[:, None, :]).reshape(len(V), 9)])


def p2_norm_jacobian(y, params: dict) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """``|f|`` of :func:`inverse` (P2 blocks ``S``, ``b``, ``D``, optional ``gamma``; no other
    effects) and its Jacobian w.r.t. those blocks, columns named like ``solvers.params``
    (``S[0]``…, ``b[0]``…, ``D[0]``…, ``gamma[0]``…). Implicit differentiation of
    ``forward(f) = y``: ``∂f/∂θ = −(K diag(1 + 2 D f))⁻¹ ∂forward/∂θ``."""
    y = np.atleast_2d(np.asarray(y, dtype=float))
    f = inverse(y, params)
    norm = np.linalg.norm(f, axis=1)
    u_hat = f / norm[:, None]
    D = np.asarray(params.get("D", np.zeros(3)), dtype=float)
    K = K_matrix(params)
    G = np.linalg.solve((K * (1.0 + 2.0 * D * f)[:, None, :]).transpose(0, 2, 1), u_hat[:, :, None])[:, :, 0]
    u = f + D * f * f  # input terms
    S = np.asarray(params["S"], dtype=float)
    phi = phi_matrix(params["gamma"]) if "gamma" in params else np.eye(3)
    cols = [-G * (u @ phi.T), -G, -(G @ K) * f * f]
    names = [f"S[{i}]" for i in range(3)] + [f"b[{i}]" for i in range(3)] + [f"D[{i}]" for i in range(3)]
    if "gamma" in params:
        pairs = [(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)]
        cols.append(np.column_stack([-G[:, i] * S[i] * u[:, j] for i, j in pairs]))
        names += [f"gamma[{k}]" for k in range(6)]
    return norm, np.hstack(cols), names
