"""Captures of shapes benchmarks/diag_generator.py never writes, for ``calibrate`` and ``diagnose``.

An independent tester's simulator and real logs differ from ours in the layout of the file
as much as in the physics. This script draws, per procedure, a capture with the physics of
the shared forward models (``solvers.models``: one model) and varies what the capture format
(capture-format.md) allows: column order, unknown columns and metadata keys, a time origin
at the epoch or a large offset, jittered sample times and a dropped block, integer ADC
counts, other units, no ``temp_c`` or a quantised and lagging one, text or revisited position
labels, tables of averages, missing values, CRLF, a BOM, trailing commas, odd ``#`` spacing,
very short and very long captures, quiet and noisy devices. Each case is written once with no
hidden effect (a null) and once with a large canonical one, then run through the real
``station calibrate`` and ``station diagnose`` and compared with the simulated truth.

    python benchmarks/redteam_captures.py [--procedure P] [--case NAME] [--keep DIR] [--seed S]
        [--effects null,big,NAME]

``--effects``: ``null`` (no effect), ``big`` (the procedure's large effects below), or an
effect the generator draws by name (compass: ``time_varying_hard_iron``, ``time_drift``,
``mag_accel_misalignment`` besides the two run by default).

Prints one line per run: exit status, what is wrong (traceback, refusal, NaN, stray stdout,
calibration far from truth, a verdict on a null, a large effect not named).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from solvers import frames  # noqa: E402
from solvers.geomag import field_ned, igrf_reference  # noqa: E402
from solvers.models import Conditions  # noqa: E402
from solvers.models import accel as accel_model  # noqa: E402
from solvers.models import gyro as gyro_model  # noqa: E402
from solvers.models import ldv as ldv_model  # noqa: E402
from solvers.models import mag as mag_model  # noqa: E402
from solvers.positions import C_n_b_for  # noqa: E402

SITE = (45.5, 9.2, 120.0)


# ------------------------------------------------------------------ shared bits


def temperature(rng, t, kind, quantum=0.0, lag_s=0.0):
    """(die temperature the physics sees, the temperature the column records)."""
    span = max(float(t[-1] - t[0]), 1.0)
    x = (t - t[0]) / span
    if kind == "warmup":
        die = 24.0 + 12.0 * (1 - np.exp(-x * 3))
    elif kind == "cycle":
        die = 25.0 + 6.0 * np.sin(2 * np.pi * x * 2.3)
    else:
        die = 25.0 + 0.02 * rng.normal(size=len(t))
    rec = die.copy()
    if lag_s > 0:
        a = np.exp(-np.diff(t, prepend=t[0]) / lag_s)
        for i in range(1, len(rec)):
            rec[i] = a[i] * rec[i - 1] + (1 - a[i]) * die[i]
    if quantum > 0:
        rec = np.round(rec / quantum) * quantum
    return die, rec


def times(rng, n, rate, jitter=0.0, gap=None, origin=0.0):
    """Sample times: nominal grid, jitter (fraction of the period), a dropped block (i0, i1)."""
    t = np.arange(n) / rate
    if jitter:
        t = t + rng.uniform(0, jitter / rate, n)
        t = np.maximum.accumulate(t)
    keep = np.ones(n, bool)
    if gap is not None:
        keep[gap[0] : gap[1]] = False
    return t + origin, keep


def coarse(t, resolution_s):
    """Time stamps written with a coarse resolution (host clock ticks, whole seconds): many rows
    share one value; ``t`` stays non-decreasing, as capture-format.md asks."""
    return np.floor(t / resolution_s) * resolution_s if resolution_s else t


def slerp_dirs(d0, d1, n):
    w = np.linspace(0, 1, n + 2)[1:-1, None]
    v = (1 - w) * d0 + w * d1
    return v / np.linalg.norm(v, axis=1, keepdims=True)


# ------------------------------------------------------------------ P1


P1_DIRS = {
    "x_up": (1, 0, 0),
    "x_down": (-1, 0, 0),
    "y_up": (0, 1, 0),
    "y_down": (0, -1, 0),
    "z_up": (0, 0, 1),
    "z_down": (0, 0, -1),
    "xy_45": (1, 1, 0),
    "xy_135": (-1, 1, 0),
    "yz_45": (0, 1, 1),
    "yz_135": (0, -1, 1),
    "xz_45": (1, 0, 1),
    "xz_135": (-1, 0, 1),
}


def p1(rng, o, effect):
    """P1 on a level table; the raw output is ``forward`` of the accel model (V or counts).

    f is the specific force in the body frame (the sensor reads +g along the up axis)."""
    g = frames.normal_gravity_mps2(SITE[0], SITE[2])
    names = list(P1_DIRS)
    dirs = [np.array(P1_DIRS[k], float) for k in names]
    n_pos = o.get("n_pos", 12)
    while len(dirs) < n_pos:
        v = rng.normal(size=3)
        dirs.append(v)
        names.append(f"extra {len(dirs)}")
    dirs, names = [d / np.linalg.norm(d) for d in dirs[:n_pos]], names[:n_pos]
    if o.get("revisit"):
        dirs.append(dirs[0])
        names.append(names[0])
    rate, hold, move = o.get("rate", 100.0), o.get("hold_s", 20.0), o.get("move_s", 3.0)
    unit = o.get("unit", "V")
    per = {"V": 0.033, "counts": 16384 / 9.80665, "g": 1 / 9.80665}[unit]
    off = {"V": 1.65, "counts": 0.0, "g": 0.0}[unit]
    K = (np.eye(3) + rng.normal(scale=0.01, size=(3, 3))) * per * rng.uniform(0.95, 1.05, 3)[:, None]
    b = off + rng.normal(scale=0.2, size=3) * per
    hid, F = [], []
    for k, d in enumerate(dirs):
        C = C_n_b_for(d, rng.uniform(0, 2 * np.pi)) @ frames.rotvec_to_matrix(rng.normal(scale=0.005, size=3))
        fk = C.T @ np.array([0.0, 0.0, -g])
        if k:
            mv = int(move * rate)
            F.append(slerp_dirs(F[-1][-1] / g, fk / g, mv) * g + rng.normal(scale=0.5, size=(mv, 3)))
            hid += [-1] * mv
        F.append(np.repeat(fk[None], int(hold * rate), axis=0))
        hid += [k] * int(hold * rate)
    f = -np.concatenate(F)  # specific force: opposite to gravity's direction in the body
    hid = np.array(hid)
    n = len(f)
    t, keep = times(rng, n, rate, o.get("jitter", 0.0), o.get("gap"), o.get("t0", 0.0))
    die, rec = temperature(rng, t, o.get("temp", "warmup"), o.get("temp_q", 0.0), o.get("temp_lag", 0.0))
    params = {"K": K, "b": b}
    Kd = np.diag(K)
    if effect == "temperature_bias":
        params["bT"] = Kd * np.array([0.01, -0.008, 0.012])  # 10 mm/s² per °C
    elif effect == "time_drift":
        params["bt"] = Kd * np.array([0.06, -0.05, 0.04]) / (t[-1] - t[0])  # 50 mm/s² over the capture
    elif effect == "quadratic":
        params["D"] = np.array([2e-3, -1.5e-3, 1.8e-3])
    cond = Conditions(t_s=t - t[0], temp_c=die, temp_ref_c=25.0, t_ref_s=0.0)
    y = accel_model.forward(f, params, cond) + rng.normal(scale=o.get("noise", 0.01), size=(n, 3)) @ K.T
    if unit == "counts":
        y = np.round(y)
    B, M = accel_model.forward_to_p1({"K": K, "b": b})
    lab = np.array([names[k] if k >= 0 else "" for k in hid], dtype=object)
    meta = {"procedure": "accel-tabletop", "accel_unit": unit, "latitude_deg": SITE[0], "altitude_m": SITE[2]}
    if o.get("averages"):
        cols = {"position": [], "n": [], "temp_c": []}
        for c in "xyz":
            cols[f"a{c}"], cols[f"a{c}_std"] = [], []
        for k in range(len(dirs)):
            m = (hid == k) & keep
            cols["position"].append(names[k] if o.get("labels", True) else str(k + 1))
            cols["n"].append(float(m.sum()))
            cols["temp_c"].append(rec[m].mean())
            for j, c in enumerate("xyz"):
                cols[f"a{c}"].append(y[m, j].mean())
                cols[f"a{c}_std"].append(y[m, j].std(ddof=1))
        cols = {k: np.array(v, dtype=object if k == "position" else float) for k, v in cols.items()}
    else:
        cols = {"t": t, "ax": y[:, 0], "ay": y[:, 1], "az": y[:, 2], "temp_c": rec}
        if o.get("labels", True):
            cols["position"] = lab
        cols = {k: v[keep] for k, v in cols.items()}
    if o.get("no_temp"):
        cols.pop("temp_c")
    return meta, cols, {"B": B, "M": M}


def p1_check(res, truth):
    M, B = np.array(res["params"]["M"]), np.array(res["params"]["B"])
    Mt, Bt = truth["M"], truth["B"]
    # rotation gauge: compare M^T M and M^T B
    e1 = np.abs(M.T @ M - Mt.T @ Mt).max() / np.abs(Mt.T @ Mt).max()
    e2 = np.abs(M.T @ B - Mt.T @ Bt).max() / max(np.abs(Mt.T @ Bt).max(), 1e-9)
    return f"MtM {e1:.1e} MtB {e2:.1e}", e1 > 2e-3


# ------------------------------------------------------------------ P2


def p2(rng, o, effect):
    gg = 9.80
    R = o.get("radius", 1.0)
    speeds = o.get("speeds", [2 * math.pi, 4 * math.pi, 6 * math.pi])
    n_m = o.get("n_m", 20)
    atts = [frames.rotvec_to_matrix(rng.normal(size=3) * 2.0) for _ in range(n_m)]
    S, b, D = np.array([1.29, 1.21, 1.26]), np.array([0.213, 0.256, 0.516]), np.array([5.7e-5, 3.1e-5, 4.5e-5])
    rows = [(m, w) for w in speeds for m in range(n_m)]
    f = np.array([atts[m].T @ np.array([-w * w * R / gg, 0.0, 1.0]) for m, w in rows])
    c = np.array([atts[m].T @ np.array([-1.0, 0.0, 0.0]) for m, _ in rows])
    ws = np.array([w for _, w in rows])
    n = len(f)
    el = np.arange(n) * 120.0 + o.get("t0", 0.0)
    die, rec = temperature(rng, el, o.get("temp", "warmup"), o.get("temp_q", 0.0))
    params = {"S": S, "b": b, "D": D}
    if effect == "temperature_bias":
        params["bT"] = np.array([2e-4, -3e-4, 2.5e-4])
    elif effect == "misalignment":
        params["gamma"] = np.array([5e-3, -4e-3, 3e-3, 6e-3, -5e-3, 4e-3])
    cond = Conditions(
        t_s=el - el[0], temp_c=die, temp_ref_c=25.0, input_unit_mps2=gg, omega_rad_s=ws, centripetal_dir=c
    )
    y = accel_model.forward(f, params, cond) + rng.normal(scale=o.get("noise", 1e-5), size=(n, 3))
    meta = {"procedure": "accel-centrifuge", "accel_unit": "g", "radius_m": R, "g_mps2": gg}
    cols = {"position": np.array([f"mount {m + 1}" for m, _ in rows], dtype=object), "speed_rad_s": ws}
    for j, a in enumerate("xyz"):
        cols[f"a{a}"] = y[:, j]
    cols["temp_c"] = rec
    if o.get("averages"):
        cols["n"] = np.full(n, 500.0)
        for a in "xyz":
            cols[f"a{a}_std"] = np.full(n, o.get("noise", 1e-5) * math.sqrt(500))
    if o.get("no_temp"):
        cols.pop("temp_c")
    return meta, cols, {"S": S, "b": b, "D": D}


def p2_check(res, truth):
    p = res["params"]
    eS = np.abs(np.array(p["S"]) - truth["S"]).max()
    eb = np.abs(np.array(p["b"]) - truth["b"]).max()
    eD = np.abs(np.array(p["D"]) - truth["D"]).max()
    return f"S {eS:.1e} b {eb:.1e} D {eD:.1e}", eS > 1e-3 or eb > 1e-3 or eD > 2e-5


# ------------------------------------------------------------------ compass


def compass(rng, o, effect):
    lat, lon, alt = SITE
    ref = igrf_reference(lat, lon, alt, "2026-06-01")
    m_ned = field_ned(ref)
    g = frames.normal_gravity_mps2(lat, alt)
    unit = o.get("unit", "uT")
    ku = {"nT": 1.0, "uT": 1e-3, "gauss": 1e-5, "counts": 1 / 150.0}[unit]
    n_h, rate, hold, move = o.get("n_h", 14), o.get("rate", 50.0), o.get("hold_s", 4.0), o.get("move_s", 2.0)
    atts = [frames.rotvec_to_matrix(rng.normal(size=3) * 1.5) for _ in range(n_h)]
    hid, Cs = [], []
    for k, C in enumerate(atts):
        if k:
            mv = int(move * rate)
            a = frames.matrix_to_rotvec(atts[k - 1].T @ C)
            Cs += [atts[k - 1] @ frames.rotvec_to_matrix(a * s) for s in np.linspace(0, 1, mv + 2)[1:-1]]
            hid += [-1] * mv
        Cs += [C] * int(hold * rate)
        hid += [k] * int(hold * rate)
    C_all = np.array(Cs)  # body → NED
    hid = np.array(hid)
    n = len(C_all)
    t, keep = times(rng, n, rate, o.get("jitter", 0.0), o.get("gap"), o.get("t0", 0.0))
    C_b_n = np.transpose(C_all, (0, 2, 1))
    f_b = C_b_n @ np.array([0.0, 0.0, -g])
    die, rec = temperature(rng, t, o.get("temp", "warmup"), o.get("temp_q", 0.0), o.get("temp_lag", 0.0))
    W = np.eye(3) + np.triu(rng.normal(scale=0.05, size=(3, 3)))
    h = rng.normal(scale=5000, size=3)
    params = {"W": W, "h": h}
    if effect == "temperature_bias":
        params["bT"] = np.array([300.0, -250.0, 280.0])  # nT/°C
    elif effect == "time_drift":
        params["bt"] = np.array([3000.0, -2500.0, 2000.0]) / (t[-1] - t[0])
    elif effect == "mag_accel_misalignment":
        params["rho"] = np.radians([0.8, -0.6, 0.5])  # the magnetometer turned about 1.1° against the accelerometer
    elif effect == "time_varying_hard_iron":
        # a hard iron that steps by about 850 nT part-way (a part near the sensor magnetised, a
        # battery swapped): 5.7 counts of 150 nT
        params["dh"] = o.get("dh_scale", 1.0) * np.array([600.0, -450.0, 400.0])
        params["t_on_s"] = np.array(0.45 * (t[-1] - t[0]))
    elif effect == "field_anomaly":
        # a bent field: 6 % stronger and 1.5° steeper than IGRF (a magnitude change alone is a
        # common scale of W that no single capture can see; docs/diagnose.md)
        m_ned = 1.06 * (frames.rotvec_to_matrix(np.array([0.0, -math.radians(1.5), 0.0])) @ m_ned)
    cond = Conditions(t_s=t - t[0], temp_c=die, temp_ref_c=25.0)
    y = mag_model.forward(C_b_n @ m_ned, params, cond) + rng.normal(scale=o.get("noise", 60.0), size=(n, 3))
    y = y * ku
    if unit == "counts":
        y = np.round(y)
    acc = f_b + rng.normal(scale=0.02, size=(n, 3))
    if o.get("lin_acc"):
        # a hand's own acceleration: smooth (about 1 s), of RMS lin_acc per axis
        k = max(1, int(rate))
        w = np.array([np.convolve(rng.normal(size=n + k), np.ones(k) / math.sqrt(k), "valid")[:n] for _ in range(3)]).T
        acc = acc + o["lin_acc"] * w
    meta = {
        "procedure": "compass",
        "accel_unit": "m/s^2",
        "mag_unit": unit,
        "latitude_deg": lat,
        "longitude_deg": lon,
        "altitude_m": alt,
        "date": "2026-06-01",
    }
    cols = {"t": t, "ax": acc[:, 0], "ay": acc[:, 1], "az": acc[:, 2]}
    cols.update({"mx": y[:, 0], "my": y[:, 1], "mz": y[:, 2], "temp_c": rec})
    if o.get("labels"):
        cols["position"] = np.array([f"hold {k + 1}" if k >= 0 else "" for k in hid], dtype=object)
    cols = {k: v[keep] for k, v in cols.items()}
    if o.get("no_temp"):
        cols.pop("temp_c")
    return meta, cols, {"h": h * ku, "W": W / ku}


def compass_check(res, truth):
    p = res["params"]
    h, W = np.array(p["hard_iron"]), np.array(p["soft_iron"])
    eh = np.abs(h - truth["h"]).max() / np.abs(truth["h"]).max()
    WtW, Tt = W.T @ W, truth["W"].T @ truth["W"]
    eW = np.abs(WtW - Tt).max() / np.abs(Tt).max()
    return f"h {eh:.1e} WtW {eW:.1e}", eh > 0.02 or eW > 0.02


# ------------------------------------------------------------------ P4


def p4(rng, o, effect):
    lat = SITE[0]
    g = frames.normal_gravity_mps2(lat, SITE[2])
    rate, dur = o.get("rate", 100.0), o.get("duration_s", 300.0)
    n = int(rate * dur)
    t, keep = times(rng, n, rate, o.get("jitter", 0.0), o.get("gap"), o.get("t0", 0.0))
    t_written = coarse(t, o.get("t_res", 0.0))
    die, rec = temperature(rng, t, o.get("temp", "warmup"), o.get("temp_q", 0.0), o.get("temp_lag", 0.0))
    eps = rng.normal(scale=0.003, size=3)
    params = {"eps": eps}
    if effect == "temperature_bias":
        params["bT"] = np.array([2e-4, -1.5e-4, 1.8e-4])
    elif effect == "time_drift":
        params["bt"] = np.array([3e-3, -2e-3, 2.5e-3]) / (t[-1] - t[0])
    cond = Conditions(t_s=t - t[0], temp_c=die, temp_ref_c=25.0)
    unit = o.get("unit", "rad/s")
    k = {"rad/s": 1.0, "deg/s": 180 / math.pi, "counts": 131 * 180 / math.pi}[unit]
    meta = {"procedure": "gyro-drift", "gyro_unit": unit, "latitude_deg": lat, "longitude_deg": SITE[1]}
    if o.get("mode") == "A":
        # a reference IMU on a moving base: true rate = smooth motion; the reference reads it
        w = np.column_stack([0.3 * np.sin(2 * np.pi * t / p + ph) for p, ph in ((7.0, 0), (11.0, 1), (5.0, 2))])
        y = gyro_model.forward(w, params, cond) + rng.normal(scale=o.get("noise", 2e-3), size=(n, 3))
        ref = w + rng.normal(scale=1e-5, size=(n, 3))
        meta["gyro_mode"] = "reference"
        cols = {"t": t_written, "gx": y[:, 0] * k, "gy": y[:, 1] * k, "gz": y[:, 2] * k}
        cols.update({"ref_gx": ref[:, 0], "ref_gy": ref[:, 1], "ref_gz": ref[:, 2]})
    else:
        p, r = math.radians(o.get("pitch", 3.0)), math.radians(o.get("roll", -2.0))
        C = frames.p4_C_n_b(p, r, math.radians(o.get("heading", 0.0)))
        w = np.repeat((C.T @ frames.earth_rate_nue(lat))[None], n, axis=0)
        y = gyro_model.forward(w, params, cond) + rng.normal(scale=o.get("noise", 2e-3), size=(n, 3))
        f = C.T @ np.array([0.0, g, 0.0])
        acc = f + rng.normal(scale=0.02, size=(n, 3))
        meta.update({"gyro_mode": "static", "accel_unit": "m/s^2", "heading_deg": o.get("heading", 0.0)})
        cols = {"t": t_written, "ax": acc[:, 0], "ay": acc[:, 1], "az": acc[:, 2]}
        cols.update({"gx": y[:, 0] * k, "gy": y[:, 1] * k, "gz": y[:, 2] * k})
    if unit == "counts":
        for c in ("gx", "gy", "gz"):
            cols[c] = np.round(cols[c])
    cols["temp_c"] = rec
    cols = {c: v[keep] for c, v in cols.items()}
    if o.get("no_temp"):
        cols.pop("temp_c")
    return meta, cols, {"eps": eps, "tol": 5 * o.get("noise", 2e-3) / math.sqrt(keep.sum()) + 1e-6}


def p4_check(res, truth):
    d = np.array(res["params"]["drift"])
    e = np.abs(d - truth["eps"]).max()
    return f"drift {e:.1e} (tol {truth['tol']:.1e})", e > truth["tol"] * (1 if "effect" not in truth else 50)


# ------------------------------------------------------------------ LDV


def ldv(rng, o, effect):
    rate, dur = o.get("rate", 20.0), o.get("duration_s", 600.0)
    n = int(rate * dur)
    t, keep = times(rng, n, rate, o.get("jitter", 0.0), o.get("gap"), o.get("t0", 0.0))
    tt = t - t[0]
    knots = np.linspace(0, tt[-1], int(dur / 20) + 2)
    spd = np.interp(tt, knots, rng.uniform(3, 25, len(knots)))
    yaw_rate = np.interp(tt, knots, rng.normal(scale=0.12, size=len(knots)))
    pitch = np.interp(tt, knots, rng.normal(scale=0.04, size=len(knots)))
    roll = 0.15 * yaw_rate * spd / 10
    side = 0.1 * spd * yaw_rate + 0.8 * np.sin(2 * np.pi * tt / 23.0)
    vert = spd * np.sin(pitch) * 0.2 + 0.6 * np.sin(2 * np.pi * tt / 17.0)
    v_b = np.column_stack([spd, side, vert])
    w_b = np.column_stack([np.gradient(roll, tt), np.gradient(pitch, tt), yaw_rate])
    al, be = np.radians([60.0, 120.0, 90.5]), np.radians([90.0, 90.0, 60.0])
    u = np.column_stack([np.cos(al), np.cos(be), np.sqrt(1 - np.cos(al) ** 2 - np.cos(be) ** 2)])
    X = (1 + np.array([0.01, -0.005, 0.008]))[:, None] * u
    die, rec = temperature(rng, t, o.get("temp", "warmup"), o.get("temp_q", 0.0), o.get("temp_lag", 0.0))
    params = {"X": X}
    if effect == "temperature_bias":
        params["bT"] = np.array([0.02, -0.015, 0.018])
    elif effect == "time_drift":
        params["bt"] = np.array([0.3, -0.25, 0.2]) / tt[-1]
    elif effect == "offset":
        params["o"] = np.array([0.1, -0.08, 0.12])
    cond = Conditions(t_s=tt, temp_c=die, temp_ref_c=25.0, omega_body_rad_s=w_b)
    noise = o.get("noise", 0.01)
    y = ldv_model.forward(v_b, params, cond) + rng.normal(scale=noise, size=(n, 3))
    v_ref = v_b + rng.normal(scale=noise / 4, size=(n, 3))
    meta = {"procedure": "ldv", "latitude_deg": SITE[0], "longitude_deg": SITE[1]}
    cols = {"t": t, "vl1": y[:, 0], "vl2": y[:, 1], "vl3": y[:, 2]}
    if o.get("nav"):
        yaw = np.cumsum(yaw_rate) / rate
        C = np.stack([frames.euler_to_C_n_b(r, p, q) for r, p, q in zip(roll, pitch, yaw)])
        v_n = np.einsum("nij,nj->ni", C, v_ref)
        cols.update({"vn": v_n[:, 0], "ve": v_n[:, 1], "vd": v_n[:, 2]})
        cols.update({"roll_deg": np.degrees(roll), "pitch_deg": np.degrees(pitch), "yaw_deg": np.degrees(yaw)})
    else:
        cols.update({"vx": v_ref[:, 0], "vy": v_ref[:, 1], "vz": v_ref[:, 2]})
    if o.get("rates"):
        cols.update({"wx": w_b[:, 0], "wy": w_b[:, 1], "wz": w_b[:, 2]})
    cols["temp_c"] = rec
    cols = {c: v[keep] for c, v in cols.items()}
    if o.get("no_temp"):
        cols.pop("temp_c")
    return meta, cols, {"X": X}


def ldv_check(res, truth):
    """Largest error (degrees, or % of dK) and largest error in units of the reported σ: far when
    both exceed their bars (a 60 s drive's σ is 0.02-0.03°: 0.05° is 2σ there, not far)."""
    p, u = res["params"], res.get("uncertainty", {})
    a = ldv_model.angles_from_X(truth["X"])
    e = z = 0.0
    for j in range(3):
        bj, sj = p[f"beam{j + 1}"], u.get(f"beam{j + 1}", {})
        for k, f in (("dK", 100.0), ("alpha_deg", 1.0), ("beta_deg", 1.0), ("gamma_deg", 1.0)):
            err = abs(bj[k] - a[k][j])
            e = max(e, err * f)
            s = sj.get(k)
            z = max(z, err / s if isinstance(s, (int, float)) and s > 0 else math.inf)
    return f"angle/dK% err {e:.2e} ({z:.1f}σ)", e > 0.05 and z > 4.0


PROCS = {
    "accel-tabletop": (p1, p1_check, ("temperature_bias", "time_drift")),
    "accel-centrifuge": (p2, p2_check, ("temperature_bias", "misalignment")),
    "compass": (compass, compass_check, ("temperature_bias", "field_anomaly")),
    "gyro-drift": (p4, p4_check, ("temperature_bias", "time_drift")),
    "ldv": (ldv, ldv_check, ("temperature_bias", "offset")),
}

# per-case generator options and file-format options
CASES = {
    "accel-tabletop": {
        "plain": {},
        "counts_epoch_jitter": {"unit": "counts", "t0": 1.7e9, "jitter": 0.3},
        "gap_tempq_lag": {"gap": (3000, 4500), "temp_q": 0.0625, "temp_lag": 60.0},
        "no_temp_unlabelled": {"no_temp": True, "labels": False},
        "revisit": {"revisit": True},
        "nine": {"n_pos": 9},
        "thirty": {"n_pos": 30, "hold_s": 10.0},
        "averages": {"averages": True},
        "averages_numeric_labels": {"averages": True, "labels": False},
        "short_holds": {"hold_s": 3.0, "rate": 50.0},
        "noisy": {"noise": 0.1},
        "quiet": {"noise": 0.0005},
        "counts_quiet": {"unit": "counts", "noise": 0.0003},
        "unit_g_offset": {"unit": "g", "t0": 5000.0},
        "epoch_whole_seconds": {"t0": 1.7e9, "t_res": 1.0},
        "whole_seconds_unlabelled": {"t_res": 1.0, "labels": False},
    },
    "accel-centrifuge": {
        "plain": {},
        "averages": {"averages": True},
        "no_temp": {"no_temp": True},
        "tempq_t0": {"temp_q": 0.0625},
        "small": {"n_m": 6, "speeds": [3.0, 9.0, 15.0]},
        "noisy": {"noise": 1e-4},
    },
    "compass": {
        "plain": {},
        "gauss_epoch_jitter": {"unit": "gauss", "t0": 1.7e9, "jitter": 0.3},
        "nT_gap_labels": {"unit": "nT", "gap": (200, 400), "labels": True},
        "counts_tempq": {"unit": "counts", "temp_q": 0.0625, "temp_lag": 30.0},
        "no_temp": {"no_temp": True},
        "epoch_whole_seconds": {"t0": 1.7e9, "t_res": 1.0},
        "whole_seconds_labels": {"t_res": 1.0, "labels": True},
        "short": {"n_h": 9, "hold_s": 1.5, "rate": 25.0},
        "tumbling": {"n_h": 40, "hold_s": 0.0, "move_s": 1.5},
        "tumbling_hand": {"n_h": 40, "hold_s": 0.0, "move_s": 1.5, "lin_acc": 0.2},
        "noisy": {"noise": 400.0},
        "counts_quiet": {"unit": "counts", "noise": 20.0},
    },
    "gyro-drift": {
        "plain_B": {},
        "B_deg_epoch": {"unit": "deg/s", "t0": 1.7e9, "jitter": 0.3},
        "B_counts_gap_tempq": {"unit": "counts", "gap": (10000, 12000), "temp_q": 0.0625, "temp_lag": 60.0},
        "B_no_temp": {"no_temp": True},
        "B_short": {"duration_s": 20.0},
        "B_counts_quiet": {"unit": "counts", "noise": 2e-5},
        "B_epoch_whole_seconds": {"t0": 1.7e9, "t_res": 1.0},
        "A_epoch_whole_seconds": {"mode": "A", "t0": 1.7e9, "t_res": 1.0},
        "A": {"mode": "A"},
        "A_deg_epoch_jitter": {"mode": "A", "unit": "deg/s", "t0": 1.7e9, "jitter": 0.3},
        "A_gap_no_temp": {"mode": "A", "gap": (5000, 8000), "no_temp": True},
        "A_short": {"mode": "A", "duration_s": 30.0},
        "B_long_2h": {"duration_s": 7200.0},
    },
    "ldv": {
        "plain": {},
        "nav": {"nav": True},
        "nav_rates_epoch_jitter": {"nav": True, "rates": True, "t0": 1.7e9, "jitter": 0.3},
        "gap_tempq": {"gap": (2000, 3000), "temp_q": 0.0625, "temp_lag": 60.0},
        "no_temp": {"no_temp": True},
        "short": {"duration_s": 60.0},
        "epoch_whole_seconds": {"t0": 1.7e9, "t_res": 1.0, "duration_s": 300.0},
        "noisy": {"noise": 0.1},
    },
}

FORMATS = {
    "plain": {},
    "shuffled_extra": {"shuffle": True, "extra_cols": True, "extra_meta": True},
    "crlf_bom_spacing": {"crlf": True, "bom": True, "spacing": True},
    "trailing_comma": {"trailing": True},
    "empties": {"empties": 3},
}


def _cell(v):
    if isinstance(v, str):
        return v
    if not np.isfinite(v):
        return ""
    return f"{v:.15g}"


def write(path, meta, cols, fmt, rng):
    meta = {"station-capture": "1", **{k: str(v) for k, v in meta.items()}, "device": "RT-1"}
    if fmt.get("extra_meta"):
        meta.update({"operator": "J. Doe", "firmware": "v2.3: build 7", "bench_id": "B-12"})
    cols = dict(cols)
    n = len(next(iter(cols.values())))
    if fmt.get("extra_cols"):
        cols["pressure_hpa"] = 1013 + rng.normal(size=n)
        cols["sample_idx"] = np.arange(n).astype(float)
    names = list(cols)
    if fmt.get("shuffle"):
        names = [names[i] for i in rng.permutation(len(names))]
    text = [[_cell(x) for x in cols[c]] for c in names]
    if fmt.get("empties"):
        for _ in range(fmt["empties"]):
            i = int(rng.integers(1, n - 1))
            j = int(rng.integers(len(names)))
            if names[j] not in ("t", "position"):
                text[j][i] = ""
    eol = "\r\n" if fmt.get("crlf") else "\n"
    tail = "," if fmt.get("trailing") else ""
    out = []
    for i, (k, v) in enumerate(meta.items()):
        out.append(
            f"#{k}:{v}"
            if fmt.get("spacing") and i % 2
            else (f"#   {k}  :   {v}  " if fmt.get("spacing") else f"# {k}: {v}")
        )
    out.append(",".join(names) + tail)
    for i in range(n):
        out.append(",".join(col[i] for col in text) + tail)
    data = eol.join(out) + eol
    raw = data.encode("utf-8")
    if fmt.get("bom"):
        raw = b"\xef\xbb\xbf" + raw
    Path(path).write_bytes(raw)


def run(cmd, path):
    p = subprocess.run(
        [sys.executable, "-m", "station", cmd, str(path), "--json"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=1800,
    )
    problems = []
    if p.returncode not in (0, 2):
        problems.append(f"rc={p.returncode}")
    if "Traceback" in p.stderr:
        problems.append("TRACEBACK")
    res = None
    if p.returncode == 0:
        try:
            res = json.loads(p.stdout)
        except ValueError:
            problems.append("stdout not one JSON")
        if any(w in p.stdout for w in ("NaN", "Infinity")):
            problems.append("NaN/inf")
    elif p.stdout:
        problems.append("stdout on refusal")
    if p.returncode == 2 and p.stderr.count("\n") != 1:
        problems.append("refusal not one line")
    return p, res, problems


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--procedure", action="append")
    ap.add_argument("--case", action="append")
    ap.add_argument("--format", action="append")
    ap.add_argument("--effects", default="null,big")
    ap.add_argument("--keep")
    ap.add_argument("--seed", type=int, default=4242)
    a = ap.parse_args(argv)
    out = Path(a.keep) if a.keep else Path(tempfile.mkdtemp())
    out.mkdir(parents=True, exist_ok=True)
    for proc in a.procedure or PROCS:
        gen, check, effects = PROCS[proc]
        for case, opts in CASES[proc].items():
            if a.case and case not in a.case:
                continue
            for fname, fmt in FORMATS.items():
                if a.format and fname not in a.format:
                    continue
                if fname != "plain" and case not in ("plain", "plain_B", "A", "nav", "averages"):
                    continue
                for which in a.effects.split(","):
                    named = (which,) if which not in ("null", "big") else effects
                    for eff in (None,) if which == "null" else named[:1] if fname != "plain" else named:
                        rng = np.random.default_rng(a.seed)
                        meta, cols, truth = gen(rng, opts, eff)
                        if "t" in cols:
                            cols["t"] = coarse(cols["t"], opts.get("t_res", 0.0))
                        if eff:
                            truth["effect"] = eff
                        path = out / f"{proc}.{case}.{fname}.{eff or 'null'}.capture.csv"
                        write(path, meta, cols, fmt, np.random.default_rng(a.seed + 1))
                        line = [proc, case, fname, eff or "null"]
                        p, res, probs = run("calibrate", path)
                        if res is not None:
                            try:
                                txt, bad = check(res, truth)
                            except (KeyError, TypeError, ValueError) as e:
                                txt, bad = f"check failed {e!r}", True
                            line.append(txt)
                            if bad and eff is None:
                                # far from the truth, unless the calibration itself warns why
                                probs.append("CAL FAR" if not res.get("warnings") else "far, as warned")
                        else:
                            line.append(f"cal rc={p.returncode} {p.stderr.strip()[:160]}")
                        p2_, res2, probs2 = run("diagnose", path)
                        probs += [f"diag {x}" for x in probs2]
                        if res2 is not None:
                            v = res2.get("verdict")
                            q = [x.get("kind") for x in res2.get("quality", [])]
                            line.append(f"verdict={v} quality={q}")
                            if eff is None and v:
                                probs.append("FALSE ALARM?")
                            if eff and eff not in (v or []):
                                # no temperature column: a temperature bias can show only through
                                # what temperature follows (time); no time column: a drift only
                                # through temperature; neither is a miss
                                proxy = {"temperature_bias": "temp_c", "time_drift": "t"}.get(eff)
                                if proxy and proxy not in cols and v:
                                    probs.append(f"named by proxy (no {proxy} column)")
                                else:
                                    probs.append("EFFECT NOT NAMED")
                        else:
                            line.append(f"diag rc={p2_.returncode} {p2_.stderr.strip()[:160]}")
                        print(" | ".join(line), "||", ", ".join(probs) or "ok", flush=True)


if __name__ == "__main__":
    main()
