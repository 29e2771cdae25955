"""An independent capture generator for `station diagnose` on the static procedures.

Written from the contracts only (../shared/spec/capture-format.md, procedures.md,
diagnose.md, calibrate.md), before reading any of the station's simulators or its
diagnosis code: P1 accel-tabletop, P2 accel-centrifuge and P4 gyro-drift captures as a
bench would write them, with one hidden effect (or none) each.

What varies, as on a real bench: orientation sets of 9-30 positions of its own (random
tumbles, tilted cube faces, a 45 degree grid; P4 mode B with heading, pitch and roll of each
placing), with and without a `position` column, time series (holds 5-60 s at 50-400 Hz,
motion between holds) and tables of averages (with or without `n` and `<col>_std`),
white noise plus a Gauss-Markov bias instability and a random walk, temperature that
tracks time (warm-up), that does not (chamber set points in shuffled order) or that
cycles (air conditioning), unit spellings of the spec (`V`, `counts`, `g`, `m/s^2`;
`rad/s`, `deg/s`), P2 speed sets and radii of its own, P4 mode A (reference IMU) and
mode B (Earth rate, static base, site given).

Effect size. Each effect is scaled to a detection sigma z of the true extension under
this file's own noise: r = the effect's contribution to the per-hold averages (the rows
diagnose sees), after a weighted least-squares fit of the baseline model (the
procedure's model as the source states it, fitted here by this file's own code) to the
noise-free effect-only signal; z = sqrt(r^T S^-1 r), S the covariance of those rows'
noise (white / n, the bias instability's and the random walk's covariance between hold
centres, propagated through the baseline's residual). The amplitude is scaled so that
z = --z (10 or 3.5). For `earth_rate` (P4, no latitude: a plain bias is fitted) the
effect is the Earth itself: the noise is scaled instead.

    python benchmarks/indep_s27_generator.py one --procedure P1 --effect quadratic --z 10 \
        --seed 700001 --out FILE.csv
    python benchmarks/indep_s27_generator.py batch --out DIR [--per-cell 4] [--nulls 20]
    python benchmarks/indep_s27_generator.py run DIR [--jobs 2]      # station diagnose --json
    python benchmarks/indep_s27_generator.py table DIR                # the tally

Seeds are 700000 and up (400000-699999 belong to other benchmarks).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from scipy.linalg import cho_factor, cho_solve, solve_triangular
from scipy.optimize import least_squares
from scipy.signal import lfilter
from scipy.spatial.transform import Rotation

G0 = 9.80665
OMEGA_IE = 7.2921151e-5

EFFECTS = {
    "P1": [
        "temperature_bias",
        "time_drift",
        "quadratic",
        "scale_asymmetry",
        "bias_step",
        "periodic_bias",
        "temp_scale",
    ],
    "P2": [
        "misalignment",
        "cubic",
        "lever_arm",
        "time_drift",
        "temperature_bias",
        "bias_step",
        "periodic_bias",
        "temp_scale",
    ],
    "P4": ["earth_rate", "g_sensitivity", "temperature_bias", "time_drift", "bias_step", "periodic_bias", "temp_scale"],
}
EXPECTED = {
    "bias_step": "residual:time",
    "periodic_bias": "residual:time",
    "temp_scale": "residual:temperature",
}
NEEDS_TIME = {"time_drift", "bias_step", "periodic_bias"}
NEEDS_TEMP = {"temperature_bias", "temp_scale"}
PROC_NAME = {"P1": "accel-tabletop", "P2": "accel-centrifuge", "P4": "gyro-drift"}


def expected_name(effect: str) -> str | None:
    if effect == "none":
        return None
    return EXPECTED.get(effect, effect)


# ---------------------------------------------------------------- noise


def noise_params(rng, sw_out: float, fs: float, duration_s: float) -> dict:
    """White (per sample), Gauss-Markov bias instability and random walk, in output units."""
    hold_ref = sw_out / np.sqrt(fs * 30.0)
    return {
        "sw": sw_out,
        "sb": hold_ref * rng.uniform(0.2, 1.2),
        "tau": rng.uniform(60.0, 600.0),
        "q": hold_ref * rng.uniform(0.0, 0.8) / np.sqrt(max(duration_s, 1.0) * fs),
        "quant": 0.0,
    }


def noise_series(rng, n: int, fs: float, p: dict) -> np.ndarray:
    white = rng.standard_normal(n) * p["sw"]
    phi = np.exp(-1.0 / (fs * p["tau"]))
    e = rng.standard_normal(n)
    gm = lfilter([np.sqrt(1 - phi**2) * p["sb"]], [1.0, -phi], e, zi=[phi * rng.standard_normal() * p["sb"]])[0]
    rw = np.cumsum(rng.standard_normal(n)) * p["q"]
    return white + gm + rw


def noise_cov(tc: np.ndarray, nk: np.ndarray, fs: float, p: dict) -> np.ndarray:
    """Covariance of hold means: hold centres tc (noise clock, s from the first sample), nk samples."""
    d = np.abs(tc[:, None] - tc[None, :])
    cov = p["sb"] ** 2 * np.exp(-d / p["tau"])
    cov += p["q"] ** 2 * fs * np.minimum(tc[:, None], tc[None, :])
    cov += np.diag((p["sw"] ** 2 + p["quant"] ** 2 / 12.0) / nk)
    return cov


# ---------------------------------------------------------------- orientations


def orientation_set(rng, k: int) -> Rotation:
    """k sensor-to-world rotations of this bench's own choosing, spread enough for a fit."""
    kind = rng.choice(["tumble", "tilted_faces", "grid45"])
    for _ in range(200):
        if kind == "tumble":
            rots = Rotation.random(k, random_state=rng.integers(2**31))
        elif kind == "tilted_faces":
            faces = Rotation.from_euler(
                "xyz",
                [[0, 0, 0], [180, 0, 0], [90, 0, 0], [-90, 0, 0], [0, 90, 0], [0, -90, 0]],
                degrees=True,
            )
            idx = rng.integers(0, 6, k)
            idx[: min(6, k)] = np.arange(min(6, k))
            tilt = Rotation.from_rotvec(rng.normal(0, np.radians(20), (k, 3)))
            rots = tilt * faces[idx]
        else:
            base = rng.choice([-135, -90, -45, 0, 45, 90, 135, 180], (k, 2))
            rots = Rotation.from_euler("xy", base + rng.normal(0, 1.0, (k, 2)), degrees=True) * Rotation.from_rotvec(
                rng.normal(0, 0.01, (k, 3))
            )
        up = rots.inv().apply([0, 0, 1.0])  # world up in the sensor frame
        ev = np.linalg.eigvalsh(up.T @ up / k)
        cosang = up @ up.T - 2 * np.eye(k)
        if ev[0] > 0.12 and cosang.max() < np.cos(np.radians(12)):
            return rots
    return Rotation.random(k, random_state=rng.integers(2**31))


# ---------------------------------------------------------------- timeline


def timeline(rng, k: int, fs: float, hold_s: np.ndarray, move_s: tuple[float, float], gaps: np.ndarray | None = None):
    """Segments hold 0, move, hold 1, ... ; returns time (s), noise clock (s), hold index (-1 moving), move fraction."""
    t_parts, h_parts, s_parts = [], [], []
    t = 0.0
    for j in range(k):
        n = int(round(hold_s[j] * fs))
        t_parts.append(t + np.arange(n) / fs)
        h_parts.append(np.full(n, j))
        s_parts.append(np.zeros(n))
        t += n / fs
        if j < k - 1:
            if gaps is not None and gaps[j] > 0:
                t += gaps[j]
            m = int(round(rng.uniform(*move_s) * fs))
            t_parts.append(t + np.arange(m) / fs)
            h_parts.append(np.full(m, -1))
            s_parts.append((np.arange(m) + 0.5) / m)
            t += m / fs
    tt = np.concatenate(t_parts)
    return tt, np.arange(tt.size) / fs, np.concatenate(h_parts), np.concatenate(s_parts)


def temperature_profile(rng, kind: str, trel: np.ndarray, hold: np.ndarray, k: int) -> np.ndarray | None:
    if kind == "none":
        return None
    t0 = rng.uniform(18, 30)
    dur = max(trel[-1], 1.0)
    if kind == "warmup":
        temp = t0 + rng.uniform(4, 15) * (1 - np.exp(-trel / (dur * rng.uniform(0.2, 0.8))))
    elif kind == "chamber":
        sets = rng.permutation(np.linspace(-rng.uniform(5, 12), rng.uniform(5, 12), k))
        # each hold at its set point; the sensor lags by a few seconds after a move
        target = np.where(hold >= 0, sets[np.maximum(hold, 0)], np.nan)
        target = _ffill(target, sets[0])
        alpha = 1.0 / (1.0 + rng.uniform(1, 4) * (len(trel) / dur))
        temp = t0 + lfilter([alpha], [1, alpha - 1], target - target[0]) + target[0]
    else:  # cycle
        per = dur / rng.uniform(1.5, 4)
        temp = t0 + rng.uniform(1.5, 4) * np.sin(2 * np.pi * trel / per + rng.uniform(0, 6.3)) + 0.5 * trel / dur
    return temp


def _ffill(x: np.ndarray, first: float) -> np.ndarray:
    out = x.copy()
    if np.isnan(out[0]):
        out[0] = first
    idx = np.where(~np.isnan(out), np.arange(out.size), 0)
    np.maximum.accumulate(idx, out=idx)
    return out[idx]


def hold_means(x: np.ndarray, hold: np.ndarray, k: int) -> np.ndarray:
    out = np.empty((k,) + x.shape[1:])
    for j in range(k):
        out[j] = x[hold == j].mean(axis=0)
    return out


def hold_covs(tnoise: np.ndarray, hold: np.ndarray, k: int, fs: float, noise: list[dict]) -> list[np.ndarray]:
    """Per axis, the (k, k) covariance of the k hold means (noise_cov at the holds' centres)."""
    t_c = hold_means(tnoise, hold, k)
    nk = np.array([(hold == j).sum() for j in range(k)], float)
    return [noise_cov(t_c, nk, fs, noise[i]) for i in range(3)]


def draw_temperature(rng, effect_name: str, trel: np.ndarray, hold: np.ndarray, k: int, p):
    """The bench's temperature: its kind (drawn with probabilities p over warmup, chamber, cycle,
    none; never none for an effect that needs a temperature) and its profile (degC, None for none)."""
    tkind = rng.choice(["warmup", "chamber", "cycle", "none"], p=p)
    if effect_name in NEEDS_TEMP and tkind == "none":
        tkind = rng.choice(["warmup", "chamber", "cycle"])
    return tkind, temperature_profile(rng, tkind, trel, hold, k)


def capture_ctx(k, fs, series, trel, tnoise, hold_idx, temp, tkind, unit, **more) -> dict:
    """What write_capture (and make_one's record) need of a build: the holds, the clocks, the
    temperature and the unit, then any keys of the procedure's own (``more``)."""
    ctx = dict(k=k, fs=fs, series=series, trel=trel, tnoise=tnoise, hold_idx=hold_idx, temp=temp, tkind=tkind)
    return {**ctx, "unit": unit, **more}


# ---------------------------------------------------------------- effect shapes


def unit_vec(rng, n=3):
    v = rng.standard_normal(n)
    return v / np.linalg.norm(v)


class Effect:
    """An effect's shape at unit amplitude; `amp` multiplies it."""

    def __init__(self, name: str, rng, trel_end: float):
        self.name = name
        self.dir = unit_vec(rng)
        self.mat = rng.standard_normal((3, 3))
        self.t_step = trel_end * rng.uniform(0.3, 0.7)
        self.period = trel_end / rng.uniform(2.0, 5.0)
        self.phase = rng.uniform(0, 2 * np.pi)
        self.t_ref = 25.0
        self.amp = 0.0


def draw_effect(rng, effect_name: str, trel: np.ndarray, temp: np.ndarray | None) -> Effect | None:
    """The hidden effect (None for "none"), its reference temperature near the bench's mean."""
    eff = None if effect_name == "none" else Effect(effect_name, rng, trel[-1])
    if eff is not None and temp is not None:
        eff.t_ref = float(np.mean(temp)) + rng.uniform(-3, 3)
    return eff


# ---------------------------------------------------------------- P1


def p1_apply(eff: Effect | None, a: np.ndarray, temp, trel) -> np.ndarray:
    """a: true specific force in the sensor frame (m/s^2, N x 3) -> what the sensing element feels."""
    if eff is None or eff.amp == 0:
        return a
    x, d = eff.amp, eff.dir
    n = eff.name
    if n == "temperature_bias":
        return a + x * np.outer(temp - eff.t_ref, d)
    if n == "time_drift":
        return a + x * np.outer(trel, d)
    if n == "quadratic":
        return a + x * d * a**2
    if n == "scale_asymmetry":
        return a + x * d * np.abs(a)
    if n == "bias_step":
        return a + x * np.outer(trel > eff.t_step, d)
    if n == "periodic_bias":
        return a + x * np.outer(np.sin(2 * np.pi * trel / eff.period + eff.phase), d)
    if n == "temp_scale":
        return a * (1 + x * np.outer(temp - eff.t_ref, d))
    raise ValueError(n)


def p1_residual(theta, vbar, g):
    b = theta[:3]
    m = np.zeros((3, 3))
    m[np.triu_indices(3)] = theta[3:]
    a = vbar @ m.T + b
    return np.linalg.norm(a, axis=1) - g, a, m


def p1_z(truth, vbar_eff, covs, g):
    """Weighted baseline fit (norm condition, upper-triangular gauge) to noise-free data; returns z."""
    _, a0, m0 = p1_residual(truth["theta0"], truth["vbar0"], g)
    u = a0 / np.linalg.norm(a0, axis=1)[:, None]
    j = u @ m0  # d|A_k|/dV_k, k x 3
    s = sum(np.outer(j[:, i], j[:, i]) * covs[i] for i in range(3))
    lo = np.linalg.cholesky(s)

    def fun(th):
        return solve_triangular(lo, p1_residual(th, vbar_eff, g)[0], lower=True)

    sol = least_squares(fun, truth["theta0"], x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200)
    return float(np.linalg.norm(sol.fun))


def build_p1(rng, effect_name: str):
    # 9 positions leave the norm fit (9 parameters) no degree of freedom: an effect needs 12+
    k = int(rng.integers(9 if effect_name == "none" else 12, 31))
    rots = orientation_set(rng, k)
    series = rng.random() < 0.65 or effect_name in NEEDS_TIME
    fs = float(rng.choice([50, 100, 125, 200, 250, 400]))
    if series:
        hold = rng.uniform(5, 60, k)
        while hold.sum() * fs > 80_000:
            if fs >= 100:
                fs /= 2
            else:
                hold *= 0.8
    else:
        hold = rng.uniform(20, 300, k)
        fs = float(rng.choice([50, 100]))
    trel, tnoise, hold_idx, sfrac = timeline(rng, k, fs, hold, (1.5, 4.0))
    # orientation per sample: holds fixed, moves a smooth slerp to the next hold
    quats = rots.as_quat()
    rot_idx = np.where(hold_idx >= 0, hold_idx, 0)
    # moving samples: index of the hold before
    prev = _ffill(np.where(hold_idx >= 0, hold_idx, np.nan).astype(float), 0).astype(int)
    moving = hold_idx < 0
    r_all = Rotation.from_quat(quats[rot_idx])
    if moving.any():
        pm = prev[moving]
        sm = 3 * sfrac[moving] ** 2 - 2 * sfrac[moving] ** 3
        rel = (rots[pm].inv() * rots[np.minimum(pm + 1, k - 1)]).as_rotvec()
        r_mov = rots[pm] * Rotation.from_rotvec(rel * sm[:, None])
        q = r_all.as_quat()
        q[moving] = r_mov.as_quat()
        r_all = Rotation.from_quat(q)
    g = G0 + rng.uniform(-0.03, 0.03)
    a_true = r_all.inv().apply([0, 0, g])
    a_true[moving] += rng.normal(0, 0.3, (moving.sum(), 3))  # handling
    tkind, temp = draw_temperature(rng, effect_name, trel, hold_idx, k, p=[0.35, 0.3, 0.2, 0.15])
    unit = rng.choice(["V", "counts", "g", "m/s^2"])
    if unit == "V":
        s = rng.uniform(0.02, 0.1, 3) * rng.choice([-1, 1], 3, p=[0.2, 0.8])
        o = rng.choice([1.65, 2.5]) + rng.normal(0, 0.05, 3)
    elif unit == "counts":
        s = rng.choice([16384, 8192, 4096]) / G0 * rng.uniform(0.97, 1.03, 3)
        o = rng.normal(0, 150, 3)
    elif unit == "g":
        s = rng.uniform(0.98, 1.02, 3) / G0
        o = rng.normal(0, 0.03, 3)
    else:
        s = rng.uniform(0.98, 1.02, 3)
        o = rng.normal(0, 0.3, 3)
    kmat = np.diag(s) @ (np.eye(3) + rng.normal(0, 0.01, (3, 3)) * (1 - np.eye(3)))
    sw = rng.uniform(0.002, 0.03)  # m/s^2 per sample
    noise = [noise_params(rng, sw * abs(s[i]), fs, trel[-1]) for i in range(3)]
    if unit == "counts":
        for p in noise:
            p["quant"] = 1.0
    eff = draw_effect(rng, effect_name, trel, temp)
    m_true = np.linalg.inv(kmat)
    q_, u_ = np.linalg.qr(m_true)
    sgn = np.sign(np.diag(u_))
    q_, u_ = q_ * sgn, (u_.T * sgn).T
    theta0 = np.concatenate([q_.T @ (-m_true @ o), u_[np.triu_indices(3)]])

    def vbar_of(amp):
        if eff is not None:
            eff.amp = amp
        a = p1_apply(eff, a_true, temp, trel)
        return hold_means(o + a @ kmat.T, hold_idx, k)

    vbar0 = vbar_of(0.0)
    covs = hold_covs(tnoise, hold_idx, k, fs, noise)
    truth = {"theta0": theta0, "vbar0": vbar0}
    # holds numbered in the bench's own order (P1's own numbers mean directions: these do not), or named
    labels = [str(j + 1) for j in range(k)] if rng.random() < 0.5 else [f"pose{j + 1:02d}" for j in range(k)]
    ctx = capture_ctx(k, fs, series, trel, tnoise, hold_idx, temp, tkind, unit, labels=labels)

    def zfun(amp):
        return p1_z(truth, vbar_of(amp), covs, g)

    def write(amp, path, scale_noise=1.0):
        if eff is not None:
            eff.amp = amp
        a = p1_apply(eff, a_true, temp, trel)
        v = o + a @ kmat.T
        v = v + np.stack([noise_series(rng, trel.size, fs, noise[i]) for i in range(3)], 1) * scale_noise
        if unit == "counts" and series:
            v = np.round(v)
        meta = {"accel_unit": unit}
        if rng.random() < 0.5:
            meta["g_mps2"] = f"{g:.6f}"
        else:
            meta["latitude_deg"] = f"{rng.uniform(-60, 60):.4f}"
            meta["longitude_deg"] = f"{rng.uniform(-180, 180):.4f}"
            meta["altitude_m"] = f"{rng.uniform(0, 1500):.0f}"
            meta["g_mps2"] = f"{g:.6f}"
        cols = {"ax": v[:, 0], "ay": v[:, 1], "az": v[:, 2]}
        write_capture(rng, path, "accel-tabletop", meta, cols, ctx, decimals=_decimals(unit))

    return zfun, write, ctx, eff


def _decimals(unit):
    return {"V": 6, "counts": 2, "g": 7, "m/s^2": 6, "rad/s": 8, "deg/s": 6}[unit]


# ---------------------------------------------------------------- writing


def write_capture(rng, path, procedure, meta, cols, ctx, decimals, extra_cols=None, extra_dec=None):
    """A time series (t, maybe position) or a table of hold averages (maybe n and _std)."""
    extra_cols = extra_cols or {}
    extra_dec = extra_dec or {}
    hold_idx, k = ctx["hold_idx"], ctx["k"]
    labels = ctx.get("labels") or [str(j + 1) for j in range(k)]
    lines = ["# station-capture: 1", f"# procedure: {procedure}", f"# device: INDEP-{rng.integers(1000, 9999)}"]
    if ctx.get("date", True):
        lines.append(f"# date: 2026-{rng.integers(1, 12):02d}-{rng.integers(1, 28):02d}")
    for key, val in meta.items():
        lines.append(f"# {key}: {val}")
    temp = ctx["temp"]
    allc = dict(cols)
    allc.update(extra_cols)
    dec = {c: decimals for c in cols}
    dec.update(extra_dec)
    if temp is not None:
        allc["temp_c"] = np.round(temp + rng.normal(0, 0.03, temp.size), 2)
        dec["temp_c"] = 2
    names = list(allc)
    if ctx["series"]:
        lines.insert(3, f"# sample_rate_hz: {ctx['fs']:g}")
        with_pos = ctx.get("with_position", rng.random() < 0.6)
        t = ctx["trel"] + ctx.get("t0", rng.uniform(0, 5000))
        header = ["t"] + (["position"] if with_pos else []) + names
        order = rng.permutation(len(header) - 1 - with_pos) if rng.random() < 0.3 else None
        if order is not None:
            tail = [names[i] for i in order]
            header = header[: 1 + with_pos] + tail
            names = tail
        lines.append(",".join(header))
        body = np.column_stack([allc[c] for c in names])
        fmts = [f"%.{dec[c]}f" for c in names]
        pos = [labels[h] if h >= 0 else "" for h in hold_idx]
        for i in range(t.size):
            row = [f"{t[i]:.4f}"]
            if with_pos:
                row.append(pos[i])
            row += [f % x for f, x in zip(fmts, body[i], strict=True)]
            lines.append(",".join(row))
    else:
        with_n = rng.random() < 0.6
        with_std = rng.random() < 0.5
        header = ["position"] + names
        means = {c: hold_means(np.asarray(allc[c], float), hold_idx, k) for c in names}
        stds = {}
        for c in names:
            if c in ("temp_c", "speed_rad_s", "heading_deg"):
                continue
            stds[c] = np.array([np.std(np.asarray(allc[c], float)[hold_idx == j], ddof=1) for j in range(k)])
        if with_n:
            header.append("n")
        if with_std:
            header += [f"{c}_std" for c in stds]
        lines.append(",".join(header))
        for j in range(k):
            row = [labels[j]] + [f"%.{dec[c] + 3}f" % means[c][j] for c in names]
            if with_n:
                row.append(str(int((hold_idx == j).sum())))
            if with_std:
                row += [f"%.{dec[c] + 2}f" % stds[c][j] for c in stds]
            lines.append(",".join(row))
    Path(path).write_text("\n".join(lines) + "\n")


# ---------------------------------------------------------------- P2


def p2_forward(eff: Effect | None, f: np.ndarray, temp, trel, par, spd, radius, fdir):
    """f: specific force in g at the sensor frame (N x 3) -> output N."""
    s, b, d = par["S"], par["b"], par["D"]
    phi = np.eye(3)
    x = 0.0 if eff is None else eff.amp
    n = None if eff is None else eff.name
    if n == "lever_arm" and x:
        # axis i at radius R + dr_i: its centripetal part scales by (R + dr_i) / R
        cen = fdir["centripetal"]  # N x 3, centripetal specific force in g per unit radius (sensor frame)
        f = f + cen * (x * eff.dir)[None, :]
    if n == "misalignment" and x:
        gam = x * eff.mat * (1 - np.eye(3))
        phi = np.eye(3) + gam
    inner = f + d * f**2
    if n == "cubic" and x:
        inner = inner + x * eff.dir * f**3
    out = (inner @ phi.T) * s + b
    if n == "time_drift" and x:
        out = out + x * np.outer(trel, eff.dir)
    if n == "temperature_bias" and x:
        out = out + x * np.outer(temp - eff.t_ref, eff.dir)
    if n == "bias_step" and x:
        out = out + x * np.outer(trel > eff.t_step, eff.dir)
    if n == "periodic_bias" and x:
        out = out + x * np.outer(np.sin(2 * np.pi * trel / eff.period + eff.phase), eff.dir)
    if n == "temp_scale" and x:
        out = out + (out - b) * x * np.outer(temp - eff.t_ref, eff.dir)
    return out


def p2_invert(theta, nbar):
    s, b, d = theta[:3], theta[3:6], theta[6:9]
    y = (nbar - b) / s
    disc = np.maximum(1 + 4 * d * y, 1e-12)
    return 2 * y / (1 + np.sqrt(disc))


def p2_z(theta0, nbar0, nbar_eff, amag, covs):
    f0 = p2_invert(theta0, nbar0)
    fn = np.linalg.norm(f0, axis=1)
    s, d = theta0[:3], theta0[6:9]
    j = (f0 / fn[:, None]) / (s * (1 + 2 * d * f0))
    cov = sum(np.outer(j[:, i], j[:, i]) * covs[i] for i in range(3))
    lo = np.linalg.cholesky(cov)
    target = np.sqrt(amag**2 + 1)

    def fun(th):
        return solve_triangular(lo, np.linalg.norm(p2_invert(th, nbar_eff), axis=1) - target, lower=True)

    sol = least_squares(fun, theta0, x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=400)
    return float(np.linalg.norm(sol.fun))


def build_p2(rng, effect_name: str):
    n_or = int(rng.integers(10, 25))
    speeds_n = int(rng.integers(3, 6))
    while n_or * speeds_n < 54:
        speeds_n += 1
    radius = float(rng.choice([0.3, 0.5, 0.8, 1.0, 1.25, 1.5]))
    a_max = rng.uniform(6, 20)
    a_set = np.sort(rng.uniform(0.4, 1.0, speeds_n)) * a_max
    a_set[0] = rng.uniform(0.5, 2.0)
    speeds = np.sqrt(a_set * G0 / radius)
    rots = orientation_set(rng, n_or)  # sensor -> platform (radial out, tangential, up)
    k = n_or * speeds_n
    series = effect_name in NEEDS_TIME or rng.random() < 0.4
    fs = float(rng.choice([50, 100, 200]))
    hold = rng.uniform(5, 30, k) if series else rng.uniform(10, 60, k)
    while series and hold.sum() * fs > 80_000:
        if fs > 50:
            fs /= 2
        else:
            hold *= 0.8
    gaps = np.zeros(k - 1)
    gaps[speeds_n - 1 :: speeds_n] = rng.uniform(60, 180, n_or - 1)  # stop, remount, start
    trel, tnoise, hold_idx, sfrac = timeline(rng, k, fs, hold, (2.0, 5.0), gaps)
    or_idx = np.arange(k) // speeds_n
    sp_idx = np.arange(k) % speeds_n
    prev = _ffill(np.where(hold_idx >= 0, hold_idx, np.nan).astype(float), 0).astype(int)
    moving = hold_idx < 0
    w = speeds[sp_idx[prev]].astype(float)
    alpha = np.zeros_like(w)
    if moving.any():
        pm = prev[moving]
        nxt = np.minimum(pm + 1, k - 1)
        same = or_idx[nxt] == or_idx[pm]
        w0, w1 = speeds[sp_idx[pm]], np.where(same, speeds[sp_idx[nxt]], 0.0)
        # a ramp within an orientation; spin-down then spin-up around a remount
        sm = sfrac[moving]
        w_m = np.where(same, w0 + (w1 - w0) * sm, np.where(sm < 0.5, w0 * (1 - 2 * sm), speeds[0] * (2 * sm - 1)))
        dur = np.diff(np.concatenate([[0], trel]))[moving]
        w[moving] = w_m
        alpha[moving] = np.gradient(w_m) / np.maximum(dur, 1e-3)
    r_sensor = rots[or_idx[prev]]
    cen_platform = np.column_stack([-(w**2), np.zeros_like(w), np.zeros_like(w)]) / G0  # per metre of radius
    f_platform = cen_platform * radius + np.column_stack([np.zeros_like(w), alpha * radius / G0, np.ones_like(w)])
    f = r_sensor.inv().apply(f_platform)
    cen = r_sensor.inv().apply(cen_platform)
    tkind, temp = draw_temperature(rng, effect_name, trel, hold_idx, k, p=[0.35, 0.3, 0.2, 0.15])
    unit = rng.choice(["V", "g", "m/s^2"])
    sc = {"V": 1.0, "g": 1.0, "m/s^2": G0}[unit]
    par = {
        "S": rng.uniform(0.9, 1.3, 3) * sc * (1.0 if unit != "g" else rng.uniform(0.98, 1.02)),
        "b": rng.uniform(-0.3, 0.5, 3) * (1 if unit == "V" else 0.05) * sc,
        "D": rng.uniform(1e-5, 8e-5, 3) * rng.choice([-1, 1], 3),
    }
    if unit == "g":
        par["S"] = rng.uniform(0.98, 1.02, 3)
    sw = rng.uniform(1e-4, 2e-3) * sc
    noise = [noise_params(rng, sw, fs, trel[-1]) for _ in range(3)]
    eff = draw_effect(rng, effect_name, trel, temp)
    theta0 = np.concatenate([par["S"], par["b"], par["D"]])
    amag = a_set[sp_idx]
    fdir = {"centripetal": cen}

    def nbar_of(amp):
        if eff is not None:
            eff.amp = amp
        return hold_means(p2_forward(eff, f, temp, trel, par, w, radius, fdir), hold_idx, k)

    nbar0 = nbar_of(0.0)
    covs = hold_covs(tnoise, hold_idx, k, fs, noise)
    labels = [str(or_idx[j] + 1) for j in range(k)]
    ctx = capture_ctx(
        k,
        fs,
        series,
        trel,
        tnoise,
        hold_idx,
        temp,
        tkind,
        unit,
        labels=labels,
        with_position=True,
        n_orientations=n_or,
        speeds=speeds.tolist(),
        radius_m=radius,
    )

    def zfun(amp):
        return p2_z(theta0, nbar0, nbar_of(amp), amag, covs)

    def write(amp, path, scale_noise=1.0):
        if eff is not None:
            eff.amp = amp
        out = p2_forward(eff, f, temp, trel, par, w, radius, fdir)
        out = out + np.stack([noise_series(rng, trel.size, fs, noise[i]) for i in range(3)], 1) * scale_noise
        meta = {"accel_unit": unit, "radius_m": f"{radius:g}", "g_mps2": f"{G0:.5f}"}
        if rng.random() < 0.5:
            meta["latitude_deg"] = f"{rng.uniform(-60, 60):.3f}"
        cols = {"ax": out[:, 0], "ay": out[:, 1], "az": out[:, 2]}
        write_capture(
            rng,
            path,
            "accel-centrifuge",
            meta,
            cols,
            ctx,
            decimals=7,
            extra_cols={"speed_rad_s": w},
            extra_dec={"speed_rad_s": 6},
        )

    return zfun, write, ctx, eff


# ---------------------------------------------------------------- P4


def p4_orientations(rng, k: int, mode: str):
    """Body (x forward, y up, z right) to NUE rotations, with the heading of the forward axis."""
    heads, mats = [], []
    for _ in range(k):
        psi = rng.uniform(0, 2 * np.pi)
        th = np.radians(rng.uniform(-50, 50))
        ga = rng.uniform(-np.pi, np.pi)
        x = np.array([np.cos(th) * np.cos(psi), np.sin(th), np.cos(th) * np.sin(psi)])
        y0 = np.array([-np.sin(th) * np.cos(psi), np.cos(th), -np.sin(th) * np.sin(psi)])
        z0 = np.cross(x, y0)
        y = np.cos(ga) * y0 + np.sin(ga) * z0
        z = np.cross(x, y)
        mats.append(np.column_stack([x, y, z]))
        heads.append(np.degrees(psi))
    return np.array(mats), np.array(heads)


def build_p4(rng, effect_name: str, no_heading: bool = False):
    """``no_heading``: no ``heading_deg`` column, the latitude given (a tabletop session's positions
    at a known site): mode B (the same draws as with the column), and ``earth_rate`` (mode
    "plain", its noise scaled to the Earth rate's z) with the latitude written, so the Earth rate
    is the baseline's and nothing is to be named."""
    k = int(rng.integers(9, 31))
    if effect_name == "earth_rate":
        mode = "plain"
    else:
        mode = rng.choice(["A", "B"])
    # the station refuses a P4 table of averages by design (a drift's error needs the series: Allan
    # deviation), so P4 is written as time series only (the draw is kept: seeds give the same files)
    series = bool(rng.random() < 0.7 or True)
    fs = float(rng.choice([50, 100, 200, 400]))
    hold = rng.uniform(5, 60, k) if series else rng.uniform(20, 240, k)
    if not series:
        fs = 100.0
    while series and hold.sum() * fs > 50_000:
        if fs > 50:
            fs /= 2
        else:
            hold *= 0.8
    trel, tnoise, hold_idx, sfrac = timeline(rng, k, fs, hold, (2.0, 5.0))
    cbn, heads = p4_orientations(rng, k, mode)
    lat = rng.uniform(-65, 65)
    w_ie_n = OMEGA_IE * np.array([np.cos(np.radians(lat)), np.sin(np.radians(lat)), 0.0])
    rots = Rotation.from_matrix(cbn)
    prev = _ffill(np.where(hold_idx >= 0, hold_idx, np.nan).astype(float), 0).astype(int)
    moving = hold_idx < 0
    r_all = rots[prev]
    w_body = r_all.inv().apply(w_ie_n)
    if moving.any():
        pm = prev[moving]
        nxt = np.minimum(pm + 1, k - 1)
        sm = 3 * sfrac[moving] ** 2 - 2 * sfrac[moving] ** 3
        dsm = 6 * sfrac[moving] * (1 - sfrac[moving])
        rel = (rots[pm].inv() * rots[nxt]).as_rotvec()
        counts = np.bincount(pm, minlength=k)
        seglen = counts[pm] / fs
        r_mov = rots[pm] * Rotation.from_rotvec(rel * sm[:, None])
        q = r_all.as_quat()
        q[moving] = r_mov.as_quat()
        r_all = Rotation.from_quat(q)
        w_body = r_all.inv().apply(w_ie_n)
        w_body[moving] += rel * (dsm / seglen)[:, None]
    f_body = r_all.inv().apply([0, G0, 0.0])
    tkind, temp = draw_temperature(rng, effect_name, trel, hold_idx, k, p=[0.45, 0.2, 0.2, 0.15])
    gunit = rng.choice(["rad/s", "deg/s"])
    gsc = 1.0 if gunit == "rad/s" else np.degrees(1.0)
    aunit = rng.choice(["g", "m/s^2"])
    asc = 1.0 / G0 if aunit == "g" else 1.0
    eps = rng.normal(0, 0.01, 3)  # rad/s power-up bias
    sw = rng.uniform(0.002, 0.02)  # rad/s per sample
    noise = [noise_params(rng, sw, fs, trel[-1]) for _ in range(3)]
    eff = draw_effect(rng, "none" if effect_name == "earth_rate" else effect_name, trel, temp)

    def gyro_of(amp):
        out = w_body + eps
        if eff is None:
            return out
        eff.amp = amp
        n, d, x = eff.name, eff.dir, amp
        if n == "g_sensitivity":
            return out + x * f_body @ eff.mat.T
        if n == "temperature_bias":
            return out + x * np.outer(temp - eff.t_ref, d)
        if n == "time_drift":
            return out + x * np.outer(trel, d)
        if n == "bias_step":
            return out + x * np.outer(trel > eff.t_step, d)
        if n == "periodic_bias":
            return out + x * np.outer(np.sin(2 * np.pi * trel / eff.period + eff.phase), d)
        if n == "temp_scale":
            return out + w_body * x * np.outer(temp - eff.t_ref, d)
        raise ValueError(n)

    covs = hold_covs(tnoise, hold_idx, k, fs, noise)
    ones = np.ones(k)
    # what the baseline does not absorb: mode A/B subtract a known rate (the reference's, or the Earth's
    # at the given site); mode "plain" (no latitude) fits a constant only, so the Earth rate is the effect
    base_known = hold_means(w_body + eps, hold_idx, k) - eps

    def zfun(amp, scale_noise=1.0):
        if mode == "plain":
            sig = hold_means(w_body, hold_idx, k)
        else:
            sig = hold_means(gyro_of(amp), hold_idx, k) - base_known - eps
        z2 = 0.0
        for i in range(3):
            c = covs[i] * scale_noise**2
            cf = cho_factor(c)
            ci1 = cho_solve(cf, ones)
            ci_s = cho_solve(cf, sig[:, i])
            e = (ones @ ci_s) / (ones @ ci1)
            r = sig[:, i] - e
            z2 += r @ cho_solve(cf, r)
        return float(np.sqrt(z2))

    ctx = capture_ctx(k, fs, series, trel, tnoise, hold_idx, temp, tkind, gunit, mode=mode)

    def write(amp, path, scale_noise=1.0):
        gy = gyro_of(amp)
        gy = gy + np.stack([noise_series(rng, trel.size, fs, noise[i]) for i in range(3)], 1) * scale_noise
        acc_err = (np.eye(3) + rng.normal(0, 0.003, (3, 3))) @ np.eye(3)
        acc = (f_body @ acc_err.T + rng.normal(0, 0.03, 3)) + rng.normal(0, 0.02, f_body.shape)
        meta = {"gyro_unit": gunit, "accel_unit": aunit}
        cols = {
            "gx": gy[:, 0] * gsc,
            "gy": gy[:, 1] * gsc,
            "gz": gy[:, 2] * gsc,
            "ax": acc[:, 0] * asc,
            "ay": acc[:, 1] * asc,
            "az": acc[:, 2] * asc,
        }
        extra, extra_dec = {}, {}
        if mode == "A":
            meta["gyro_mode"] = "reference"
            ref = w_body + rng.normal(0, 2e-7, w_body.shape)
            for i, c in enumerate(("ref_gx", "ref_gy", "ref_gz")):
                extra[c] = ref[:, i]
                extra_dec[c] = 10
        else:
            meta["gyro_mode"] = "static"
            if mode == "B":
                meta["latitude_deg"] = f"{lat:.5f}"
                meta["longitude_deg"] = f"{rng.uniform(-180, 180):.4f}"
                meta["altitude_m"] = f"{rng.uniform(0, 1200):.0f}"
            elif no_heading:
                meta["latitude_deg"] = f"{lat:.5f}"
            hd = heads[prev]
            if not no_heading and (mode == "B" or rng.random() < 0.5):
                extra["heading_deg"] = np.round(hd, 2)
                extra_dec["heading_deg"] = 2
        dec = 9 if gunit == "rad/s" else 7
        cols_dec = {c: (dec if c.startswith("g") else 6) for c in cols}
        extra_dec.update({c: d for c, d in cols_dec.items() if c.startswith("a")})
        extra.update({c: cols.pop(c) for c in ("ax", "ay", "az")})
        write_capture(rng, path, "gyro-drift", meta, cols, ctx, decimals=dec, extra_cols=extra, extra_dec=extra_dec)

    return zfun, write, ctx, eff


# ---------------------------------------------------------------- one capture

BUILDERS = {"P1": build_p1, "P2": build_p2, "P4": build_p4}


def make_one(proc: str, effect: str, z_target: float, seed: int, out: str, no_heading: bool = False) -> dict:
    if seed < 700000:
        raise SystemExit("seeds 700000 and up only")
    rng = np.random.default_rng(seed)
    zfun, write, ctx, eff = BUILDERS[proc](rng, effect, **({"no_heading": True} if no_heading else {}))
    info = {
        "procedure": proc,
        "effect": effect,
        "z_target": z_target,
        "seed": seed,
        "file": str(out),
        "series": bool(ctx["series"]),
        "k": int(ctx["k"]),
        "fs": ctx["fs"],
        "temperature": ctx["tkind"],
        "unit": str(ctx["unit"]),
    }
    if "mode" in ctx:
        info["mode"] = str(ctx["mode"])
    if effect == "none":
        write(0.0, out)
        info["z"] = 0.0
    elif effect == "earth_rate":
        z1 = zfun(0.0)
        scale = z1 / z_target
        info["z"] = zfun(0.0, scale_noise=scale)
        info["noise_scale"] = scale
        write(0.0, out, scale_noise=scale)
    else:
        amp = 1e-6
        for _ in range(3):
            z = zfun(amp)
            if z <= 0:
                amp *= 1e3
                continue
            amp *= z_target / z
        info["z"] = zfun(amp)
        info["amp"] = amp
        write(amp, out)
    return info


def applicable(proc: str, effect: str) -> bool:
    return True


def batch(out_dir: Path, per_cell: int, nulls: int, zs: list[float], seed0: int, procs: list[str]):
    out_dir.mkdir(parents=True, exist_ok=True)
    manifest = []
    seed = seed0
    for proc in procs:
        jobs = [(e, z) for e in EFFECTS[proc] for z in zs for _ in range(per_cell)] + [("none", 0.0)] * nulls
        for eff, z in jobs:
            name = f"{proc}_{eff}_z{z:g}_{seed}.csv"
            info = make_one(proc, eff, z, seed, str(out_dir / name))
            manifest.append(info)
            print(json.dumps(info), flush=True)
            seed += 1
    with open(out_dir / "manifest.jsonl", "a") as fh:
        for info in manifest:
            fh.write(json.dumps(info) + "\n")


def run(out_dir: Path, jobs: int, station: list[str]):
    man = [json.loads(x) for x in (out_dir / "manifest.jsonl").read_text().splitlines()]

    def one(info):
        res = Path(info["file"]).with_suffix(".json")
        if res.exists():
            return
        p = subprocess.run(
            ["nice", "-n", "10", *station, "diagnose", info["file"], "--json", "--no-plots"],
            capture_output=True,
            text=True,
        )
        rec = {"rc": p.returncode, "stderr": p.stderr[-2000:]}
        if p.returncode == 0:
            try:
                rec["out"] = json.loads(p.stdout)
            except json.JSONDecodeError:
                rec["bad_stdout"] = p.stdout[:2000]
        res.write_text(json.dumps(rec))
        print(info["file"], p.returncode, (rec.get("out") or {}).get("verdict"), flush=True)

    with ThreadPoolExecutor(jobs) as ex:
        list(ex.map(one, man))


def table(out_dir: Path):
    man = [json.loads(x) for x in (out_dir / "manifest.jsonl").read_text().splitlines()]
    cells: dict = {}
    fails = []
    for info in man:
        res = Path(info["file"]).with_suffix(".json")
        if not res.exists():
            continue
        rec = json.loads(res.read_text())
        key = (info["procedure"], info["effect"], info["z_target"])
        c = cells.setdefault(key, {"n": 0, "named": 0, "extra": 0, "clean": 0, "error": 0})
        c["n"] += 1
        if rec["rc"] != 0:
            c["error"] += 1
            fails.append((info, f"rc={rec['rc']} {rec['stderr'].strip().splitlines()[-1:]}"))
            continue
        verdict = rec["out"].get("verdict", [])
        exp = expected_name(info["effect"])
        named = exp in verdict if exp else False
        # names the report ties to the expected one (confused_with: the data cannot tell them apart)
        tied = {
            c["name"] for e in rec["out"].get("effects", []) if e["name"] == exp for c in e.get("confused_with", [])
        } | {e["name"] for e in rec["out"].get("effects", []) for c in e.get("confused_with", []) if c["name"] == exp}
        c["tied"] = c.get("tied", 0) + bool(named and tied & set(verdict))
        extra = [v for v in verdict if v != exp and v not in tied]
        c["named"] += named
        c["extra"] += bool(extra)
        c["clean"] += (named and not extra) if exp else not verdict
        c["null_named"] = c.get("null_named", 0) + (not exp and bool(verdict))
        if (exp and not named) or (not exp and verdict):
            fails.append((info, verdict))
    print("| procedure | effect | z | n | named | named with a tie | wrong extra | clean | errors |")
    print("|---|---|---|---|---|---|---|---|---|")
    for (p, e, z), c in sorted(cells.items(), key=lambda kv: (kv[0][0], kv[0][1] == "none", -kv[0][2], kv[0][1])):
        zs = "-" if e == "none" else f"{z:g}"
        named = f"{c['named']}/{c['n']}" if e != "none" else f"{c.get('null_named', 0)}/{c['n']} named"
        print(
            f"| {p} | {e} | {zs} | {c['n']} | {named} | {c.get('tied', 0)} | {c['extra']} | {c['clean']} | {c['error']} |"
        )
    print()
    for info, v in fails:
        print(
            f"{Path(info['file']).name}: {v}  (series={info['series']} k={info['k']} T={info['temperature']} "
            f"unit={info['unit']}{' mode=' + info['mode'] if 'mode' in info else ''})"
        )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    o = sub.add_parser("one")
    o.add_argument("--procedure", choices=["P1", "P2", "P4"], required=True)
    o.add_argument("--effect", default="none")
    o.add_argument("--z", type=float, default=10.0)
    o.add_argument("--seed", type=int, required=True)
    o.add_argument("--out", required=True)
    o.add_argument("--no-heading", action="store_true", help="P4 mode B: no heading_deg column (latitude only)")
    b = sub.add_parser("batch")
    b.add_argument("--out", required=True)
    b.add_argument("--per-cell", type=int, default=4)
    b.add_argument("--nulls", type=int, default=20)
    b.add_argument("--z", type=float, nargs="+", default=[10.0])
    b.add_argument("--seed0", type=int, default=700000)
    b.add_argument("--procedures", nargs="+", default=["P1", "P2", "P4"])
    r = sub.add_parser("run")
    r.add_argument("dir")
    r.add_argument("--jobs", type=int, default=2)
    t = sub.add_parser("table")
    t.add_argument("dir")
    a = ap.parse_args(argv)
    if a.cmd == "one":
        print(json.dumps(make_one(a.procedure, a.effect, a.z, a.seed, a.out, a.no_heading)))
    elif a.cmd == "batch":
        batch(Path(a.out), a.per_cell, a.nulls, a.z, a.seed0, a.procedures)
    elif a.cmd == "run":
        station = [str(Path(sys.executable).parent / "station")]
        os.environ.setdefault("STATION_SHARED", "/work/shared")
        os.environ["PYTHONPATH"] = str(Path(__file__).resolve().parents[1])
        run(Path(a.dir), a.jobs, station)
    else:
        table(Path(a.dir))


if __name__ == "__main__":
    main()
