"""An independent capture generator for the diagnose benchmark (benchmarks/bench_diagnose_independent.py).

Not ``solvers.simulate``: the bench choices here are this file's own, drawn per scenario
from wide ranges a real bench spans:

- accel-tabletop: 9–30 positions (axis-aligned, tilted and random directions in a random
  order), with or without a ``position`` column (labels the station knows, or none), or a
  table of averages; holds of 8–45 s, moves of 2–8 s with hand tremor; 50–200 Hz; units
  V, counts, g or m/s²; white noise plus Gauss–Markov bias instability (τ 20–400 s).
- gyro-drift: 1–4 static orientations (tilted, several headings), 4–15 min in all,
  rad/s or deg/s, angle random walk plus bias instability, latitude in the metadata.
- accel-centrifuge: a table of 6–20 mountings (random attitudes) × 2–5 speeds, radius
  0.4–1.6 m, rows in mounting order or in speed order, ``elapsed_s`` and ``temp_c``.
- compass: 8–20 hand-held holds of 2–6 s with moves of 1–3 s, 25–100 Hz, field in nT, µT
  or gauss, hand acceleration while moving, hard iron wandering slowly.
- ldv: a vehicle drive of 5–15 min (random speed and turn profile), 10–50 Hz, reference
  velocity in the body frame or NED plus attitude, body rates present or not.

Temperature profiles: constant, a warm-up that tracks time, a thermal-chamber staircase
or a cycle that does not track time, a random walk.

Effects: the canonical ones (diagnose.md) with patterns drawn here, put into the shared
forward models of ``solvers.models`` (one model), and effects the library does not hold
(``bias_step``, ``periodic_bias``, ``temp_scale``: a scale factor linear in temperature),
added to the raw output here — the world has effects nobody listed.

Sizing: :func:`detection_z` is the amplitude signal-to-noise ratio of the *true*
extension: the noise-free signature (output with the effect minus output without),
mapped to what the procedure observes (the input's magnitude for norm-based
calibrations: P1, P2, compass magnitudes plus the compass dip at holds against IGRF's
inclination; the full vector for the gyro and the LDV; hold means for a table of
averages), least-squares projected off the baseline's parameters, with the generator's
own noise covariance (white plus exponential-kernel bias instability):
``z = |s⊥|² / sqrt(s⊥ᵀ Σ s⊥)``. An effect "at k σ" has the size that makes ``z = k``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from solvers import frames
from solvers.geomag import field_ned, igrf_reference
from solvers.models import Conditions
from solvers.models import accel as accel_model
from solvers.models import gyro as gyro_model
from solvers.models import ldv as ldv_model
from solvers.models import mag as mag_model

CANONICAL = {
    "accel-tabletop": ("temperature_bias", "time_drift", "quadratic", "scale_asymmetry"),
    "gyro-drift": ("temperature_bias", "time_drift", "g_sensitivity"),
    "accel-centrifuge": ("temperature_bias", "time_drift", "misalignment", "cubic", "lever_arm"),
    "compass": ("temperature_bias", "time_drift", "mag_accel_misalignment", "field_anomaly", "time_varying_hard_iron"),
    "ldv": ("temperature_bias", "time_drift", "time_delay", "lever_arm", "offset"),
}
UNLISTED = {
    "accel-tabletop": ("bias_step", "periodic_bias", "temp_scale"),
    "gyro-drift": ("bias_step", "periodic_bias"),
    "accel-centrifuge": ("temp_scale",),
    "compass": ("periodic_bias", "temp_scale"),
    "ldv": ("bias_step", "periodic_bias", "temp_scale"),
}
PROCEDURES = tuple(CANONICAL)
ACCEL_UNITS = {"V": 0.25, "counts": 16384 / 9.80665, "g": 1 / 9.80665, "m/s^2": 1.0}  # output per m/s²
MAG_UNITS = {"nT": 1.0, "uT": 1e-3, "gauss": 1e-5}  # output per nT
SITES = [(52.2, 0.12, 20.0), (-33.9, 151.2, 40.0), (47.4, 8.5, 420.0), (35.7, 139.7, 10.0), (64.1, -21.9, 30.0)]


@dataclass
class Rendered:
    meta: dict
    columns: dict
    raw: np.ndarray  # (N, 3) raw output the signature is taken on
    obs: Observation


@dataclass
class Observation:
    """What the procedure's calibration observes of a raw signature (see module docstring)."""

    kind: str  # "radial" (norm-based) or "vector"
    use: np.ndarray  # sample mask of the samples the calibration uses
    A: np.ndarray | None  # (3, 3) raw → calibrated input (radial)
    u: np.ndarray | None  # (N, 3) unit input direction per sample (radial)
    sigma: np.ndarray  # (3,) white noise per raw axis (vector) or (1,) radial σ in input units
    gm_ratio: float  # bias-instability σ over white σ
    tau_s: float
    t: np.ndarray
    hold: np.ndarray  # hold index per sample (−1 moving)
    averages: bool  # only hold means reach the calibration
    span: list = field(default_factory=list)  # raw-space (N, 3) patterns the baseline absorbs
    dip: dict | None = None  # compass: {"f_hat": (H, 3), "W": (3, 3), "sigma": (H,)}


# ------------------------------------------------------------------ helpers


def _temperature(rng, t, kind):
    T0 = rng.uniform(15, 30)
    span = t[-1] - t[0] if len(t) > 1 else 1.0
    if kind == "constant":
        return T0 + rng.normal(scale=0.02, size=len(t))
    if kind == "warmup":
        return (
            T0
            + rng.uniform(2, 8) * (1 - np.exp(-(t - t[0]) / rng.uniform(0.2, 0.6) / span))
            + rng.normal(scale=0.03, size=len(t))
        )
    if kind == "staircase":  # thermal chamber: levels in a random order, not tracking time
        levels = rng.permutation(np.linspace(-10, 10, int(rng.integers(3, 6))))
        k = np.minimum(((t - t[0]) / span * len(levels)).astype(int), len(levels) - 1)
        return T0 + levels[k] + rng.normal(scale=0.05, size=len(t))
    if kind == "cycle":
        return (
            T0
            + rng.uniform(3, 8) * np.sin(2 * np.pi * (t - t[0]) / span * rng.uniform(1.2, 2.5) + rng.uniform(0, 6.28))
            + rng.normal(scale=0.03, size=len(t))
        )
    # random walk
    steps = rng.normal(scale=1.0, size=len(t))
    walk = np.cumsum(steps)
    walk = (walk - walk.mean()) / max(np.ptp(walk), 1e-9) * rng.uniform(2, 6)
    return T0 + walk


def _gm(rng, t, sigma, tau, dim=3):
    """Gauss–Markov (exponential kernel, stationary σ) on a uniform time grid t."""
    from scipy.signal import lfilter

    dt = float(t[1] - t[0]) if len(t) > 1 else 1.0
    a = math.exp(-dt / tau)
    w = rng.normal(scale=sigma * math.sqrt(1 - a * a), size=(len(t), dim))
    w[0] = rng.normal(scale=sigma, size=dim)
    return lfilter([1.0], [1.0, -a], w, axis=0)


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _rand_dir(rng):
    return _unit(rng.normal(size=3))


def _slerp_moves(C0, C1, n):
    """Attitudes from C0 to C1 over n samples (smooth), with a little tremor."""
    r = frames.matrix_to_rotvec(C0.T @ C1)
    s = np.linspace(0, 1, n + 2)[1:-1]
    s = s * s * (3 - 2 * s)
    return np.stack([C0 @ frames.rotvec_to_matrix(r * x) for x in s])


def _holds_and_moves(atts, hold_n, move_n):
    """Each attitude held for hold_n samples, joined by smooth moves of move_n samples:
    (the attitudes (N, 3, 3), each sample's hold index (-1 moving))."""
    Cs, hid = [], []
    for k, C in enumerate(atts):
        if k:
            Cs.append(_slerp_moves(atts[k - 1], C, move_n))
            hid += [-1] * move_n
        Cs.append(np.repeat(C[None], hold_n, axis=0))
        hid += [k] * hold_n
    return np.concatenate(Cs), np.array(hid)


def _meta(sc, tag, units=None, site=True, **extra) -> dict:
    """A capture's header (capture-format.md): the procedure, a device named after the trial,
    ``units``, then (``site``) the site, date and sample rate, then ``extra``."""
    meta = {"station-capture": "1", "procedure": sc["procedure"], "device": f"IND-{tag}-{sc['seed_rng'] % 10000}"}
    meta.update(units or {})
    if site:
        lat, lon, alt = sc["site"]
        meta.update(latitude_deg=f"{lat}", longitude_deg=f"{lon}", altitude_m=f"{alt}", date="2025-06-01")
        meta["sample_rate_hz"] = f"{sc['rate']:g}"
    meta.update(extra)
    return meta


def _xyz(prefix, v) -> dict:
    """Columns prefix+x, y, z from the (N, 3) array ``v``."""
    return {f"{prefix}{c}": v[:, j] for j, c in enumerate("xyz")}


def _on_axis(n, j, col) -> np.ndarray:
    """An (n, 3) raw pattern: ``col`` on output axis j, zero on the others."""
    e = np.zeros((n, 3))
    e[:, j] = col
    return e


def _unlisted(name, size, pattern, t, temp):
    """Additive raw terms of the unlisted effects (size in raw units; temp_scale handled by the caller)."""
    tt = (t - t[0]) / max(t[-1] - t[0], 1e-9)
    if name == "bias_step":
        return np.outer(tt >= pattern["at"], pattern["v"]) * size
    if name == "periodic_bias":
        return np.outer(np.sin(2 * np.pi * (t - t[0]) / pattern["period_s"] + pattern["phase"]), pattern["v"]) * size
    return np.zeros((len(t), 3))


def _patterns(rng, duration_s):
    """One pattern per effect (unit size), drawn with the scenario."""
    return {
        "v": _rand_dir(rng),
        "v2": _rand_dir(rng),
        "signs": rng.choice([-1.0, 1.0], 3) * rng.uniform(0.4, 1.0, 3),
        "M": rng.normal(size=(3, 3)),
        "at": rng.uniform(0.3, 0.7),
        "phase": rng.uniform(0, 2 * np.pi),
        "period_s": duration_s / rng.uniform(3.0, 8.0),
        "gamma": _unit(rng.normal(size=6)),
    }


# ------------------------------------------------------------------ P1 level table


def tabletop_scenario(rng):
    n_pos = int(rng.integers(9, 31))
    axes = [np.array(v, float) for v in ([1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1])]
    names = ["x_up", "x_down", "y_up", "y_down", "z_up", "z_down"]
    mode = rng.choice(["labelled", "unlabelled", "averages"], p=[0.35, 0.4, 0.25])
    dirs, labels = [], []
    for k in range(n_pos):
        if k < 6:
            dirs.append(axes[k] if mode != "unlabelled" else _unit(axes[k] + rng.normal(scale=0.03, size=3)))
            labels.append(names[k])
        elif rng.uniform() < 0.5:
            d = _unit(rng.normal(size=3) * np.array([1, 1, 0.3]) + rng.choice([-1, 1]) * np.eye(3)[rng.integers(3)])
            dirs.append(d)
            labels.append(f"q{k + 1}")
        else:
            dirs.append(_rand_dir(rng))
            labels.append(f"r{k + 1}")
    order = rng.permutation(n_pos)
    unit = str(rng.choice(list(ACCEL_UNITS)))
    rate = float(rng.choice([50.0, 100.0, 125.0, 200.0]))
    hold = float(rng.uniform(8, 45))
    if n_pos * hold * rate > 110_000:
        rate = 50.0
    white = float(rng.uniform(0.003, 0.03))
    return {
        "procedure": "accel-tabletop",
        "seed_rng": int(rng.integers(1 << 31)),
        "dirs": [dirs[k] for k in order],
        "labels": [labels[k] for k in order],
        "mode": str(mode),
        "unit": unit,
        "rate": rate,
        "hold": hold,
        "move": float(rng.uniform(2, 8)),
        "white": white,
        "gm": white * float(rng.uniform(0.0, 0.04)),
        "tau": float(rng.uniform(20, 400)),
        "temp": str(rng.choice(["constant", "warmup", "staircase", "cycle", "walk"])),
        "placement_deg": float(rng.uniform(0.1, 1.0)),
        "site": SITES[int(rng.integers(len(SITES)))],
        "K": (np.eye(3) + rng.normal(scale=0.01, size=(3, 3))) * ACCEL_UNITS[unit] * rng.uniform(0.9, 1.1, 3)[:, None],
        "b": rng.normal(scale=0.3, size=3) * ACCEL_UNITS[unit],
    }


def tabletop_render(sc, effect=None, size=0.0, noise=True):
    rng = np.random.default_rng(sc["seed_rng"])
    g = frames.normal_gravity_mps2(sc["site"][0], sc["site"][2])
    rate, hold_n, move_n = sc["rate"], int(sc["hold"] * sc["rate"]), int(sc["move"] * sc["rate"])
    atts = []
    for d in sc["dirs"]:
        P = frames.rotvec_to_matrix(rng.normal(scale=math.radians(sc["placement_deg"]), size=3))
        from solvers.positions import C_n_b_for

        atts.append(C_n_b_for(d, rng.uniform(0, 2 * np.pi)) @ P)
    C_all, hold_id = _holds_and_moves(atts, hold_n, move_n)
    n = len(C_all)
    t = np.arange(n) / rate
    moving = hold_id < 0
    f = np.einsum("nji,j->ni", C_all, np.array([0.0, 0.0, -g]))
    f[moving] += rng.normal(scale=0.5, size=(int(moving.sum()), 3))
    temp = _temperature(rng, t, sc["temp"])
    pat = _patterns(rng, t[-1])
    params = {"K": sc["K"].copy(), "b": sc["b"].copy()}
    extra = np.zeros((n, 3))
    Kd = np.diag(sc["K"])
    if effect == "temperature_bias":
        params["bT"] = Kd * pat["signs"] * size  # size: m/s² per °C
    elif effect == "time_drift":
        params["bt"] = Kd * pat["signs"] * size / 3600.0  # size: m/s² per hour
    elif effect == "quadratic":
        params["D"] = pat["signs"] * size  # 1/(m/s²)
    elif effect == "scale_asymmetry":
        params["A"] = pat["signs"] * size
    elif effect in ("bias_step", "periodic_bias"):
        extra = _unlisted(effect, size, {**pat}, t, temp) * Kd  # size in m/s²
    cond = Conditions(t_s=t, temp_c=temp, temp_ref_c=float(np.mean(temp)), t_ref_s=float(np.mean(t)))
    y = accel_model.forward(f, params, cond) + extra
    if effect == "temp_scale":  # size: relative scale per °C
        y = y + ((temp - temp.mean())[:, None] * pat["signs"] * size * f) @ sc["K"].T
    nz = np.zeros((n, 3))
    if noise:
        nz = rng.normal(scale=sc["white"], size=(n, 3)) + (_gm(rng, t, sc["gm"], sc["tau"]) if sc["gm"] > 0 else 0)
    y = y + nz @ sc["K"].T
    gyro = np.zeros((n, 3))
    gyro[moving] = rng.normal(scale=0.3, size=(int(moving.sum()), 3))
    gyro += rng.normal(scale=0.002, size=(n, 3)) + 0.01
    meta = _meta(sc, "P1", {"accel_unit": sc["unit"], "gyro_unit": "rad/s"})
    lab = np.array([sc["labels"][k] if k >= 0 else "" for k in hold_id], dtype=object)
    if sc["mode"] == "averages":
        cols = {
            "position": [],
            "n": [],
            "ax": [],
            "ay": [],
            "az": [],
            "ax_std": [],
            "ay_std": [],
            "az_std": [],
            "temp_c": [],
        }
        for k in range(len(atts)):
            m = hold_id == k
            cols["position"].append(sc["labels"][k])
            cols["n"].append(float(m.sum()))
            for j, c in enumerate("xyz"):
                cols[f"a{c}"].append(float(y[m, j].mean()))
                cols[f"a{c}_std"].append(float(y[m, j].std(ddof=1)))
            cols["temp_c"].append(float(temp[m].mean()))
        cols = {k: np.array(v, dtype=object if k == "position" else float) for k, v in cols.items()}
    else:
        cols = {"t": t}
        if sc["mode"] == "labelled":
            cols["position"] = lab
        cols.update({**_xyz("a", y), **_xyz("g", gyro), "temp_c": temp})
    u = f / np.linalg.norm(f, axis=1, keepdims=True)
    Kinv = np.linalg.inv(sc["K"])
    span = [np.outer(np.ones(n), sc["K"][:, j]) for j in range(3)]
    span += [np.outer(f[:, i], sc["K"][:, j]) for i in range(3) for j in range(3)]
    obs = Observation(
        "radial",
        ~moving,
        Kinv,
        u,
        np.array([sc["white"]]),
        sc["gm"] / sc["white"],
        sc["tau"],
        t,
        hold_id,
        sc["mode"] == "averages",
        span,
    )
    return Rendered(meta, cols, y, obs)


# ------------------------------------------------------------------ P4 gyro drift


def gyro_scenario(rng):
    n_or = int(rng.choice([1, 2, 3, 4], p=[0.25, 0.2, 0.2, 0.35]))
    total = float(rng.uniform(240, 900))
    unit = str(rng.choice(["rad/s", "deg/s"]))
    white = float(rng.uniform(5e-4, 5e-3))
    return {
        "procedure": "gyro-drift",
        "seed_rng": int(rng.integers(1 << 31)),
        "n_or": n_or,
        "total": total,
        "rate": float(rng.choice([20.0, 50.0, 100.0])),
        "unit": unit,
        "white": white,
        "gm": white * float(rng.uniform(0.0, 0.01)),
        "tau": float(rng.uniform(30, 300)),
        "temp": str(rng.choice(["constant", "warmup", "staircase", "cycle", "walk"])),
        "site": SITES[int(rng.integers(len(SITES)))],
        "headings": [float(h) for h in rng.uniform(0, 360, n_or)],
        "tilts": [(float(rng.normal(scale=25)), float(rng.normal(scale=25))) for _ in range(n_or)],
        "eps": rng.normal(scale=0.005, size=3),
    }


def gyro_render(sc, effect=None, size=0.0, noise=True):
    rng = np.random.default_rng(sc["seed_rng"])
    lat = sc["site"][0]
    g = frames.normal_gravity_mps2(lat, sc["site"][2])
    per = int(sc["total"] / sc["n_or"] * sc["rate"])
    Cs, hid, head = [], [], []
    for k in range(sc["n_or"]):
        p, r = map(math.radians, sc["tilts"][k])
        C = frames.p4_C_n_b(p, r, math.radians(sc["headings"][k] + rng.normal(scale=1.0)))
        Cs.append(np.repeat(C[None], per, axis=0))
        hid += [k] * per
        head += [sc["headings"][k]] * per
    C_all = np.concatenate(Cs)
    hid = np.array(hid)
    n = len(C_all)
    t = np.arange(n) / sc["rate"]
    C_b_n = np.transpose(C_all, (0, 2, 1))
    w_e = C_b_n @ frames.earth_rate_nue(lat)
    f_b = C_b_n @ np.array([0.0, g, 0.0])
    temp = _temperature(rng, t, sc["temp"])
    pat = _patterns(rng, t[-1])
    params = {"eps": sc["eps"].copy()}
    extra = np.zeros((n, 3))
    if effect == "temperature_bias":
        params["bT"] = pat["signs"] * size  # rad/s per °C
    elif effect == "time_drift":
        params["bt"] = pat["signs"] * size / 3600.0  # rad/s per hour
    elif effect == "g_sensitivity":
        params["G"] = pat["M"] / np.linalg.norm(pat["M"]) * size  # rad/s per m/s²
    elif effect in ("bias_step", "periodic_bias"):
        extra = _unlisted(effect, size, pat, t, temp)
    cond = Conditions(t_s=t, temp_c=temp, temp_ref_c=float(temp.mean()), t_ref_s=float(t.mean()), f_mps2=f_b)
    y = gyro_model.forward(w_e, params, cond) + extra
    if noise:
        y = y + rng.normal(scale=sc["white"], size=(n, 3)) + (_gm(rng, t, sc["gm"], sc["tau"]) if sc["gm"] > 0 else 0)
    acc = f_b + (rng.normal(scale=0.02, size=(n, 3)) if noise else 0)
    k = 1.0 if sc["unit"] == "rad/s" else 180 / math.pi
    meta = _meta(
        sc,
        "P4",
        {"accel_unit": "m/s^2", "gyro_unit": sc["unit"]},
        gyro_mode="static",
        frame="body x forward, y up, z right",
    )
    cols = {"t": t, **_xyz("a", acc), **_xyz("g", y * k), "temp_c": temp}
    if sc["n_or"] > 1:
        cols["position"] = np.array([f"o{x + 1}" for x in hid], dtype=object)
        cols["heading_deg"] = np.array(head)
    else:
        meta["heading_deg"] = f"{sc['headings'][0]:.1f}"
    span = [_on_axis(n, j, 1.0) for j in range(3)]
    obs = Observation(
        "vector",
        np.ones(n, bool),
        None,
        None,
        np.full(3, sc["white"]),
        sc["gm"] / sc["white"],
        sc["tau"],
        t,
        hid,
        False,
        span,
    )
    return Rendered(meta, cols, y, obs)


# ------------------------------------------------------------------ P2 centrifuge


def centrifuge_scenario(rng):
    n_m = int(rng.integers(6, 21))
    n_s = int(rng.integers(2, 6))
    speeds = np.sort(rng.uniform(math.pi, 8 * math.pi, n_s))
    return {
        "procedure": "accel-centrifuge",
        "seed_rng": int(rng.integers(1 << 31)),
        "n_m": n_m,
        "speeds": [float(s) for s in speeds],
        "radius": float(rng.uniform(0.4, 1.6)),
        "order": str(rng.choice(["mounting", "speed"])),
        "noise": float(rng.uniform(3e-6, 3e-5)),
        "row_s": float(rng.uniform(60, 300)),
        "temp": str(rng.choice(["constant", "warmup", "staircase", "cycle", "walk", "speed"])),
        "S": rng.uniform(0.95, 1.3, 3),
        "b": rng.normal(scale=0.05, size=3),
        "D": rng.normal(scale=5e-5, size=3),
        "g": float(rng.uniform(9.78, 9.83)),
    }


def centrifuge_render(sc, effect=None, size=0.0, noise=True):
    rng = np.random.default_rng(sc["seed_rng"])
    atts = [frames.rotvec_to_matrix(rng.normal(size=3) * 2.0) for _ in range(sc["n_m"])]
    rows = [(m, w) for m in range(sc["n_m"]) for w in sc["speeds"]]
    if sc["order"] == "speed":
        rows = [(m, w) for w in sc["speeds"] for m in range(sc["n_m"])]
    f, c, ws, lab = [], [], [], []
    for m, w in rows:
        A = w * w * sc["radius"] / sc["g"]
        f.append(atts[m].T @ np.array([-A, 0.0, 1.0]))
        c.append(atts[m].T @ np.array([-1.0, 0.0, 0.0]))
        ws.append(w)
        lab.append(f"m{m + 1}")
    f, c, ws = np.array(f), np.array(c), np.array(ws)
    n = len(f)
    el = np.arange(n) * sc["row_s"]
    if sc["temp"] == "speed":
        temp = 22.0 + 0.4 * ws / math.pi + rng.normal(scale=0.05, size=n)
    else:
        temp = _temperature(rng, el, sc["temp"])
    pat = _patterns(rng, el[-1])
    params = {"S": sc["S"], "b": sc["b"], "D": sc["D"]}
    if effect == "temperature_bias":
        params["bT"] = pat["signs"] * size  # g per °C
    elif effect == "time_drift":
        params["bt"] = pat["signs"] * size / 3600.0  # g per hour
    elif effect == "misalignment":
        params["gamma"] = pat["gamma"] * size  # rad
    elif effect == "cubic":
        params["C3"] = pat["signs"] * size  # 1/g²
    elif effect == "lever_arm":
        params["dr"] = pat["signs"] * size  # m
    cond = Conditions(
        t_s=el,
        temp_c=temp,
        temp_ref_c=float(temp.mean()),
        t_ref_s=float(el.mean()),
        input_unit_mps2=sc["g"],
        omega_rad_s=ws,
        centripetal_dir=c,
    )
    y = accel_model.forward(f, params, cond)
    if effect == "temp_scale":
        y = y + ((temp - temp.mean())[:, None] * pat["signs"] * size * f) * sc["S"]
    if noise:
        y = y + rng.normal(scale=sc["noise"], size=(n, 3))
    meta = _meta(sc, "P2", {"accel_unit": "g"}, site=False, radius_m=repr(sc["radius"]), g_mps2=repr(sc["g"]))
    cols = {
        "position": np.array(lab, dtype=object),
        "speed_rad_s": ws,
        **_xyz("a", y),
        "temp_c": temp,
        "elapsed_s": el,
    }
    u = f / np.linalg.norm(f, axis=1, keepdims=True)
    S = np.diag(sc["S"])
    span = [_on_axis(n, j, col * sc["S"][j]) for j in range(3) for col in (np.ones(n), f[:, j], f[:, j] ** 2)]
    obs = Observation(
        "radial",
        np.ones(n, bool),
        np.linalg.inv(S),
        u,
        np.array([sc["noise"]]),
        0.0,
        1.0,
        el,
        np.arange(n),
        False,
        span,
    )
    return Rendered(meta, cols, y, obs)


# ------------------------------------------------------------------ P3 compass


def compass_scenario(rng):
    unit = str(rng.choice(list(MAG_UNITS)))
    return {
        "procedure": "compass",
        "seed_rng": int(rng.integers(1 << 31)),
        "n_h": int(rng.integers(8, 21)),
        "hold": float(rng.uniform(2, 6)),
        "move": float(rng.uniform(1, 3)),
        "rate": float(rng.choice([25.0, 50.0, 100.0])),
        "unit": unit,
        "white_nT": float(rng.uniform(30, 200)),
        "gm_nT": float(rng.uniform(0, 15)),
        "tau": float(rng.uniform(20, 200)),
        "temp": str(rng.choice(["constant", "warmup", "cycle", "walk"])),
        "site": SITES[int(rng.integers(len(SITES)))],
        "accel_unit": str(rng.choice(["g", "m/s^2"])),
        "W": np.eye(3) + np.triu(rng.normal(scale=0.05, size=(3, 3))),
        "h": rng.normal(scale=5000, size=3),
    }


def compass_render(sc, effect=None, size=0.0, noise=True):
    rng = np.random.default_rng(sc["seed_rng"])
    lat, lon, alt = sc["site"]
    ref = igrf_reference(lat, lon, alt, "2025-06-01")
    m_ned = field_ned(ref)
    g = frames.normal_gravity_mps2(lat, alt)
    atts = [frames.rotvec_to_matrix(_rand_dir(rng) * rng.uniform(0, math.pi)) for _ in range(sc["n_h"])]
    hn, mn = int(sc["hold"] * sc["rate"]), int(sc["move"] * sc["rate"])
    C_all, hid = _holds_and_moves(atts, hn, mn)
    n = len(C_all)
    t = np.arange(n) / sc["rate"]
    moving = hid < 0
    C_b_n = np.transpose(C_all, (0, 2, 1))
    f_b = C_b_n @ np.array([0.0, 0.0, -g])
    f_b[moving] += rng.normal(scale=0.6, size=(int(moving.sum()), 3))
    temp = _temperature(rng, t, sc["temp"])
    pat = _patterns(rng, t[-1])
    m_n = m_ned.copy()
    if effect == "field_anomaly":  # size: relative magnitude change; inclination moves with it (steel nearby)
        R = frames.rotvec_to_matrix(
            np.cross([0, 0, 1.0], _unit(m_ned))
            / np.linalg.norm(np.cross([0, 0, 1.0], _unit(m_ned)))
            * size
            * 0.4
            * pat["signs"][0]
        )
        m_n = (1 + size * pat["signs"][1] / abs(pat["signs"][1])) * (R @ m_ned)
    m_b = C_b_n @ m_n
    params = {"W": sc["W"], "h": sc["h"]}
    extra = np.zeros((n, 3))
    if effect == "temperature_bias":
        params["bT"] = pat["signs"] * size  # nT per °C
    elif effect == "time_drift":
        params["bt"] = pat["signs"] * size / 3600.0  # nT per hour
    elif effect == "mag_accel_misalignment":
        params["rho"] = pat["v"] * size  # rad
    elif effect == "time_varying_hard_iron":
        params["dh"] = pat["v"] * size  # nT
        params["t_on_s"] = np.array(t[0] + pat["at"] * (t[-1] - t[0]))
    elif effect == "periodic_bias":
        extra = _unlisted(effect, size, pat, t, temp)
    cond = Conditions(t_s=t, temp_c=temp, temp_ref_c=float(temp.mean()), t_ref_s=float(t.mean()))
    y = mag_model.forward(m_b, params, cond) + extra
    if effect == "temp_scale":
        y = y + np.linalg.solve(sc["W"], ((temp - temp.mean())[:, None] * pat["signs"] * size * m_b).T).T
    if noise:
        y = (
            y
            + rng.normal(scale=sc["white_nT"], size=(n, 3))
            + (_gm(rng, t, sc["gm_nT"], sc["tau"]) if sc["gm_nT"] > 0 else 0)
        )
    a_k = 1 / 9.80665 if sc["accel_unit"] == "g" else 1.0
    acc = (f_b + (rng.normal(scale=0.02, size=(n, 3)) if noise else 0)) * a_k
    w = np.zeros((n, 3))
    w[moving] = rng.normal(scale=0.8, size=(int(moving.sum()), 3))
    gyr = np.degrees(w + (rng.normal(scale=0.003, size=(n, 3)) if noise else 0))
    ku = MAG_UNITS[sc["unit"]]
    meta = _meta(sc, "P3", {"accel_unit": sc["accel_unit"], "gyro_unit": "deg/s", "mag_unit": sc["unit"]})
    cols = {"t": t, **_xyz("a", acc), **_xyz("g", gyr), **_xyz("m", y * ku), "temp_c": temp}
    Winv = np.linalg.inv(sc["W"])
    m_true = C_b_n @ m_ned
    span = []
    for j in range(3):
        span.append(_on_axis(n, j, 1.0))
        # W upper ⇔ W⁻¹ upper: output j from input i ≥ j
        span += [_on_axis(n, j, m_true[:, i]) for i in range(j, 3)]
    # a rotation of the field about the vertical (heading is not known)
    span.append((np.einsum("nij,j->ni", C_b_n, np.cross([0, 0, 1.0], m_ned))) @ Winv.T)
    H = len(atts)
    f_hat = np.array([_unit(C_b_n[hid == k][0] @ np.array([0.0, 0.0, -1.0])) for k in range(H)])
    Fm = np.linalg.norm(m_ned)
    dip_sigma = np.full(H, math.hypot(sc["white_nT"] / Fm / math.sqrt(hn), 0.02 / g / math.sqrt(hn)))
    obs = Observation(
        "radial",
        np.ones(n, bool),
        sc["W"],
        m_true / Fm,
        np.array([sc["white_nT"]]),
        sc["gm_nT"] / sc["white_nT"],
        sc["tau"],
        t,
        hid,
        False,
        span,
        dip={"f_hat": f_hat, "W": sc["W"], "sigma": dip_sigma, "m_hat": m_true / Fm, "F": Fm},
    )
    return Rendered(meta, cols, y, obs)


# ------------------------------------------------------------------ P5 LDV


def ldv_scenario(rng):
    return {
        "procedure": "ldv",
        "seed_rng": int(rng.integers(1 << 31)),
        "duration": float(rng.uniform(300, 900)),
        "rate": float(rng.choice([10.0, 20.0, 50.0])),
        "ref": str(rng.choice(["body", "nav"])),
        "rates": bool(rng.uniform() < 0.7),
        "noise": float(rng.uniform(0.003, 0.03)),
        "temp": str(rng.choice(["constant", "warmup", "cycle", "walk"])),
        "site": SITES[int(rng.integers(len(SITES)))],
    }


def ldv_render(sc, effect=None, size=0.0, noise=True):
    rng = np.random.default_rng(sc["seed_rng"])
    n = int(sc["duration"] * sc["rate"])
    t = np.arange(n) / sc["rate"]
    # a drive: speed and turn profile from random piecewise accelerations, hills
    knots = np.linspace(0, t[-1], int(sc["duration"] / 20) + 2)
    spd = np.interp(t, knots, rng.uniform(3, 25, len(knots)))
    yaw_rate = np.interp(t, knots, rng.normal(scale=0.12, size=len(knots)))
    pitch = np.interp(t, knots, rng.normal(scale=0.04, size=len(knots)))
    roll = 0.15 * yaw_rate * spd / 10
    side = 0.03 * spd * yaw_rate * 3 + rng.normal(scale=0.05) + 0.8 * np.sin(2 * np.pi * t / rng.uniform(15, 40))
    vert = spd * np.sin(pitch) * 0.2 + 0.6 * np.sin(2 * np.pi * t / rng.uniform(10, 30))
    v_b = np.column_stack([spd, side, vert])
    w_b = np.column_stack([np.gradient(roll, t), np.gradient(pitch, t), yaw_rate])
    X = []
    for a, b in ((60, 90), (120, 90), (90, 60)):
        ca, cb = math.cos(math.radians(a + rng.normal(scale=1))), math.cos(math.radians(b + rng.normal(scale=1)))
        X.append((1 + rng.normal(scale=0.005)) * np.array([ca, cb, math.sqrt(1 - ca * ca - cb * cb)]))
    X = np.array(X)
    temp = _temperature(rng, t, sc["temp"])
    pat = _patterns(rng, t[-1])
    params = {"X": X}
    extra = np.zeros((n, 3))
    if effect == "temperature_bias":
        params["bT"] = pat["signs"] * size  # m/s per °C
    elif effect == "time_drift":
        params["bt"] = pat["signs"] * size / 3600.0  # m/s per hour
    elif effect == "time_delay":
        params["tau_s"] = np.array(size * pat["signs"][0] / abs(pat["signs"][0]))
    elif effect == "lever_arm":
        params["r"] = pat["v"] * size
    elif effect == "offset":
        params["o"] = pat["signs"] * size
    elif effect in ("bias_step", "periodic_bias"):
        extra = _unlisted(effect, size, pat, t, temp)
    cond = Conditions(t_s=t, temp_c=temp, temp_ref_c=float(temp.mean()), t_ref_s=float(t.mean()), omega_body_rad_s=w_b)
    y = ldv_model.forward(v_b, params, cond) + extra
    if effect == "temp_scale":
        y = y + (temp - temp.mean())[:, None] * pat["signs"] * size * (v_b @ X.T)
    if noise:
        y = y + rng.normal(scale=sc["noise"], size=(n, 3))
    v_ref = v_b + (rng.normal(scale=sc["noise"] / 4, size=(n, 3)) if noise else 0)
    meta = _meta(sc, "P5", frame="body x forward, y right, z down")
    cols = {"t": t, "vl1": y[:, 0], "vl2": y[:, 1], "vl3": y[:, 2]}
    if sc["ref"] == "nav":
        yaw = np.cumsum(yaw_rate) / sc["rate"]
        C = np.stack([frames.euler_to_C_n_b(r, p, q) for r, p, q in zip(roll, pitch, yaw)])
        v_n = np.einsum("nij,nj->ni", C, v_ref)
        cols.update(
            {
                "vn": v_n[:, 0],
                "ve": v_n[:, 1],
                "vd": v_n[:, 2],
                "roll_deg": np.degrees(roll),
                "pitch_deg": np.degrees(pitch),
                "yaw_deg": np.degrees(yaw),
            }
        )
    else:
        cols.update(_xyz("v", v_ref))
    if sc["rates"]:
        cols.update(_xyz("w", w_b))
    cols["temp_c"] = temp
    span = [_on_axis(n, j, v_b[:, i]) for j in range(3) for i in range(3)]
    obs = Observation(
        "vector", np.ones(n, bool), None, None, np.full(3, sc["noise"]), 0.0, 1.0, t, np.zeros(n, int), False, span
    )
    return Rendered(meta, cols, y, obs)


SCENARIOS = {
    "accel-tabletop": tabletop_scenario,
    "gyro-drift": gyro_scenario,
    "accel-centrifuge": centrifuge_scenario,
    "compass": compass_scenario,
    "ldv": ldv_scenario,
}
RENDER = {
    "accel-tabletop": tabletop_render,
    "gyro-drift": gyro_render,
    "accel-centrifuge": centrifuge_render,
    "compass": compass_render,
    "ldv": ldv_render,
}


def tied_names(result: dict, name: str) -> set[str]:
    """The names a diagnose result gives as indistinguishable from ``name`` (itself included):
    every effect whose ``confused_with`` group holds it."""
    out = {name}
    for e in result["effects"]:
        group = {e["name"]} | {c["name"] for c in e["confused_with"]}
        if name in group:
            out |= group
    return out


def applicable(sc: dict, effect: str) -> bool:
    """Whether a scenario can show the effect at all (its driver exists and varies)."""
    p = sc["procedure"]
    if effect in ("temperature_bias", "temp_scale") and sc.get("temp") == "constant":
        return False
    if p == "accel-tabletop" and sc["mode"] == "averages" and effect in ("time_drift", "bias_step", "periodic_bias"):
        return False  # a table without time
    if p == "gyro-drift" and effect == "g_sensitivity" and sc["n_or"] < 3:
        return False
    if p == "ldv" and effect == "lever_arm" and not sc["rates"]:
        return False
    return True


# ------------------------------------------------------------------ detection σ of the true extension


def scenario_for(procedure: str, rng, effect: str | None = None, tries: int = 50) -> dict | None:
    """The first scenario ``rng`` draws for ``procedure`` in which ``effect`` applies (the first
    drawn when None), or None when none of ``tries`` draws does (the benchmark's and the tests'
    one way of drawing a trial)."""
    for _ in range(tries):
        sc = SCENARIOS[procedure](rng)
        if effect is None or applicable(sc, effect):
            return sc
    return None


def _kernel_apply(x: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """``Σ_j exp(−|i − j| dt/τ) x_j`` on a uniform grid (two recursive passes)."""
    from scipy.signal import lfilter

    a = math.exp(-dt / tau)
    fw = lfilter([1.0], [1.0, -a], x, axis=0)
    bw = lfilter([1.0], [1.0, -a], x[::-1], axis=0)[::-1]
    return fw + bw - x


def _observe(o: Observation, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Raw-space pattern (N, 3) → (per-sample observable (M, k) in white-σ units, dip rows in σ units)."""
    if o.kind == "radial":
        x = np.einsum("ni,ni->n", o.u, d @ o.A.T)[:, None] / o.sigma[0]
    else:
        x = d / o.sigma
    x = x[o.use]
    dip = np.zeros(0)
    if o.dip is not None:
        H = len(o.dip["f_hat"])
        rows = []
        for k in range(H):
            m = o.hold == k
            dm = (d[m] @ o.dip["W"].T).mean(axis=0) / o.dip["F"]
            mh = o.dip["m_hat"][m][0]
            dperp = dm - mh * (mh @ dm)
            rows.append(o.dip["f_hat"][k] @ dperp / o.dip["sigma"][k])
        dip = np.array(rows)
    if o.averages:
        hid = o.hold[o.use]
        for k in np.unique(hid):
            sel = hid == k
            x[sel] = x[sel].mean(axis=0)
    return x, dip


def detection_z(o: Observation, signature: np.ndarray) -> float:
    """Amplitude SNR of a raw-space signature after the baseline's span is projected off."""
    s, sd = _observe(o, signature)
    cols = [_observe(o, c) for c in o.span]
    S = np.concatenate([s.ravel(), sd])
    B = np.column_stack([np.concatenate([c[0].ravel(), c[1]]) for c in cols])
    coef, *_ = np.linalg.lstsq(B, S, rcond=None)
    r = S - B @ coef
    m = s.size
    rs = r[:m].reshape(s.shape)
    num = float(r @ r)
    var = float(r @ r)  # white part (unit variance)
    if o.gm_ratio > 0:
        full = np.zeros((len(o.t), rs.shape[1]))
        full[o.use] = rs
        dt = float(o.t[1] - o.t[0]) if len(o.t) > 1 else 1.0
        var += o.gm_ratio**2 * float(np.sum(full * _kernel_apply(full, dt, o.tau_s)))
    return num / math.sqrt(max(var, 1e-300))


def size_for(sc: dict, effect: str, k_sigma: float, ref: float | None = None) -> tuple[float, float]:
    """(size, z per unit size) putting ``effect`` at ``k_sigma`` of its true extension's detection σ."""
    render = RENDER[sc["procedure"]]
    base = render(sc, None, 0.0, noise=False).raw
    ref = ref or REF_SIZE[sc["procedure"]][effect]
    z = detection_z(render(sc, None, 0.0, noise=False).obs, render(sc, effect, ref, noise=False).raw - base)
    if not z > 0:
        return math.nan, 0.0
    size = ref * k_sigma / z
    # one refinement (nonlinear effects: delay, rotations)
    z2 = detection_z(render(sc, None, 0.0, noise=False).obs, render(sc, effect, size, noise=False).raw - base)
    if z2 > 0:
        size *= k_sigma / z2
    return size, z / ref


REF_SIZE = {
    "accel-tabletop": {
        "temperature_bias": 1e-3,
        "time_drift": 1e-2,
        "quadratic": 1e-4,
        "scale_asymmetry": 1e-3,
        "bias_step": 1e-2,
        "periodic_bias": 1e-2,
        "temp_scale": 1e-4,
    },
    "gyro-drift": {
        "temperature_bias": 1e-5,
        "time_drift": 1e-4,
        "g_sensitivity": 1e-5,
        "bias_step": 1e-4,
        "periodic_bias": 1e-4,
    },
    "accel-centrifuge": {
        "temperature_bias": 1e-5,
        "time_drift": 1e-5,
        "misalignment": 1e-4,
        "cubic": 1e-7,
        "lever_arm": 1e-3,
        "temp_scale": 1e-5,
    },
    "compass": {
        "temperature_bias": 10.0,
        "time_drift": 100.0,
        "mag_accel_misalignment": 0.01,
        "field_anomaly": 0.01,
        "time_varying_hard_iron": 100.0,
        "periodic_bias": 100.0,
        "temp_scale": 1e-3,
    },
    "ldv": {
        "temperature_bias": 1e-3,
        "time_drift": 1e-2,
        "time_delay": 1e-2,
        "lever_arm": 0.05,
        "offset": 1e-2,
        "bias_step": 1e-2,
        "periodic_bias": 1e-2,
        "temp_scale": 1e-4,
    },
}


def write_csv(path, meta: dict, columns: dict) -> None:
    """A capture file (capture-format.md) written here, not by the station's writer."""
    names = list(columns)
    text = []
    for k in names:
        c = np.asarray(columns[k])
        if c.dtype == object:
            text.append(np.array([str(x) for x in c], dtype=object))
        else:
            s = np.char.mod("%.10g", c.astype(float)).astype(object)
            s[~np.isfinite(c.astype(float))] = ""
            text.append(s)
    rows = text[0]
    for c in text[1:]:
        rows = rows + "," + c
    with open(path, "w") as fh:
        for k, v in meta.items():
            fh.write(f"# {k}: {v}\n")
        fh.write(",".join(names) + "\n")
        fh.write("\n".join(rows.tolist()) + "\n")
