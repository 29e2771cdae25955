"""Magnetometer forward error model (P3 and its diagnose effects).

Forward, the true field in the accelerometer/body frame ``m_b`` [nT] (rows) to raw output
``y`` [the capture's mag_unit]::

    y = W⁻¹ R(ρ) (s m_b) + h + Δh·[t ≥ t_on] + b_T (T − T_ref) + b_t (t − t_ref)

and the calibration of source 002 is its inverse ``m = W (y − h)`` (baseline).

- baseline: ``W`` [3x3] upper-triangular soft-iron correction (raw → nT), ``h`` [3] hard
  iron (raw units).
- effects (diagnose.md): ``mag_accel_misalignment`` → ``rho`` [3] rad, the rotation
  vector of the magnetometer frame against the accelerometer frame (``R(ρ)`` maps
  accelerometer-frame components to magnetometer-frame ones); ``field_anomaly`` →
  ``field_scale`` (scalar): the local field is ``s`` times the IGRF field;
  ``time_varying_hard_iron`` → ``dh`` [3] raw units and ``t_on_s`` (scalar, s): a step
  in the hard iron when a current switches on; ``temperature_bias`` → ``bT`` [3];
  ``time_drift`` → ``bt`` [3] raw/s.
"""

from __future__ import annotations

import numpy as np

from solvers.frames import rotvec_to_matrix
from solvers.models import Conditions, additive_terms, random_signs

BASELINE = ("W", "h")
EFFECTS = {
    "mag_accel_misalignment": ("rho",),
    "field_anomaly": ("field_scale",),
    "time_varying_hard_iron": ("dh", "t_on_s"),
    "temperature_bias": ("bT",),
    "time_drift": ("bt",),
}
SHAPES = {"W": (3, 3), "h": (3,), "rho": (3,), "field_scale": (), "dh": (3,), "t_on_s": (), "bT": (3,), "bt": (3,)}


def hard_iron(params: dict, cond: Conditions | None, n: int) -> np.ndarray:
    """Total additive offset (N, 3): ``h`` plus the step, temperature and time terms."""
    out = np.asarray(params["h"], dtype=float) + additive_terms(params, cond, n)  # (n, 3)
    if "dh" in params:
        if cond is None or cond.t_s is None:
            raise ValueError("time_varying_hard_iron needs the time (cond.t_s)")
        on = np.asarray(cond.t_s, dtype=float) >= float(params["t_on_s"])
        out += np.outer(on, params["dh"])
    return out


def forward(m_body_nT, params: dict, cond: Conditions | None = None) -> np.ndarray:
    """True field (N, 3) nT in the accelerometer frame → raw output (N, 3)."""
    m = np.atleast_2d(np.asarray(m_body_nT, dtype=float))
    if "field_scale" in params:
        m = m * float(params["field_scale"])
    if "rho" in params:
        m = m @ rotvec_to_matrix(params["rho"]).T
    raw = np.linalg.solve(np.asarray(params["W"], dtype=float), m.T).T
    return raw + hard_iron(params, cond, len(m))


def inverse(y, params: dict, cond: Conditions | None = None) -> np.ndarray:
    """Raw output (N, 3) → calibrated field ``W (y − h …)`` [nT], in the accelerometer frame
    when ``rho`` is given (the field scale is a property of the site, not undone here)."""
    y = np.atleast_2d(np.asarray(y, dtype=float))
    m = (y - hard_iron(params, cond, len(y))) @ np.asarray(params["W"], dtype=float).T
    if "rho" in params:
        m = m @ rotvec_to_matrix(params["rho"])
    return m


def effect_blocks(name: str, size: float, rng: np.random.Generator, params: dict, duration_s: float = 60.0) -> dict:
    """Effect blocks of magnitude ``size``: mag_accel_misalignment rad; field_anomaly
    relative change of the field magnitude; time_varying_hard_iron raw units (step at a
    random time in the middle half of the capture); temperature_bias raw/°C;
    time_drift raw/hour."""
    if name == "mag_accel_misalignment":
        v = rng.normal(size=3)
        return {"rho": size * v / np.linalg.norm(v)}
    if name == "field_anomaly":
        return {"field_scale": np.array(1.0 + size * rng.choice([-1.0, 1.0]))}
    if name == "time_varying_hard_iron":
        v = rng.normal(size=3)
        return {"dh": size * v / np.linalg.norm(v), "t_on_s": np.array(rng.uniform(0.25, 0.75) * duration_s)}
    if name == "temperature_bias":
        return {"bT": size * random_signs(rng, 3)}
    if name == "time_drift":
        return {"bt": size * random_signs(rng, 3) / 3600.0}
    raise KeyError(f"unknown magnetometer effect {name!r}; known: {', '.join(EFFECTS)}")
