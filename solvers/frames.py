"""Frames, rotations, gravity and Earth rate: the conventions, stated once.

Conventions
-----------
- A rotation matrix ``C_a_b`` maps a vector's components in frame *b* into frame *a*:
  ``v_a = C_a_b @ v_b``. Its transpose is ``C_b_a``.
- Body frame ``b`` = the sensor triad's axes.
- ``NED``: x north, y east, z down (compass, LDV, the simulator).
- ``NUE``: x north, y up, z east: P4's navigation frame (source 003), with body axes
  x forward, y up, z right.
- Accelerometers measure specific force ``f = a - g_vec``: at rest, the axis pointing up
  reads ``+g``.
- Euler angles (roll φ, pitch θ, yaw ψ) are aerospace z-y-x for NED:
  ``C_n_b = Rz(ψ) Ry(θ) Rx(φ)``.
"""

from __future__ import annotations

import math

import numpy as np

OMEGA_EARTH_RAD_S = 7.2921151e-5  # WGS-84 Earth rotation rate
G_STANDARD_MPS2 = 9.80665


def rot_x(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def skew(v) -> np.ndarray:
    """Cross-product matrix ``[v]×``: ``skew(a) @ b == np.cross(a, b)``. Batched: vectors
    (..., 3) → (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    K = np.zeros((*v.shape[:-1], 3, 3))
    K[..., 0, 1], K[..., 0, 2] = -v[..., 2], v[..., 1]
    K[..., 1, 0], K[..., 1, 2] = v[..., 2], -v[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -v[..., 1], v[..., 0]
    return K


def rotvec_to_matrix(rotvec) -> np.ndarray:
    """Rodrigues: rotation by |rotvec| radians about rotvec's direction (active)."""
    r = np.asarray(rotvec, dtype=float)
    angle = float(np.linalg.norm(r))
    if angle < 1e-15:
        return np.eye(3) + skew(r)
    k = skew(r / angle)
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


def matrix_to_rotvec(C: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rotvec_to_matrix` (angle in [0, π])."""
    C = np.asarray(C, dtype=float)
    cos_a = np.clip((np.trace(C) - 1.0) / 2.0, -1.0, 1.0)
    angle = math.acos(cos_a)
    w = np.array([C[2, 1] - C[1, 2], C[0, 2] - C[2, 0], C[1, 0] - C[0, 1]])
    if angle < 1e-9:
        return w / 2.0
    if math.pi - angle < 1e-6:
        # near π: axis from the symmetric part
        M = (C + np.eye(3)) / 2.0
        axis = np.sqrt(np.clip(np.diag(M), 0.0, None))
        i = int(np.argmax(axis))
        axis = M[:, i] / math.sqrt(M[i, i])
        return axis * angle
    return w * (angle / (2.0 * math.sin(angle)))


def euler_to_C_n_b(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """Body → NED for aerospace z-y-x Euler angles."""
    return rot_z(yaw_rad) @ rot_y(pitch_rad) @ rot_x(roll_rad)


def C_n_b_to_euler(C_n_b: np.ndarray) -> tuple[float, float, float]:
    """(roll, pitch, yaw) in radians from a body → NED matrix."""
    pitch = -math.asin(float(np.clip(C_n_b[2, 0], -1.0, 1.0)))
    roll = math.atan2(C_n_b[2, 1], C_n_b[2, 2])
    yaw = math.atan2(C_n_b[1, 0], C_n_b[0, 0])
    return roll, pitch, yaw


def rotation_between(a, b) -> np.ndarray:
    """The smallest rotation C with ``C @ â = b̂`` (both normalised)."""
    a = np.asarray(a, dtype=float) / np.linalg.norm(a)
    b = np.asarray(b, dtype=float) / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    if c < -1.0 + 1e-12:
        # opposite: rotate π about any axis perpendicular to a
        perp = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(perp) < 1e-6:
            perp = np.cross(a, [0.0, 1.0, 0.0])
        return rotvec_to_matrix(math.pi * perp / np.linalg.norm(perp))
    k = skew(v)
    return np.eye(3) + k + k @ k / (1.0 + c)


def normal_gravity_mps2(latitude_deg: float, altitude_m: float = 0.0) -> float:
    """WGS-84 normal gravity (Somigliana) with the free-air height correction.

    ``γ(φ) = γ_e (1 + k sin²φ) / sqrt(1 − e² sin²φ)``, then
    ``γ(φ, h) = γ(φ) (1 − 2/a (1 + f + m − 2 f sin²φ) h + 3 h² / a²)``.
    """
    a = 6378137.0
    f = 1.0 / 298.257223563
    m = 0.00344978650684
    gamma_e = 9.7803253359
    k = 0.00193185265241
    e2 = 6.69437999013e-3
    s2 = math.sin(math.radians(latitude_deg)) ** 2
    g0 = gamma_e * (1.0 + k * s2) / math.sqrt(1.0 - e2 * s2)
    h = float(altitude_m)
    return g0 * (1.0 - 2.0 / a * (1.0 + f + m - 2.0 * f * s2) * h + 3.0 * h * h / (a * a))


def earth_rate_nue(latitude_deg: float) -> np.ndarray:
    """Earth rate in P4's north-up-east frame: ``[ω cos L, ω sin L, 0]`` rad/s."""
    lat = math.radians(latitude_deg)
    return OMEGA_EARTH_RAD_S * np.array([math.cos(lat), math.sin(lat), 0.0])


def earth_rate_ned(latitude_deg: float) -> np.ndarray:
    """Earth rate in NED: ``[ω cos L, 0, −ω sin L]`` rad/s."""
    lat = math.radians(latitude_deg)
    return OMEGA_EARTH_RAD_S * np.array([math.cos(lat), 0.0, -math.sin(lat)])


# P4 (source 003): body x forward, y up, z right; navigation x north, y up, z east.
# NED <-> NUE and body(FRD) <-> body(FUR) permutations, so that one attitude routine serves both.
C_NUE_NED = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
C_FUR_FRD = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def p4_C_n_b(pitch_rad: float, roll_rad: float, heading_rad: float = 0.0) -> np.ndarray:
    """P4's body(x fwd, y up, z right) → nav(N, U, E) rotation from (ψ, θ, γ).

    Built through the NED/FRD equivalents: ``C_nue_fur = C_NUE_NED C_ned_frd C_FUR_FRDᵀ``
    with ``C_ned_frd = Rz(ψ) Ry(θ) Rx(γ)``; pitch θ raises the forward axis, roll γ
    lowers the right axis (right wing down positive).
    """
    return C_NUE_NED @ euler_to_C_n_b(roll_rad, pitch_rad, heading_rad) @ C_FUR_FRD.T


def p4_pitch_roll_from_accel(f_body_fur) -> tuple[float, float]:
    """Pitch and roll (rad) from the mean specific force in P4's body frame (x fwd, y up, z right).

    At rest the specific force points up: ``f_b = C_b_n [0, g, 0]`` (NUE). In FRD terms
    ``f_frd = g [sinθ, −cosθ sinγ, −cosθ cosγ]``, which this inverts.
    """
    f_frd = C_FUR_FRD.T @ np.asarray(f_body_fur, dtype=float)
    pitch = math.atan2(f_frd[0], math.hypot(f_frd[1], f_frd[2]))
    roll = math.atan2(-f_frd[1], -f_frd[2])
    return pitch, roll
