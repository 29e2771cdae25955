"""Three-beam laser Doppler velocimeter forward error model (P5 and its diagnose effects).

Per beam j, with body-frame velocity ``v`` [m/s] at the reference point (source 004)::

    V_Lj(t) = (1 + δK_j) u_j · (v(t − τ) + ω(t − τ) × r) + o_j + b_Tj (T − T_ref) + b_tj (t − t_ref)

``u_j = (cos α_j, cos β_j, cos γ_j)`` the beam's direction cosines. The source's linear
form is ``X_j = (1 + δK_j) u_j``; block ``X`` [3x3] holds the three beams as rows.

- baseline: ``X`` [3x3].
- effects (diagnose.md): ``time_delay`` → ``tau_s`` (scalar, s; needs ``cond.t_s``; the
  velocity is interpolated in time, or shifted all-pass below ``cond.delay_band_hz``); ``lever_arm`` → ``r`` [3] m (needs
  ``cond.omega_body_rad_s``); ``offset`` → ``o`` [3] m/s; ``temperature_bias`` → ``bT``
  [3]; ``time_drift`` → ``bt`` [3] m/s per s.
"""

from __future__ import annotations

import numpy as np

from solvers.models import Conditions, additive_terms, random_signs

BASELINE = ("X",)
EFFECTS = {
    "time_delay": ("tau_s",),
    "lever_arm": ("r",),
    "offset": ("o",),
    "temperature_bias": ("bT",),
    "time_drift": ("bt",),
}
SHAPES = {"X": (3, 3), "tau_s": (), "r": (3,), "o": (3,), "bT": (3,), "bt": (3,)}


def X_from_angles(dK, alpha_deg, beta_deg, gamma_deg) -> np.ndarray:
    """Rows ``(1 + δK_j)(cos α_j, cos β_j, cos γ_j)``."""
    cosines = np.cos(np.radians(np.stack([alpha_deg, beta_deg, gamma_deg], axis=-1)))
    return (1.0 + np.asarray(dK, dtype=float))[:, None] * cosines


def angles_from_X(X) -> dict:
    """Source 004's read-out: ``1 + δK = |X_j|``, ``cos α = X_j1 / |X_j|`` and so on."""
    X = np.asarray(X, dtype=float)
    norm = np.linalg.norm(X, axis=1)
    ang = np.degrees(np.arccos(np.clip(X / norm[:, None], -1.0, 1.0)))
    return {"dK": norm - 1.0, "alpha_deg": ang[:, 0], "beta_deg": ang[:, 1], "gamma_deg": ang[:, 2]}


def _uniform(t: np.ndarray) -> bool:
    """Whether the samples are equally spaced (to 0.1 % of a step)."""
    if len(t) < 4 or t[-1] <= t[0]:
        return False
    dt = (t[-1] - t[0]) / (len(t) - 1)
    return bool(np.max(np.abs(np.diff(t) - dt)) <= 1e-3 * dt)


def _allpass_delayed(arr: np.ndarray, t: np.ndarray, tau: float, band_hz: float) -> np.ndarray:
    """``arr(t − τ)`` by a Fourier phase shift of its content below ``band_hz`` (uniform ``t``):
    the line through the first and last samples is taken out first (so the periodic extension
    has no jump) and shifted exactly; the remainder's spectrum is multiplied by
    ``exp(−2πi f τ)`` below the band and left as it is above it. Both are unitary, so white
    noise in ``arr`` keeps its energy at every τ."""
    n = len(t)
    span = t[-1] - t[0]
    slope = (arr[-1] - arr[0]) / span
    line = arr[0] + (t - t[0])[:, None] * slope
    spec = np.fft.rfft(arr - line, axis=0)
    f = np.fft.rfftfreq(n, span / (n - 1))
    phase = np.where(f < band_hz, np.exp(-2j * np.pi * f * tau), 1.0)
    if n % 2 == 0:
        phase[-1] = phase[-1].real  # the Nyquist term of a real series stays real
    return np.fft.irfft(spec * phase[:, None], n=n, axis=0) + line - tau * slope


def _delayed(arr: np.ndarray, t: np.ndarray, tau: float, band_hz: float | None = None) -> np.ndarray:
    """``arr(t − τ)``: linear interpolation (``band_hz`` None, or a non-uniform ``t``), else
    ``_allpass_delayed``."""
    if band_hz is not None and tau != 0.0 and _uniform(t):
        return _allpass_delayed(arr, t, tau, band_hz)
    return np.column_stack([np.interp(t - tau, t, arr[:, k]) for k in range(arr.shape[1])])


def body_velocity_at_beam(v_body_mps, params: dict, cond: Conditions | None = None) -> np.ndarray:
    """``v(t − τ) + ω(t − τ) × r``: what the beams see before gain and offset."""
    v = np.atleast_2d(np.asarray(v_body_mps, dtype=float))
    w = None
    if "r" in params:
        if cond is None or cond.omega_body_rad_s is None:
            raise ValueError("lever_arm needs the body rate (cond.omega_body_rad_s)")
        w = np.asarray(cond.omega_body_rad_s, dtype=float)
    if "tau_s" in params:
        if cond is None or cond.t_s is None:
            raise ValueError("time_delay needs the time (cond.t_s)")
        t = np.asarray(cond.t_s, dtype=float)
        v = _delayed(v, t, float(params["tau_s"]), cond.delay_band_hz)
        if w is not None:
            w = _delayed(w, t, float(params["tau_s"]), cond.delay_band_hz)
    if w is not None:
        v = v + np.cross(w, np.asarray(params["r"], dtype=float))
    return v


def forward(v_body_mps, params: dict, cond: Conditions | None = None) -> np.ndarray:
    """Body velocity (N, 3) m/s → the three beam outputs (N, 3) m/s."""
    v = body_velocity_at_beam(v_body_mps, params, cond)
    y = v @ np.asarray(params["X"], dtype=float).T
    if "o" in params:
        y = y + np.asarray(params["o"])
    return y + additive_terms(params, cond, len(v))


def effect_blocks(name: str, size: float, rng: np.random.Generator, params: dict) -> dict:
    """Effect blocks of magnitude ``size``: time_delay s; lever_arm m; offset m/s;
    temperature_bias m/s per °C; time_drift m/s per hour."""
    if name == "time_delay":
        return {"tau_s": np.array(size)}
    if name == "lever_arm":
        v = rng.normal(size=3)
        return {"r": size * v / np.linalg.norm(v)}
    if name == "offset":
        return {"o": size * random_signs(rng, 3)}
    if name == "temperature_bias":
        return {"bT": size * random_signs(rng, 3)}
    if name == "time_drift":
        return {"bt": size * random_signs(rng, 3) / 3600.0}
    raise KeyError(f"unknown LDV effect {name!r}; known: {', '.join(EFFECTS)}")
