"""Forward error models, one per sensor, shared by the simulator, the calibrations and diagnosis.

Each model module defines:
- ``forward(x, params, cond)``: true input → raw output, rows are samples;
- ``inverse(y, params, cond)``: raw output → true input (exact, for the fitted blocks);
- ``BASELINE`` and ``EFFECTS``: the block names each switches on;
- ``effect_blocks(name, size, rng, ...)``: blocks for an effect of a given size (for the
  simulator and the hidden-effect tests), the size's unit in the docstring.

An effect is on when its blocks are in the params dict. ``Conditions`` carries everything
about a sample that is not the input itself (time, temperature, centrifuge geometry, ...).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Conditions:
    """Per-sample conditions (arrays of length N where given).

    t_s: time from the capture's start [s]; temp_c: sensor temperature [°C];
    temp_rate_c_s: its rate of change [°C/s] on the same rows (``temperature_rate``), for a
    temperature column that lags (or leads) the temperature the sensor's bias follows;
    temp_ref_c / t_ref_s: the references the temperature and time terms are about;
    input_unit_mps2: one model input unit in m/s² (1 for m/s², g for inputs in g);
    omega_rad_s: centrifuge speed [rad/s] (N,); centripetal_dir: (N, 3) body-frame unit
    vector of the centripetal specific force; f_mps2: (N, 3) specific force for gyro
    g-sensitivity; omega_body_rad_s: (N, 3) body rate for the LDV lever arm.
    delay_band_hz: how a delayed input is formed between samples (LDV ``time_delay``): None,
    linear interpolation (exact for a piecewise-linear input: a simulated drive); a value, an
    all-pass Fourier shift of the input's content below that frequency (``math.inf``: all of
    it) on a uniform time base, which keeps the energy of the input's noise whatever the delay
    (a measured, noisy reference, whose linear interpolation averages neighbouring samples'
    noise and so fits better at any delay off the sample grid).
    """

    t_s: np.ndarray | None = None
    temp_c: np.ndarray | None = None
    temp_rate_c_s: np.ndarray | None = None
    temp_ref_c: float = 25.0
    t_ref_s: float = 0.0
    input_unit_mps2: float = 1.0
    omega_rad_s: np.ndarray | None = None
    centripetal_dir: np.ndarray | None = None
    f_mps2: np.ndarray | None = None
    omega_body_rad_s: np.ndarray | None = None
    delay_band_hz: float | None = None
    extra: dict = field(default_factory=dict)


def additive_terms(params: dict, cond: Conditions | None, n: int) -> np.ndarray:
    """The bias-like terms every sensor shares: ``b_T (T − T_ref + τ_T dT/dt) + b_t (t − t_ref)``, (N, k).

    ``temperature_bias`` (block ``bT``) needs ``cond.temp_c``; ``time_drift`` (``bt``)
    needs ``cond.t_s``. ``bT_lag_s`` (τ_T, scalar, s): the recorded temperature lags the one
    the bias follows by a first-order lag τ_T (a sensor on the board, not on the die; negative:
    it leads, as a chamber's air does), whose inverse is ``T + τ_T dT/dt``; needs
    ``cond.temp_rate_c_s``. A block present without its condition is an error, not a zero.
    The generic ``residual:<driver>`` extension of diagnosis (block ``bR``, (p, k)) adds
    ``Σ_p φ_p(x) bR[p]``: its basis ``cond.extra["basis"]``, (N, p) or per axis (N, p, k),
    holds the smooth functions of the driver at each sample.
    """
    width = None
    for key in ("bT", "bt", "bR"):
        if key in params:
            width = np.asarray(params[key]).shape[-1]
    if width is None:
        return np.zeros((n, 1))
    out = np.zeros((n, width))
    if "bT" in params:
        if cond is None or cond.temp_c is None:
            raise ValueError("temperature_bias needs the temperature (cond.temp_c)")
        temp = np.asarray(cond.temp_c, dtype=float) - cond.temp_ref_c
        lag_s = float(params.get("bT_lag_s", 0.0))
        if lag_s != 0.0:
            if cond.temp_rate_c_s is None:
                raise ValueError("a temperature lag needs the temperature's rate (cond.temp_rate_c_s)")
            temp = temp + lag_s * np.asarray(cond.temp_rate_c_s, dtype=float)
        out += np.outer(temp, params["bT"])
    if "bt" in params:
        if cond is None or cond.t_s is None:
            raise ValueError("time_drift needs the time (cond.t_s)")
        out += np.outer(np.asarray(cond.t_s, dtype=float) - cond.t_ref_s, params["bt"])
    if "bR" in params:
        basis = None if cond is None else cond.extra.get("basis")
        if basis is None:
            raise ValueError("the generic extension needs its basis (cond.extra['basis'])")
        B, c = np.asarray(basis, dtype=float), np.asarray(params["bR"], dtype=float)
        out += B @ c if B.ndim == 2 else np.einsum("npk,pk->nk", B, c)
    return out


RATE_MAX_HALF_WINDOW_S = 60.0  # temperature_rate: the longest half window
RATE_CHANGE_FRACTION = 0.1  # … and at most this share of the time its rate takes to change by itself


def temperature_rate(t_s, temp_c, half_window_s: float | None = None) -> np.ndarray:
    """dT/dt [°C/s] at each row of a time series: the slope of the least-squares line through
    the rows within ``half_window_s`` either side (at least two rows' spacing); 0 where the
    window holds one time. ``None``: a window per row, the shortest that holds the slope's noise
    (from the column's noise in successive differences, or its rounding) to 2 % of the typical
    rate and, in a column rounded to steps of q, spans 3 q of change either side at the local
    rate, but at most RATE_CHANGE_FRACTION of the time that rate takes to change, within 60 s: a lag of tens of seconds needs the rate on a few seconds where the
    temperature moves fast, and a quantised column moves one step in 10 s where it is slow."""
    t = np.asarray(t_s, dtype=float)
    T = np.asarray(temp_c, dtype=float)
    if t.size < 3:
        return np.zeros(t.size)
    order = np.argsort(t, kind="stable")
    if np.any(order != np.arange(t.size)):
        out = np.empty(t.size)
        out[order] = temperature_rate(t[order], T[order], half_window_s)
        return out
    dt = float(np.median(np.diff(t)))
    dt = dt if dt > 0 else float(t[-1] - t[0]) / (t.size - 1)
    if half_window_s is not None:
        return _slopes(t, T, np.full(t.size, max(float(half_window_s), 2.0 * dt)))
    dT = np.abs(np.diff(T))
    steps = dT[dT > 0]
    q = float(steps.min()) if steps.size else 0.0
    res = max(float(np.median(dT)) / 0.6745 / math.sqrt(2.0), q / math.sqrt(12.0))  # noise or rounding
    slope_30s = _slopes(t, T, np.full(t.size, 30.0))
    coarse = np.abs(slope_30s)
    typical = float(np.percentile(coarse, 75))
    if not (res > 0 and typical > 0 and dt > 0):
        return _slopes(t, T, np.full(t.size, 2.0 * dt))
    w = np.full(t.size, 0.5 * (res * math.sqrt(12.0) / (0.02 * typical * math.sqrt(1.0 / dt))) ** (2.0 / 3.0))
    if q > 0:
        w = np.maximum(w, 3.0 * q / np.maximum(coarse, 1e-12))
    # and short beside the time the rate takes to change (a lag's transient): a window's slope
    # is exact for a quadratic only where the window is whole, and a rate that doubles within
    # the window is not one
    change = np.abs(_slopes(t, slope_30s, np.full(t.size, 30.0)))
    w = np.minimum(w, RATE_CHANGE_FRACTION * coarse / np.maximum(change, 1e-300))
    return _slopes(t, T, np.clip(w, 2.0 * dt, RATE_MAX_HALF_WINDOW_S))


def _slopes(t: np.ndarray, T: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Per row, the least-squares slope of ``T`` on ``t`` over the rows within ``w`` (per row)."""
    lo = np.searchsorted(t, t - w, side="left")
    hi = np.searchsorted(t, t + w, side="right")
    tc = t - t.mean()  # centred: the sums below lose no digits to an epoch time origin
    c = lambda x: np.concatenate([[0.0], np.cumsum(x)])  # noqa: E731
    St, ST, Stt, StT = c(tc), c(T), c(tc * tc), c(tc * T)
    k = (hi - lo).astype(float)
    st, sT = St[hi] - St[lo], ST[hi] - ST[lo]
    den = k * (Stt[hi] - Stt[lo]) - st * st
    num = k * (StT[hi] - StT[lo]) - st * sT
    ok = den > 1e-12 * np.maximum(k * k * w * w, 1e-300)
    return np.where(ok, num / np.where(ok, den, 1.0), 0.0)


def random_signs(rng: np.random.Generator, shape) -> np.ndarray:
    """±1 with a random magnitude in [0.5, 1]: an effect's pattern for a given size."""
    return rng.choice([-1.0, 1.0], size=shape) * rng.uniform(0.5, 1.0, size=shape)
