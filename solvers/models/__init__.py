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

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Conditions:
    """Per-sample conditions (arrays of length N where given).

    t_s: time from the capture's start [s]; temp_c: sensor temperature [°C];
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
    """The bias-like terms every sensor shares: ``b_T (T − T_ref) + b_t (t − t_ref)``, (N, k).

    ``temperature_bias`` (block ``bT``) needs ``cond.temp_c``; ``time_drift`` (``bt``)
    needs ``cond.t_s``. A block present without its condition is an error, not a zero.
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
        out += np.outer(np.asarray(cond.temp_c, dtype=float) - cond.temp_ref_c, params["bT"])
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


def random_signs(rng: np.random.Generator, shape) -> np.ndarray:
    """±1 with a random magnitude in [0.5, 1]: an effect's pattern for a given size."""
    return rng.choice([-1.0, 1.0], size=shape) * rng.uniform(0.5, 1.0, size=shape)
