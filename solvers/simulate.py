"""The simulator: realistic captures of the five procedures, made with the forward models.

``simulate(procedure, seed=..., effects={name: size}, **options) -> Simulation`` returns
capture metadata and columns (exactly what a capture file holds) and the truth. Every raw
value comes from ``solvers.models.*.forward``: the physics lives there, not here. What
lives here is the bench: positions and moves, the operator's placement error, a table that
is not quite level, white noise and bias instability, a temperature profile.

``LiveImu`` is the same bench run sample by sample for the simulated serial device.

Effect sizes are in the units each model's ``effect_blocks`` documents.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from solvers import frames
from solvers.frames import matrix_to_rotvec, rotvec_to_matrix
from solvers.geomag import field_ned, igrf_reference
from solvers.jsonable import jsonable
from solvers.models import Conditions
from solvers.models import accel as accel_model
from solvers.models import gyro as gyro_model
from solvers.models import ldv as ldv_model
from solvers.models import mag as mag_model
from solvers.positions import P1_POSITIONS, C_n_b_for

PROCEDURES = ("accel-tabletop", "accel-centrifuge", "compass", "gyro-drift", "ldv")

EFFECTS_BY_PROCEDURE = {
    "accel-tabletop": ("temperature_bias", "time_drift", "quadratic", "scale_asymmetry"),
    "accel-centrifuge": ("temperature_bias", "time_drift", "misalignment", "cubic", "lever_arm"),
    "compass": ("temperature_bias", "time_drift", "mag_accel_misalignment", "field_anomaly", "time_varying_hard_iron"),
    "gyro-drift": ("temperature_bias", "time_drift", "g_sensitivity", "earth_rate"),
    "ldv": ("temperature_bias", "time_drift", "time_delay", "lever_arm", "offset"),
}

# A bench in Beijing by default (the P1 source's example place); any place works.
DEFAULT_SITE = {"latitude_deg": 39.98, "longitude_deg": 116.35, "altitude_m": 52.0, "date": "2026-11-21"}


@dataclass
class Simulation:
    """A simulated capture: ``meta`` and ``columns`` as in a capture file, and the truth."""

    procedure: str
    meta: dict[str, str]
    columns: dict[str, np.ndarray]
    truth: dict = field(default_factory=dict)


class SimulationError(ValueError):
    """Options the simulator cannot honour (an unknown effect for the procedure, ...)."""


def _check_effects(procedure: str, effects: dict[str, float] | None) -> dict[str, float]:
    effects = dict(effects or {})
    allowed = EFFECTS_BY_PROCEDURE[procedure]
    for name in effects:
        if name not in allowed:
            raise SimulationError(f"effect {name!r} does not apply to {procedure}; choose from {', '.join(allowed)}")
    return effects


def _fmt(x: float) -> str:
    return repr(float(x))


# ---------------------------------------------------------------- bench building blocks


def smoothstep(s: np.ndarray) -> np.ndarray:
    """0 → 1 with zero rate at both ends (a hand's move)."""
    return 0.5 - 0.5 * np.cos(np.pi * np.clip(s, 0.0, 1.0))


def move_attitudes(C0: np.ndarray, C1: np.ndarray, n: int, duration_s: float):
    """Attitudes (body → nav) and body rates along a smooth move from C0 to C1."""
    theta_b = matrix_to_rotvec(C0.T @ C1)  # rotation expressed in the body frame at C0
    s = np.arange(n) / max(n, 1)
    sv = smoothstep(s)
    dsv = 0.5 * np.pi * np.sin(np.pi * s) / duration_s
    Cs = np.stack([C0 @ rotvec_to_matrix(k * theta_b) for k in sv])
    omega_b = dsv[:, None] * theta_b[None, :]
    return Cs, omega_b


def gauss_markov(rng: np.random.Generator, n: int, dt: float, sigma: float, tau_s: float, dim: int = 3) -> np.ndarray:
    """First-order Gauss-Markov bias instability (steady-state σ, correlation time τ)."""
    if sigma <= 0 or n == 0:
        return np.zeros((n, dim))
    from scipy.signal import lfilter  # only when needed: slow to import

    a = math.exp(-dt / tau_s)
    q = sigma * math.sqrt(1.0 - a * a)
    w = rng.normal(size=(n, dim)) * q
    w[0] = rng.normal(size=dim) * sigma
    return lfilter([1.0], [1.0, -a], w, axis=0)


def warmup_temperature(
    t_s: np.ndarray, start_c: float, rise_c: float, tau_s: float, rng: np.random.Generator
) -> np.ndarray:
    """A power-up warm-up: exponential rise plus a little sensor noise."""
    return start_c + rise_c * (1.0 - np.exp(-t_s / tau_s)) + rng.normal(scale=0.02, size=t_s.shape)


def placement_error(rng: np.random.Generator, max_deg: float) -> np.ndarray:
    """A random small rotation of up to ``max_deg`` (uniform angle, random axis)."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return rotvec_to_matrix(axis * math.radians(rng.uniform(0.0, max_deg)))


def _site_meta(site: dict) -> dict[str, str]:
    return {
        "latitude_deg": _fmt(site["latitude_deg"]),
        "longitude_deg": _fmt(site["longitude_deg"]),
        "altitude_m": _fmt(site["altitude_m"]),
        "date": str(site["date"]),
    }


def _positions_column(labels: list[str]) -> np.ndarray:
    return np.array(labels, dtype=object)


# ---------------------------------------------------------------- P1: level table

# The simulated analogue triad's datasheet values: what a nominal (uncalibrated) reading assumes.
NOMINAL_ACCEL_SCALE_V_PER_MPS2 = 0.0855
NOMINAL_ACCEL_ZERO_V = 1.65
NOMINAL_ACCEL_PARAMS = {"K": NOMINAL_ACCEL_SCALE_V_PER_MPS2 * np.eye(3), "b": np.full(3, NOMINAL_ACCEL_ZERO_V)}


def nominal_tabletop_device(rng: np.random.Generator) -> dict:
    """An analogue accelerometer triad read in volts: ~0.0855 V per m/s², ~1.65 V at zero."""
    scale = NOMINAL_ACCEL_SCALE_V_PER_MPS2 * (1.0 + rng.normal(scale=0.02, size=3))
    cross = rng.normal(scale=0.005, size=(3, 3))
    np.fill_diagonal(cross, 0.0)
    K = np.diag(scale) @ (np.eye(3) + cross)
    b = NOMINAL_ACCEL_ZERO_V + rng.normal(scale=0.03, size=3)
    return {"K": K, "b": b}


def simulate_tabletop(
    seed: int = 0,
    effects: dict[str, float] | None = None,
    *,
    rate_hz: float = 100.0,
    hold_s: float = 20.0,
    move_s: float = 4.0,
    init_rest_s: float | None = None,
    positions: list[str] | None = None,
    extra_positions: int = 0,
    placement_deg: float = 0.5,
    tilted_placement_deg: float = 3.0,
    table_tilt_deg: float = 0.3,
    noise_mps2: float = 0.01,
    bias_instability_mps2: float = 2e-4,
    averages: bool = False,
    label_positions: bool = True,
    site: dict | None = None,
    gyro_scale_sigma: float = 0.0,
    gyro_misalignment_sigma_rad: float = 0.0,
    gyro_g_sensitivity: float = 0.0,
    gyro_noise_rad_s: float = 0.003,
) -> Simulation:
    """P1 on a level table: 12 source positions (or ``positions``), plus random extra ones.

    The gyro (rad/s) sees the moves and the Earth rate through ``y = K ω + ε + G f``: ``K`` =
    I unless ``gyro_scale_sigma`` (relative) or ``gyro_misalignment_sigma_rad`` draw one, ``G``
    (rad/s per m/s², each element ± ``gyro_g_sensitivity``) only when that is non-zero; these
    draws use their own random stream, so the rest of a seed's capture is unchanged."""
    effects = _check_effects("accel-tabletop", effects)
    rng = np.random.default_rng(seed)
    site = dict(DEFAULT_SITE, **(site or {}))
    g = frames.normal_gravity_mps2(site["latitude_deg"], site["altitude_m"])
    params = nominal_tabletop_device(rng)
    names = list(positions or P1_POSITIONS)
    dirs = [P1_POSITIONS[n] for n in names]
    for k in range(extra_positions):
        v = rng.normal(size=3)
        names.append(f"extra_{k + 1}")
        dirs.append(v / np.linalg.norm(v))
    # Table tilt: one small rotation of the whole table; placement error per position.
    tilt = placement_error(rng, 0.0)
    tilt_axis = rng.normal(size=3) * np.array([1.0, 1.0, 0.0])
    tilt = rotvec_to_matrix(tilt_axis / np.linalg.norm(tilt_axis) * math.radians(table_tilt_deg))
    attitudes, placement = [], []
    for name, d in zip(names, dirs):
        tilted = name[:2] in {"xy", "yz", "xz"} or name.startswith("extra")
        P = placement_error(rng, tilted_placement_deg if tilted else placement_deg)
        C = tilt @ C_n_b_for(d, rng.uniform(0, 2 * math.pi)) @ P
        attitudes.append(C)
        placement.append(math.degrees(np.linalg.norm(matrix_to_rotvec(P))))
    dt = 1.0 / rate_hz
    rest_s = hold_s if init_rest_s is None else init_rest_s
    segs_C, segs_w, segs_label = [], [], []
    n_hold = int(round(hold_s * rate_hz))
    n_move = int(round(move_s * rate_hz))
    for i, (name, C) in enumerate(zip(names, attitudes)):
        if i == 0:
            n0 = int(round(max(rest_s, hold_s) * rate_hz))
            segs_C.append(np.repeat(C[None], n0, axis=0))
            segs_w.append(np.zeros((n0, 3)))
            segs_label += [name] * n0
            continue
        Cs, w = move_attitudes(attitudes[i - 1], C, n_move, move_s)
        segs_C.append(Cs)
        segs_w.append(w)
        segs_label += [""] * n_move
        segs_C.append(np.repeat(C[None], n_hold, axis=0))
        segs_w.append(np.zeros((n_hold, 3)))
        segs_label += [name] * n_hold
    C_all = np.concatenate(segs_C)
    w_all = np.concatenate(segs_w)
    n = len(C_all)
    t = np.arange(n) * dt
    temp = warmup_temperature(t, 24.0, 3.0, 600.0, rng)
    f_true = np.einsum("nij,j->ni", np.transpose(C_all, (0, 2, 1)), np.array([0.0, 0.0, -g]))
    for name, size in effects.items():
        params.update(accel_model.effect_blocks(name, size, rng, params))
    cond = Conditions(t_s=t, temp_c=temp, temp_ref_c=25.0)
    y = accel_model.forward(f_true, params, cond)
    K = accel_model.K_matrix(params)
    noise_in = rng.normal(scale=noise_mps2, size=(n, 3)) + gauss_markov(rng, n, dt, bias_instability_mps2, 100.0)
    y = y + noise_in @ K.T
    # Gyro (rad/s): Earth rate + moves + a MEMS bias and noise.
    lat = site["latitude_deg"]
    w_earth = np.einsum("nji,j->ni", C_all, frames.earth_rate_ned(lat))
    gyro_bias = rng.normal(scale=0.01, size=3)
    grng = np.random.default_rng([seed, 14])
    gparams = {"eps": gyro_bias}
    if gyro_scale_sigma or gyro_misalignment_sigma_rad:
        cross = grng.normal(scale=gyro_misalignment_sigma_rad, size=(3, 3))
        np.fill_diagonal(cross, 0.0)
        gparams["K"] = np.diag(1.0 + grng.normal(scale=gyro_scale_sigma, size=3)) + cross
    gcond = None
    if gyro_g_sensitivity:
        gparams["G"] = gyro_g_sensitivity * grng.uniform(-1.0, 1.0, size=(3, 3))
        gcond = Conditions(f_mps2=f_true)
    gyro = gyro_model.forward(w_all + w_earth, gparams, gcond) + rng.normal(scale=gyro_noise_rad_s, size=(n, 3))
    B, M = accel_model.forward_to_p1({"K": K, "b": params["b"]})
    truth = {
        "procedure": "accel-tabletop",
        "seed": seed,
        "g_mps2": g,
        "B": B,
        "M": M,
        "K": K,
        "b": params["b"],
        "effects": {k: float(v) for k, v in effects.items()},
        "effect_blocks": {k: v for k, v in params.items() if k not in ("K", "b")},
        "positions": names,
        "placement_error_deg": placement,
        "table_tilt_deg": table_tilt_deg,
        "noise_mps2": noise_mps2,
        "gyro_bias_rad_s": gyro_bias,
        "gyro": {"K": gparams.get("K", np.eye(3)), "eps": gyro_bias, "G": gparams.get("G", np.zeros((3, 3)))},
    }
    meta = {
        "station-capture": "1",
        "procedure": "accel-tabletop",
        "device": f"SIM-ACC-{seed:04d}",
        "accel_unit": "V",
        "gyro_unit": "rad/s",
        **_site_meta(site),
        "sample_rate_hz": _fmt(rate_hz),
        "simulated": "yes",
    }
    y = np.round(y, 6)
    labels = np.array(segs_label, dtype=object)
    if averages:
        cols = _averages(labels, {"ax": y[:, 0], "ay": y[:, 1], "az": y[:, 2], "temp_c": temp})
        return Simulation("accel-tabletop", meta, cols, jsonable(truth))
    cols = {"t": np.round(t, 6)}
    if label_positions:
        cols["position"] = labels
    cols.update(
        {
            "ax": y[:, 0],
            "ay": y[:, 1],
            "az": y[:, 2],
            "gx": np.round(gyro[:, 0], 7),
            "gy": np.round(gyro[:, 1], 7),
            "gz": np.round(gyro[:, 2], 7),
            "temp_c": np.round(temp, 3),
        }
    )
    return Simulation("accel-tabletop", meta, cols, jsonable(truth))


def _averages(labels: np.ndarray, cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """One row per labelled position: means, ``<col>_std`` and ``n``."""
    order = [p for i, p in enumerate(labels) if p and (i == 0 or labels[i - 1] != p)]
    out: dict[str, list] = {"position": [], "n": []}
    for name in cols:
        out[name] = []
        out[name + "_std"] = []
    for p in order:
        sel = labels == p
        out["position"].append(p)
        out["n"].append(float(sel.sum()))
        for name, v in cols.items():
            out[name].append(float(np.mean(v[sel])))
            out[name + "_std"].append(float(np.std(v[sel], ddof=1)))
    res = {k: np.array(v, dtype=object if k == "position" else float) for k, v in out.items()}
    return {k: (np.round(v, 9) if k != "position" else v) for k, v in res.items()}


# ---------------------------------------------------------------- P2: centrifuge

GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


def fibonacci_directions(n: int) -> np.ndarray:
    """``n`` unit vectors spread evenly over the sphere (a Fibonacci lattice), (n, 3)."""
    k = np.arange(n)
    z = 1.0 - 2.0 * (k + 0.5) / n
    r = np.sqrt(1.0 - z * z)
    return np.column_stack([r * np.cos(GOLDEN_ANGLE * k), r * np.sin(GOLDEN_ANGLE * k), z])


def centrifuge_orientations(n: int = 20) -> list[np.ndarray]:
    """``n`` mounting attitudes (body → table frame: radial-out, tangential, up), spread
    over the sphere (Fibonacci directions for the body x axis, rolls stepped by 137.5°)."""
    return [
        frames.rotation_between([1.0, 0.0, 0.0], d) @ frames.rot_x(GOLDEN_ANGLE * k * 1.7)
        for k, d in enumerate(fibonacci_directions(n))
    ]


def simulate_centrifuge(
    seed: int = 0,
    effects: dict[str, float] | None = None,
    *,
    speeds_rad_s=(2 * math.pi, 4 * math.pi, 6 * math.pi),
    radius_m: float = 1.0,
    g_mps2: float = 9.8,
    n_orientations: int = 20,
    noise_g: float = 1e-5,
    truth_params: dict | None = None,
    latitude_deg: float = 39.0,
) -> Simulation:
    """P2 as a table of averages (like Wang & Li 2021 Table 1), outputs in g.

    The table frame is (radial outward, tangential, up); the specific force at the centre
    of the triad is ``f = (−ω²R/g, 0, 1)`` in g (centripetal inward plus the reaction to
    gravity; ``solvers.models.accel.centrifuge_specific_force_g``), so ``|f|² = A² + 1`` with
    ``A = ω²R/g``.
    """
    effects = _check_effects("accel-centrifuge", effects)
    rng = np.random.default_rng(seed)
    if truth_params is None:
        params = {
            "S": np.array([1.29, 1.21, 1.26]) * (1 + rng.normal(scale=0.01, size=3)),
            "b": np.array([0.213, 0.256, 0.516]) * (1 + rng.normal(scale=0.05, size=3)),
            "D": np.array([0.57, 0.31, 0.45]) * 1e-4 * (1 + rng.normal(scale=0.05, size=3)),
        }
    else:
        params = {k: np.asarray(v, dtype=float) for k, v in truth_params.items()}
    for name, size in effects.items():
        params.update(accel_model.effect_blocks(name, size, rng, params))
    orients = centrifuge_orientations(n_orientations)
    rows_f, rows_c, rows_w, pos, spd = [], [], [], [], []
    for w in speeds_rad_s:
        f_t = accel_model.centrifuge_specific_force_g(w, radius_m, g_mps2)
        for k, C_t_b in enumerate(orients):
            rows_f.append(C_t_b.T @ f_t)
            rows_c.append(C_t_b.T @ np.array([-1.0, 0.0, 0.0]))
            rows_w.append(w)
            pos.append(str(k + 1))
            spd.append(w)
    f = np.array(rows_f)
    m = len(f)
    elapsed = np.arange(m) * 120.0  # two minutes a row
    temp = 25.0 + 0.5 * np.array(spd) / (2 * math.pi) + rng.normal(scale=0.05, size=m)
    cond = Conditions(
        t_s=elapsed,
        temp_c=temp,
        temp_ref_c=25.0,
        input_unit_mps2=g_mps2,
        omega_rad_s=np.array(rows_w),
        centripetal_dir=np.array(rows_c),
    )
    y = accel_model.forward(f, params, cond) + rng.normal(scale=noise_g, size=(m, 3))
    truth = {
        "procedure": "accel-centrifuge",
        "seed": seed,
        **{k: v for k, v in params.items()},
        "effects": {k: float(v) for k, v in effects.items()},
        "f_g": f,
        "radius_m": radius_m,
        "g_mps2": g_mps2,
        "noise_g": noise_g,
    }
    meta = {
        "station-capture": "1",
        "procedure": "accel-centrifuge",
        "device": f"SIM-CFG-{seed:04d}",
        "accel_unit": "g",
        "radius_m": _fmt(radius_m),
        "g_mps2": _fmt(g_mps2),
        "latitude_deg": _fmt(latitude_deg),
        "simulated": "yes",
    }
    cols = {
        "position": np.array(pos, dtype=object),
        "speed_rad_s": np.array(spd),
        "ax": np.round(y[:, 0], 9),
        "ay": np.round(y[:, 1], 9),
        "az": np.round(y[:, 2], 9),
        "temp_c": np.round(temp, 3),
        "elapsed_s": elapsed,
    }
    return Simulation("accel-centrifuge", meta, cols, jsonable(truth))


# ---------------------------------------------------------------- P3: compass


def sphere_attitudes(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """``n`` hand-held attitudes spread over the sphere (body → NED)."""
    return [C_n_b_for(d, rng.uniform(0, 2 * math.pi)) @ placement_error(rng, 10.0) for d in fibonacci_directions(n)]


def simulate_compass(
    seed: int = 0,
    effects: dict[str, float] | None = None,
    *,
    rate_hz: float = 50.0,
    n_orientations: int = 24,
    hold_s: float = 2.0,
    move_s: float = 2.5,
    mag_noise_uT: float = 0.15,
    accel_noise_mps2: float = 0.02,
    hand_accel_mps2: float = 0.3,
    site: dict | None = None,
) -> Simulation:
    """P3: a compass module turned by hand through the sphere; accel g, gyro deg/s, mag uT."""
    effects = _check_effects("compass", effects)
    rng = np.random.default_rng(seed)
    site = dict(DEFAULT_SITE, **(site or {}))
    ref = igrf_reference(site["latitude_deg"], site["longitude_deg"], site["altitude_m"], site["date"])
    m_ned = field_ned(ref)
    g = frames.normal_gravity_mps2(site["latitude_deg"], site["altitude_m"])
    atts = sphere_attitudes(rng, n_orientations)
    dt = 1.0 / rate_hz
    n_hold, n_move = int(hold_s * rate_hz), int(move_s * rate_hz)
    Cs, ws = [np.repeat(atts[0][None], n_hold, axis=0)], [np.zeros((n_hold, 3))]
    for a, b in zip(atts[:-1], atts[1:]):
        C, w = move_attitudes(a, b, n_move, move_s)
        Cs += [C, np.repeat(b[None], n_hold, axis=0)]
        ws += [w, np.zeros((n_hold, 3))]
    C_all, w_all = np.concatenate(Cs), np.concatenate(ws)
    n = len(C_all)
    t = np.arange(n) * dt
    moving = np.linalg.norm(w_all, axis=1) > 1e-9
    lin = gauss_markov(rng, n, dt, hand_accel_mps2, 0.3) * moving[:, None]
    C_b_n = np.transpose(C_all, (0, 2, 1))
    f_b = np.einsum("nij,j->ni", C_b_n, np.array([0.0, 0.0, -g])) + np.einsum("nij,nj->ni", C_b_n, lin)
    m_b = np.einsum("nij,j->ni", C_b_n, m_ned)
    W_true = 1000.0 * (np.eye(3) + np.triu(rng.normal(scale=0.04, size=(3, 3))))  # uT → nT
    params = {"W": W_true, "h": rng.normal(scale=8.0, size=3)}  # hard iron in uT
    temp = warmup_temperature(t, 23.0, 2.0, 300.0, rng)
    for name, size in effects.items():
        params.update(mag_model.effect_blocks(name, size, rng, params, duration_s=float(t[-1])))
    cond = Conditions(t_s=t, temp_c=temp, temp_ref_c=25.0)
    mag = mag_model.forward(m_b, params, cond) + rng.normal(scale=mag_noise_uT, size=(n, 3))
    acc = accel_model.forward(f_b / frames.G_STANDARD_MPS2, {"K": np.eye(3), "b": np.zeros(3)}) + rng.normal(
        scale=accel_noise_mps2 / frames.G_STANDARD_MPS2, size=(n, 3)
    )
    gyro_bias = rng.normal(scale=0.005, size=3)
    gyr = gyro_model.forward(w_all, {"eps": gyro_bias}) + rng.normal(scale=0.002, size=(n, 3))
    truth = {
        "procedure": "compass",
        "seed": seed,
        "soft_iron": params["W"],
        "hard_iron": params["h"],
        "reference": ref,
        "effects": {k: float(v) for k, v in effects.items()},
        "effect_blocks": {k: v for k, v in params.items() if k not in ("W", "h")},
        "heading_deg": [math.degrees(frames.C_n_b_to_euler(C)[2]) for C in atts],
        "mag_noise_uT": mag_noise_uT,
    }
    meta = {
        "station-capture": "1",
        "procedure": "compass",
        "device": f"SIM-MAG-{seed:04d}",
        "accel_unit": "g",
        "gyro_unit": "deg/s",
        "mag_unit": "uT",
        **_site_meta(site),
        "sample_rate_hz": _fmt(rate_hz),
        "simulated": "yes",
    }
    cols = {
        "t": np.round(t, 6),
        "ax": np.round(acc[:, 0], 6),
        "ay": np.round(acc[:, 1], 6),
        "az": np.round(acc[:, 2], 6),
        "gx": np.round(np.degrees(gyr[:, 0]), 5),
        "gy": np.round(np.degrees(gyr[:, 1]), 5),
        "gz": np.round(np.degrees(gyr[:, 2]), 5),
        "mx": np.round(mag[:, 0], 4),
        "my": np.round(mag[:, 1], 4),
        "mz": np.round(mag[:, 2], 4),
        "temp_c": np.round(temp, 3),
    }
    return Simulation("compass", meta, cols, jsonable(truth))


# ---------------------------------------------------------------- P4: gyro drift


def simulate_gyro_drift(
    seed: int = 0,
    effects: dict[str, float] | None = None,
    *,
    mode: str = "static",
    rate_hz: float = 100.0,
    duration_s: float = 180.0,
    headings_deg=None,
    pitch_deg: float | None = None,
    roll_deg: float | None = None,
    gyro_noise_rad_s: float = 0.002,
    bias_instability_rad_s: float = 2e-5,
    heading_error_deg: float = 3.0,
    site: dict | None = None,
) -> Simulation:
    """P4: mode ``static`` (B, static base, Earth rate seen) or ``reference`` (A, a
    reference IMU ten times better rigidly mounted, both moving). Body axes x forward,
    y up, z right; navigation north-up-east (source 003). ``headings_deg`` with several
    values makes a multi-position capture (per-row ``heading_deg``)."""
    effects = _check_effects("gyro-drift", effects)
    if mode not in ("static", "reference"):
        raise SimulationError(f"gyro-drift mode must be 'static' or 'reference', not {mode!r}")
    rng = np.random.default_rng(seed)
    site = dict(DEFAULT_SITE, **(site or {}))
    lat = site["latitude_deg"]
    g = frames.normal_gravity_mps2(lat, site["altitude_m"])
    dt = 1.0 / rate_hz
    headings = list(headings_deg) if headings_deg is not None else [0.0]
    if "g_sensitivity" in effects and len(headings) == 1 and pitch_deg is None:
        headings = [0.0, 90.0, 180.0, 270.0]
    n_per = int(round(duration_s * rate_hz / len(headings)))
    eps = np.radians(rng.normal(scale=0.3, size=3))  # MEMS power-up bias, ~0.3 °/s
    params = {"eps": eps}
    for name, size in effects.items():
        params.update(gyro_model.effect_blocks(name, size, rng, params))
    C_list, hdg_col, tilt = [], [], []
    for k, h in enumerate(headings):
        p = math.radians(
            pitch_deg
            if pitch_deg is not None
            else rng.normal(scale=1.0) + (20.0 * (k % 2) if len(headings) > 1 else 0.0)
        )
        r = math.radians(
            roll_deg
            if roll_deg is not None
            else rng.normal(scale=1.0) + (15.0 * ((k // 2) % 2) if len(headings) > 1 else 0.0)
        )
        true_h = math.radians(h + rng.normal(scale=heading_error_deg))
        C = frames.p4_C_n_b(p, r, true_h)
        C_list.append(np.repeat(C[None], n_per, axis=0))
        hdg_col += [h] * n_per
        tilt.append({"pitch_deg": math.degrees(p), "roll_deg": math.degrees(r), "heading_deg": math.degrees(true_h)})
    C_all = np.concatenate(C_list)
    n = len(C_all)
    t = np.arange(n) * dt
    C_b_n = np.transpose(C_all, (0, 2, 1))
    w_earth = C_b_n @ frames.earth_rate_nue(lat)
    f_b = C_b_n @ np.array([0.0, g, 0.0])
    w_motion = np.zeros((n, 3))
    if mode == "reference":
        # a slow turntable-like oscillation both units see
        w_motion = np.column_stack(
            [0.05 * np.sin(2 * np.pi * t / 7.0), 0.2 * np.sin(2 * np.pi * t / 11.0), 0.03 * np.sin(2 * np.pi * t / 5.0)]
        )
    temp = warmup_temperature(t, 25.0, 6.0, 240.0, rng)
    cond = Conditions(t_s=t, temp_c=temp, temp_ref_c=25.0, f_mps2=f_b)
    w_true = w_earth + w_motion
    gyr = (
        gyro_model.forward(w_true, params, cond)
        + rng.normal(scale=gyro_noise_rad_s, size=(n, 3))
        + gauss_markov(rng, n, dt, bias_instability_rad_s, 60.0)
    )
    acc = f_b + rng.normal(scale=0.01, size=(n, 3))
    truth = {
        "procedure": "gyro-drift",
        "seed": seed,
        "mode": mode,
        "drift": eps,
        "earth_rate_body_mean": w_earth.mean(axis=0),
        "attitudes": tilt,
        "effects": {k: float(v) for k, v in effects.items()},
        "effect_blocks": {k: v for k, v in params.items() if k != "eps"},
        "gyro_noise_rad_s": gyro_noise_rad_s,
        "latitude_deg": lat,
    }
    meta = {
        "station-capture": "1",
        "procedure": "gyro-drift",
        "device": f"SIM-GYR-{seed:04d}",
        "accel_unit": "m/s^2",
        "gyro_unit": "rad/s",
        **_site_meta(site),
        "sample_rate_hz": _fmt(rate_hz),
        "gyro_mode": mode,
        "frame": "body x forward, y up, z right",
        "simulated": "yes",
    }
    if len(headings) == 1:
        meta["heading_deg"] = _fmt(headings[0])
    cols = {
        "t": np.round(t, 6),
        "ax": np.round(acc[:, 0], 5),
        "ay": np.round(acc[:, 1], 5),
        "az": np.round(acc[:, 2], 5),
        "gx": np.round(gyr[:, 0], 8),
        "gy": np.round(gyr[:, 1], 8),
        "gz": np.round(gyr[:, 2], 8),
        "temp_c": np.round(temp, 3),
    }
    if len(headings) > 1:
        cols["heading_deg"] = np.array(hdg_col, dtype=float)
        cols["position"] = np.array([str(headings.index(h) + 1) for h in hdg_col], dtype=object)
    if mode == "reference":
        ref = (
            w_true
            + np.radians(1.0 / 3600.0) * rng.normal(size=3)
            + rng.normal(scale=gyro_noise_rad_s / 10, size=(n, 3))
        )
        cols.update(
            {"ref_gx": np.round(ref[:, 0], 9), "ref_gy": np.round(ref[:, 1], 9), "ref_gz": np.round(ref[:, 2], 9)}
        )
    return Simulation("gyro-drift", meta, cols, jsonable(truth))


# ---------------------------------------------------------------- P5: LDV


def simulate_ldv(
    seed: int = 0,
    effects: dict[str, float] | None = None,
    *,
    rate_hz: float = 10.0,
    duration_s: float = 600.0,
    maneuver: str = "varied",
    reference: str = "body",
    beam_noise_mps: float = 0.01,
    ref_noise_mps: float = 0.005,
    site: dict | None = None,
    cruise_mps: float = 10.0,
) -> Simulation:
    """P5: a vehicle with INS/DGPS and a three-beam LDV; ``maneuver`` 'varied' (turns,
    hills, braking: body velocity directions spread) or 'straight' (the ill-conditioned
    case the source warns of); ``reference`` 'body' (vx vy vz) or 'nav' (vn ve vd + attitude);
    ``cruise_mps`` the mean forward speed (the drive varies it by ±8 m/s)."""
    effects = _check_effects("ldv", effects)
    rng = np.random.default_rng(seed)
    site = dict(DEFAULT_SITE, **(site or {}))
    n = int(round(duration_s * rate_hz))
    t = np.arange(n) / rate_hz
    ph = rng.uniform(0, 2 * np.pi, size=6)
    fwd = cruise_mps + 6.0 * np.sin(2 * np.pi * t / 97.0 + ph[0]) + 2.0 * np.sin(2 * np.pi * t / 23.0 + ph[1])
    if maneuver == "straight":
        lat_v = 0.01 * np.sin(2 * np.pi * t / 31.0 + ph[2])
        vert_v = 0.01 * np.sin(2 * np.pi * t / 41.0 + ph[3])
    else:
        lat_v = 2.0 * np.sin(2 * np.pi * t / 31.0 + ph[2]) + 0.8 * np.sin(2 * np.pi * t / 13.0 + ph[4])
        vert_v = 1.5 * np.sin(2 * np.pi * t / 41.0 + ph[3]) + 0.5 * np.sin(2 * np.pi * t / 17.0 + ph[5])
    v_b = np.column_stack([fwd, lat_v, vert_v])  # FRD body velocity
    w_b = np.column_stack(
        [
            0.05 * np.sin(2 * np.pi * t / 19.0),
            0.04 * np.sin(2 * np.pi * t / 29.0),
            0.15 * np.sin(2 * np.pi * t / 37.0 + ph[0]),
        ]
    )
    dK = rng.normal(scale=0.005, size=3)
    alpha = np.array([60.0, 60.0, 90.0]) + rng.normal(scale=0.5, size=3)
    beta = np.array([90.0, 90.0, 60.0]) + rng.normal(scale=0.5, size=3)
    az = np.array([1.0, 1.0, 1.0])
    # γ from α, β so the direction cosines form a unit vector (beams look down: cos γ > 0)
    cg = np.sqrt(np.clip(1 - np.cos(np.radians(alpha)) ** 2 - np.cos(np.radians(beta)) ** 2, 0, 1)) * az
    gamma = np.degrees(np.arccos(cg))
    alpha[1] = 180.0 - alpha[1]  # second beam looks backward
    params = {"X": ldv_model.X_from_angles(dK, alpha, beta, gamma)}
    for name, size in effects.items():
        params.update(ldv_model.effect_blocks(name, size, rng, params))
    temp = warmup_temperature(t, 15.0, 10.0, 900.0, rng)
    cond = Conditions(t_s=t, temp_c=temp, temp_ref_c=25.0, omega_body_rad_s=w_b)
    vl = ldv_model.forward(v_b, params, cond) + rng.normal(scale=beam_noise_mps, size=(n, 3))
    v_ref = v_b + rng.normal(scale=ref_noise_mps, size=(n, 3))
    truth = {
        "procedure": "ldv",
        "seed": seed,
        "X": params["X"],
        "dK": dK,
        "alpha_deg": alpha,
        "beta_deg": beta,
        "gamma_deg": gamma,
        "effects": {k: float(v) for k, v in effects.items()},
        "effect_blocks": {k: v for k, v in params.items() if k != "X"},
        "beam_noise_mps": beam_noise_mps,
        "ref_noise_mps": ref_noise_mps,
    }
    meta = {
        "station-capture": "1",
        "procedure": "ldv",
        "device": f"SIM-LDV-{seed:04d}",
        **_site_meta(site),
        "sample_rate_hz": _fmt(rate_hz),
        "frame": "body x forward, y right, z down",
        "simulated": "yes",
    }
    cols = {
        "t": np.round(t, 6),
        "vl1": np.round(vl[:, 0], 5),
        "vl2": np.round(vl[:, 1], 5),
        "vl3": np.round(vl[:, 2], 5),
    }
    if reference == "nav":
        yaw = np.cumsum(w_b[:, 2]) / rate_hz
        pitch = 0.02 * np.sin(2 * np.pi * t / 53.0)
        roll = 0.01 * np.sin(2 * np.pi * t / 61.0)
        C = np.stack([frames.euler_to_C_n_b(r, p, y) for r, p, y in zip(roll, pitch, yaw)])
        v_n = np.einsum("nij,nj->ni", C, v_ref)
        cols.update(
            {
                "vn": np.round(v_n[:, 0], 5),
                "ve": np.round(v_n[:, 1], 5),
                "vd": np.round(v_n[:, 2], 5),
                "roll_deg": np.round(np.degrees(roll), 6),
                "pitch_deg": np.round(np.degrees(pitch), 6),
                "yaw_deg": np.round(np.degrees(yaw), 6),
            }
        )
    else:
        cols.update({"vx": np.round(v_ref[:, 0], 5), "vy": np.round(v_ref[:, 1], 5), "vz": np.round(v_ref[:, 2], 5)})
    cols.update(
        {
            "wx": np.round(w_b[:, 0], 6),
            "wy": np.round(w_b[:, 1], 6),
            "wz": np.round(w_b[:, 2], 6),
            "temp_c": np.round(temp, 3),
        }
    )
    return Simulation("ldv", meta, cols, jsonable(truth))


# ---------------------------------------------------------------- entry point

_SIMULATORS = {
    "accel-tabletop": simulate_tabletop,
    "accel-centrifuge": simulate_centrifuge,
    "compass": simulate_compass,
    "gyro-drift": simulate_gyro_drift,
    "ldv": simulate_ldv,
}


def simulate(procedure: str, *, seed: int = 0, effects: dict[str, float] | None = None, **options) -> Simulation:
    """Simulate a capture of ``procedure``; see each ``simulate_*`` for its options."""
    if procedure not in _SIMULATORS:
        raise SimulationError(f"unknown procedure {procedure!r}; choose from {', '.join(PROCEDURES)}")
    return _SIMULATORS[procedure](seed=seed, effects=effects, **options)


# ---------------------------------------------------------------- live device

# How a hand sets the unit down: a move of MOVE_S, then it rocks on its face, a damped
# oscillation of WOBBLE_DEG (1.5° at the worst) at WOBBLE_HZ decaying with WOBBLE_TAU_S,
# over within WOBBLE_S. The stillness detector sees the rocking (gyro ~0.3 rad/s at first).
WOBBLE_HZ = 3.0
WOBBLE_TAU_S = 0.5
WOBBLE_DEG = (0.4, 1.5)
WOBBLE_S = 3.5
# Where a hand puts a unit asked to be in a position: within 1° of a flat face, within
# 3° on the 45° block (its edge is hand-held against the block); any heading.
PLACEMENT_FLAT_DEG = 1.0
PLACEMENT_TILTED_DEG = 3.0


def sweep_rate_rad_s(u_s: np.ndarray) -> np.ndarray:
    """A hand turning a compass module through every orientation: body rates [rad/s]
    at ``u_s`` seconds into the sweep, about 0.6 rad/s with an axis that keeps wandering
    (the field direction covers 80 % of the sphere in about a minute)."""
    u = np.asarray(u_s, float)[:, None]
    w = np.hstack([np.sin(0.31 * u + 0.4), np.cos(0.23 * u), 0.7 * np.sin(0.13 * u + 1.0) + 0.3])
    return 0.6 * w / np.linalg.norm(w, axis=1, keepdims=True)


def rate_table_rad_s(u_s: np.ndarray) -> np.ndarray:
    """A slow rate table carrying the unit and the reference IMU (P4 mode A): body rates
    [rad/s], mostly about the vertical (z), a little about the level axes."""
    u = np.asarray(u_s, float)[:, None]
    return np.hstack(
        [0.05 * np.sin(2 * np.pi * u / 7.0), 0.03 * np.sin(2 * np.pi * u / 5.0), 0.2 * np.sin(2 * np.pi * u / 11.0)]
    )


DRIVES = {"sweep": sweep_rate_rad_s, "table": rate_table_rad_s}


class LiveImu:
    """The simulated bench device, sample by sample: an IMU with accel (V), gyro (rad/s),
    mag (uT) and temperature that an operator (or the scripted operator) turns between
    positions. Raw outputs come from the same forward models as :func:`simulate`.

    ``set_orientation(name)`` is the operator's hand: a P1 position (``x_up`` ...), a
    sphere attitude (``s1``..``s12``) or ``level``; the unit ends within a realistic
    placement error of the asked attitude (a fresh one each time, any heading) and rocks
    before it settles. ``sweep`` turns it continuously through every orientation (P3),
    ``table`` runs the rate table (P4 mode A), ``still`` stops either where it is.
    ``reference=True`` adds a navigation-grade reference IMU rigidly mounted with it
    (``ref_gx..ref_gz`` rad/s, same axes; drift ~1 °/h, noise a tenth of the unit's)."""

    MOVE_S = 2.5

    def __init__(
        self,
        *,
        procedure: str = "accel-tabletop",
        seed: int = 0,
        rate_hz: float = 100.0,
        effects: dict[str, float] | None = None,
        hold_s: float = 8.0,
        site: dict | None = None,
        reference: bool = False,
    ):
        if procedure not in PROCEDURES:
            raise SimulationError(f"unknown procedure {procedure!r}")
        effects = _check_effects(procedure, effects)
        self.procedure = procedure
        self.rng = np.random.default_rng(seed)
        self.rate_hz = float(rate_hz)
        self.hold_s = float(hold_s)
        self.site = dict(DEFAULT_SITE, **(site or {}))
        self.g = frames.normal_gravity_mps2(self.site["latitude_deg"], self.site["altitude_m"])
        ref = igrf_reference(
            self.site["latitude_deg"], self.site["longitude_deg"], self.site["altitude_m"], self.site["date"]
        )
        self.m_ned = field_ned(ref)
        self.accel = nominal_tabletop_device(self.rng)
        self.mag = {
            "W": 1000.0 * (np.eye(3) + np.triu(self.rng.normal(scale=0.04, size=(3, 3)))),
            "h": self.rng.normal(scale=8.0, size=3),
        }
        self.gyro = {"eps": self.rng.normal(scale=0.01, size=3)}
        for name, size in effects.items():
            if name in accel_model.EFFECTS and procedure.startswith("accel"):
                self.accel.update(accel_model.effect_blocks(name, size, self.rng, self.accel))
            elif name in mag_model.EFFECTS and procedure == "compass":
                self.mag.update(mag_model.effect_blocks(name, size, self.rng, self.mag, duration_s=300.0))
            elif name in gyro_model.EFFECTS:
                self.gyro.update(gyro_model.effect_blocks(name, size, self.rng, self.gyro))
        self.reference = bool(reference)
        self.units = {"accel_unit": "V", "gyro_unit": "rad/s", "mag_unit": "uT"}
        self.device_id = f"SIM-{procedure.upper()[:3]}-{seed:04d}"
        self.positions = (
            list(P1_POSITIONS)
            if procedure.startswith("accel")
            else [f"s{k + 1}" for k in range(12)]
            if procedure == "compass"
            else ["level"]
        )
        self._bases = {name: (P1_POSITIONS[name], name[:2] in ("xy", "yz", "xz")) for name in P1_POSITIONS}
        self._bases["level"] = (np.array([0.0, 0.0, 1.0]), False)
        # _targets: where the unit is (or was last put) for each name
        self._targets = {
            name: C_n_b_for(P1_POSITIONS[name], 0.3) @ placement_error(self.rng, 1.0) for name in P1_POSITIONS
        }
        for k, C in enumerate(sphere_attitudes(self.rng, 12)):
            self._targets[f"s{k + 1}"] = C
        # level: x forward pointing north, y left (west), z up (the P4 screen's instruction)
        self._targets["level"] = C_n_b_for([0.0, 0.0, 1.0], math.pi)
        self.C = self._targets[self.positions[0]]
        # the reference IMU's own drift: ~1 °/h per axis (a fibre-optic unit)
        self.ref_bias = np.radians(1.0 / 3600.0) * self.rng.normal(size=3)
        # a move: (C0, C1, t0, T, wobble rotvec [rad]); kept until its rocking has died out
        self._move: tuple[np.ndarray, np.ndarray, float, float, np.ndarray] | None = None
        self._drive: tuple[str, float] | None = None  # (kind, start time)
        self.temp_c = 24.0
        self._temp_target = 24.0
        self.t_s = 0.0
        self.auto = False
        self._auto_index = 0
        self._auto_next_s = self.hold_s

    @property
    def truth(self) -> dict:
        B, M = accel_model.forward_to_p1(self.accel)
        return jsonable(
            {
                "accel": {"B": B, "M": M, **self.accel},
                "mag": self.mag,
                "gyro": self.gyro,
                "ref_bias_rad_s": self.ref_bias,
            }
        )

    @property
    def channels(self) -> tuple[str, ...]:
        """Outputs beyond the IMU's (capture column names): the reference IMU's gyro."""
        return ("ref_gx", "ref_gy", "ref_gz") if self.reference else ()

    @property
    def driving(self) -> str | None:
        """'sweep' or 'table' while a continuous motion runs, else None."""
        return self._drive[0] if self._drive else None

    def _wobble(self) -> np.ndarray:
        axis = self.rng.normal(size=3)
        return axis / np.linalg.norm(axis) * math.radians(self.rng.uniform(*WOBBLE_DEG))

    def set_orientation(self, name: str) -> None:
        """The operator's hand (class docstring)."""
        if name in DRIVES:
            self._settle_now()
            self._drive = (name, self.t_s)
            return
        if name == "still":
            if self._drive is not None:
                self._settle_now()
                self._move = (self.C, self.C, self.t_s, 0.0, self._wobble())
            return
        if name not in self._targets:
            shown = name if len(name) <= 24 else name[:21] + "..."
            raise SimulationError(f"unknown position {shown!r}; known: {self._known_positions()}")
        self._settle_now()
        if name in self._bases:  # a fresh placement each time: any heading, a small error
            d, tilted = self._bases[name]
            heading = self.rng.uniform(0.0, 2 * math.pi) if name != "level" else math.pi  # x north
            err = PLACEMENT_TILTED_DEG if tilted else PLACEMENT_FLAT_DEG
            self._targets[name] = C_n_b_for(d, heading) @ placement_error(self.rng, err)
        self._move = (self.C, self._targets[name], self.t_s, self.MOVE_S, self._wobble())

    def _known_positions(self) -> str:
        """The names set_orientation takes, this procedure's own first (an answer fits one sentence)."""
        own = "s1..s12" if self.positions[0] == "s1" else " ".join(self.positions)
        others = [
            n for n in ("x_up..xz_135", "s1..s12", "level") if n != own and n.split("..")[0] not in self.positions
        ]
        return f"{own}; also {' '.join(others)} {' '.join(DRIVES)} still"

    def _settle_now(self) -> None:
        """Freeze the attitude where it is now (ends a drive or a move half-way)."""
        C, _ = self._attitude(np.array([self.t_s]), commit=False)
        self.C = C[0]
        self._drive = None
        self._move = None

    def set_temperature(self, temp_c: float) -> None:
        self._temp_target = float(temp_c)

    def set_auto(self, on: bool) -> None:
        self.auto = bool(on)
        self._auto_index = 0
        self._auto_next_s = self.t_s + self.hold_s

    def _attitude(self, t: np.ndarray, commit: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Attitudes (body → NED) and body rates [rad/s] at the times ``t`` (ascending,
        after ``self.t_s``); ``commit`` advances a drive's integrated attitude."""
        n = len(t)
        if self._drive is not None:
            kind, t0 = self._drive
            w = DRIVES[kind](t - t0)
            dt = np.diff(np.concatenate([[self.t_s], t]))
            Cs = np.empty((n, 3, 3))
            C = self.C
            for k in range(n):
                C = C @ rotvec_to_matrix(w[k] * dt[k])
                Cs[k] = C
            if commit and n:
                self.C = C
            return Cs, w
        if self._move is None:
            return np.repeat(self.C[None], n, axis=0), np.zeros((n, 3))
        C0, C1, t0, T, wob = self._move
        theta = matrix_to_rotvec(C0.T @ C1)
        s = np.clip((t - t0) / T, 0.0, 1.0) if T > 0 else np.ones(n)
        Cs = np.stack([C0 @ rotvec_to_matrix(k * theta) for k in smoothstep(s)])
        rate = np.where((s > 0) & (s < 1), 0.5 * np.pi * np.sin(np.pi * s) / T, 0.0) if T > 0 else np.zeros(n)
        w = rate[:, None] * theta[None, :]
        u = t - (t0 + T)
        on = u > 0
        if on.any():  # set down: it rocks, a damped oscillation about a random axis
            wt = 2 * np.pi * WOBBLE_HZ * u[on]
            env = np.exp(-u[on] / WOBBLE_TAU_S)
            a = env * np.sin(wt)
            da = env * (2 * np.pi * WOBBLE_HZ * np.cos(wt) - np.sin(wt) / WOBBLE_TAU_S)
            Cs[on] = np.stack([C1 @ rotvec_to_matrix(x * wob) for x in a])
            w[on] = da[:, None] * wob[None, :]
        return Cs, w

    def read(self, n: int) -> dict[str, np.ndarray]:
        """The next ``n`` samples in raw units: t_s, ax..az (V), gx..gz (rad/s), mx..mz (uT),
        temp_c (and ref_gx..ref_gz, rad/s, with the reference IMU)."""
        dt = 1.0 / self.rate_hz
        t = self.t_s + np.arange(1, n + 1) * dt
        if self.auto and t[-1] >= self._auto_next_s and self._move is None and self._drive is None:
            self._auto_index = (self._auto_index + 1) % len(self.positions)
            self.set_orientation(self.positions[self._auto_index])
        Cs, w = self._attitude(t)
        if self._move is not None and t[-1] >= self._move[2] + self._move[3] + WOBBLE_S:
            self.C = self._move[1]
            self._move = None
            self._auto_next_s = t[-1] + self.hold_s
        C_b_n = np.transpose(Cs, (0, 2, 1))
        f_b = C_b_n @ np.array([0.0, 0.0, -self.g])
        m_b = C_b_n @ self.m_ned
        w_b = w + C_b_n @ frames.earth_rate_ned(self.site["latitude_deg"])
        # temperature relaxes toward its set point with a 30 s time constant
        a = math.exp(-dt / 30.0)
        temps = self._temp_target + (self.temp_c - self._temp_target) * a ** np.arange(1, n + 1)
        self.temp_c = float(temps[-1])
        cond = Conditions(t_s=t, temp_c=temps, temp_ref_c=25.0, f_mps2=f_b)
        K = accel_model.K_matrix(self.accel)
        acc = accel_model.forward(f_b, self.accel, cond) + self.rng.normal(scale=0.01, size=(n, 3)) @ K.T
        gyr = gyro_model.forward(w_b, self.gyro, cond) + self.rng.normal(scale=0.003, size=(n, 3))
        mag = mag_model.forward(m_b, self.mag, cond) + self.rng.normal(scale=0.15, size=(n, 3))
        self.t_s = float(t[-1])
        out = {
            "t_s": t,
            "ax": acc[:, 0],
            "ay": acc[:, 1],
            "az": acc[:, 2],
            "gx": gyr[:, 0],
            "gy": gyr[:, 1],
            "gz": gyr[:, 2],
            "mx": mag[:, 0],
            "my": mag[:, 1],
            "mz": mag[:, 2],
            "temp_c": temps,
        }
        if self.reference:
            ref = w_b + self.ref_bias + self.rng.normal(scale=0.0003, size=(n, 3))
            out.update({"ref_gx": ref[:, 0], "ref_gy": ref[:, 1], "ref_gz": ref[:, 2]})
        return out


class LiveVehicle:
    """P5 live: a vehicle with INS/DGPS and a three-beam LDV (the beams of
    :func:`simulate_ldv`), sample by sample, driven by the operator.

    ``drive(on)`` starts (cruise about 10 m/s with speed changes) or stops (brakes to a
    halt in ~10 s); ``turns(on)`` adds turns, hills and braking, which spread the body
    velocity's direction (the lateral and vertical components ramp in over ~3 s). On a
    straight road they are centimetres per second: the velocity set stays ill-conditioned
    (the source's warning). Outputs: ``vl1..vl3`` (beams, m/s), ``vx vy vz`` (reference
    body velocity, FRD, m/s), ``wx wy wz`` (body rates, rad/s), ``temp_c``."""

    def __init__(
        self,
        *,
        seed: int = 0,
        rate_hz: float = 10.0,
        beam_noise_mps: float = 0.01,
        ref_noise_mps: float = 0.005,
        site: dict | None = None,
    ):
        self.rng = np.random.default_rng(seed)
        self.rate_hz = float(rate_hz)
        self.site = dict(DEFAULT_SITE, **(site or {}))
        self.device_id = f"SIM-LDV-{seed:04d}"
        self.units = {"accel_unit": "", "gyro_unit": "rad/s", "mag_unit": ""}
        self.positions: list[str] = []
        dK = self.rng.normal(scale=0.005, size=3)
        alpha = np.array([60.0, 60.0, 90.0]) + self.rng.normal(scale=0.5, size=3)
        beta = np.array([90.0, 90.0, 60.0]) + self.rng.normal(scale=0.5, size=3)
        gamma = np.degrees(
            np.arccos(np.sqrt(np.clip(1 - np.cos(np.radians(alpha)) ** 2 - np.cos(np.radians(beta)) ** 2, 0, 1)))
        )
        alpha[1] = 180.0 - alpha[1]  # the second beam looks backward
        self.params = {"X": ldv_model.X_from_angles(dK, alpha, beta, gamma)}
        self.truth = jsonable(
            {"X": self.params["X"], "dK": dK, "alpha_deg": alpha, "beta_deg": beta, "gamma_deg": gamma}
        )
        self.beam_noise_mps, self.ref_noise_mps = beam_noise_mps, ref_noise_mps
        self.ph = self.rng.uniform(0, 2 * np.pi, size=6)
        self.t_s = 0.0
        self.speed_mps = 0.0  # forward cruise speed (before the speed changes)
        self.turn = 0.0  # 0 straight .. 1 full turns and hills
        self._driving = False
        self._turns = False
        self.temp_c = 15.0

    channels = ("vl1", "vl2", "vl3", "vx", "vy", "vz")  # beams and the reference body velocity

    @property
    def driving(self) -> bool:
        return self._driving

    @property
    def turning(self) -> bool:
        return self._turns

    def drive(self, on: bool) -> None:
        self._driving = bool(on)

    def turns(self, on: bool) -> None:
        self._turns = bool(on)

    def set_orientation(self, name: str) -> None:
        """Commands by name (the bench interface): ``drive``, ``stop``, ``turns``, ``straight``."""
        actions = {
            "drive": lambda: self.drive(True),
            "stop": lambda: self.drive(False),
            "turns": lambda: self.turns(True),
            "straight": lambda: self.turns(False),
        }
        if name not in actions:
            raise SimulationError(f"unknown vehicle command {name!r}; known: {', '.join(actions)}")
        actions[name]()

    def read(self, n: int) -> dict[str, np.ndarray]:
        dt = 1.0 / self.rate_hz
        t = self.t_s + np.arange(1, n + 1) * dt
        k = np.arange(1, n + 1)
        # first-order lags: cruise speed (accelerate ~5 s, brake ~3 s), turn amount ~3 s
        target = 10.0 if self._driving else 0.0
        tau = 5.0 if self._driving else 3.0
        spd = target + (self.speed_mps - target) * np.exp(-k * dt / tau)
        tt = 1.0 if self._turns else 0.0
        turn = tt + (self.turn - tt) * np.exp(-k * dt / 3.0)
        self.speed_mps, self.turn = float(spd[-1]), float(turn[-1])
        ph = self.ph
        moving = spd / 10.0  # the manoeuvres scale with the speed (a parked car has none)
        fwd = spd * (1.0 + 0.5 * turn * np.sin(2 * np.pi * t / 47.0 + ph[0])) + 0.2 * moving * np.sin(
            2 * np.pi * t / 23.0 + ph[1]
        )
        lat = moving * (0.01 + turn * 2.0) * np.sin(2 * np.pi * t / 31.0 + ph[2]) + moving * turn * 0.8 * np.sin(
            2 * np.pi * t / 13.0 + ph[4]
        )
        vert = moving * (0.01 + turn * 1.5) * np.sin(2 * np.pi * t / 41.0 + ph[3]) + moving * turn * 0.5 * np.sin(
            2 * np.pi * t / 17.0 + ph[5]
        )
        v_b = np.column_stack([fwd, lat, vert])
        w_b = moving[:, None] * np.column_stack(
            [
                0.05 * np.sin(2 * np.pi * t / 19.0),
                0.04 * np.sin(2 * np.pi * t / 29.0),
                (0.02 + 0.13 * turn) * np.sin(2 * np.pi * t / 37.0 + ph[0]),
            ]
        )
        a = math.exp(-dt / 900.0)  # warming up toward 25 °C
        temps = 25.0 + (self.temp_c - 25.0) * a**k
        self.temp_c = float(temps[-1])
        cond = Conditions(t_s=t, temp_c=temps, temp_ref_c=25.0, omega_body_rad_s=w_b)
        vl = ldv_model.forward(v_b, self.params, cond) + self.rng.normal(scale=self.beam_noise_mps, size=(n, 3))
        ref = v_b + self.rng.normal(scale=self.ref_noise_mps, size=(n, 3))
        self.t_s = float(t[-1])
        return {
            "t_s": t,
            "vl1": vl[:, 0],
            "vl2": vl[:, 1],
            "vl3": vl[:, 2],
            "vx": ref[:, 0],
            "vy": ref[:, 1],
            "vz": ref[:, 2],
            "wx": w_b[:, 0],
            "wy": w_b[:, 1],
            "wz": w_b[:, 2],
            "temp_c": temps,
        }
