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
