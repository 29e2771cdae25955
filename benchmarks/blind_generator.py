"""Blind capture generator for `station diagnose`, written from the capture format and the
procedures' spec only (no station code): its own bench choices, noise and effect sizes.

Every capture hides at most one canonical effect of diagnose.md, sized so that its
generalised-least-squares SNR against this generator's own noise (white + first-order
Gauss-Markov bias + random walk), after projecting out the baseline's parameters, is
`snr` (10 by default). The dip effects of the compass are sized on the dip rows' noise.

    python benchmarks/blind_generator.py --procedure accel-tabletop --effect quadratic --seed 540101 --out x.csv

prints the scenario (the bench choices and the hidden effect's size) as JSON.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import sys

import numpy as np
from scipy.signal import lfilter
from scipy.spatial.transform import Rotation, Slerp

G0_MPS2 = 9.80665
OMEGA_IE_RAD_S = 7.2921151e-5

EFFECTS = {
    "accel-tabletop": ["temperature_bias", "time_drift", "quadratic", "scale_asymmetry"],
    "compass": ["temperature_bias", "time_drift", "mag_accel_misalignment", "field_anomaly", "time_varying_hard_iron"],
    "gyro-drift": ["temperature_bias", "time_drift", "earth_rate", "g_sensitivity"],
    # a table of averages (no t): time_drift is not generated for P2
    "accel-centrifuge": ["temperature_bias", "misalignment", "cubic", "lever_arm"],
    "ldv": ["temperature_bias", "time_drift", "time_delay", "lever_arm", "offset"],
}


# ---------------------------------------------------------------- noise and temperature


def gauss_markov(rng, n, dt_s, sigma, tau_s):
    """First-order Gauss-Markov (OU) series, stationary, exact discretisation."""
    phi = np.exp(-dt_s / tau_s)
    w = rng.standard_normal(n) * sigma * np.sqrt(1 - phi**2)
    w[0] = rng.standard_normal() * sigma
    return lfilter([1.0], [1.0, -phi], w)


def random_walk(rng, n, dt_s, k_per_sqrt_s):
    return np.cumsum(rng.standard_normal(n) * k_per_sqrt_s * np.sqrt(dt_s))


def axis_noise(rng, t, white, gm_sigma, gm_tau, rw_k):
    """One axis: white per sample + GM bias + random walk, on the (possibly gapped) time t."""
    n = t.size
    dt_s = np.median(np.diff(t)) if n > 1 else 1.0
    # GM/RW on a uniform grid covering gaps too, then sampled at t
    grid = np.arange(t[0], t[-1] + dt_s, dt_s)
    gm = gauss_markov(rng, grid.size, dt_s, gm_sigma, gm_tau)
    rw = random_walk(rng, grid.size, dt_s, rw_k)
    idx = np.clip(np.round((t - t[0]) / dt_s).astype(int), 0, grid.size - 1)
    return white * rng.standard_normal(n) + gm[idx] + rw[idx]


def first_order(x, t, tau_s):
    dt_s = np.median(np.diff(t))
    a = np.exp(-dt_s / tau_s)
    zi = [a * x[0]]
    y, _ = lfilter([1 - a], [1, -a], x, zi=zi)
    return y


def temperature(rng, t, kind):
    """True die temperature and the recorded temp_c (maybe lagging, quantised)."""
    t0, t1 = t[0], t[-1]
    dur = t1 - t0
    base = rng.uniform(12, 32)
    info = {"kind": kind, "start_c": round(base, 2)}
    if kind == "warmup":
        rise = rng.uniform(6, 22)
        tau = rng.uniform(0.15, 0.6) * dur
        true = base + rise * (1 - np.exp(-(t - t0) / tau))
        info.update(rise_c=round(rise, 2), tau_s=round(tau, 1))
    elif kind == "ramp":
        span = rng.uniform(6, 25) * rng.choice([-1, 1])
        true = base + span * (t - t0) / dur
        info.update(span_c=round(span, 2))
    elif kind == "steps":
        nst = int(rng.integers(3, 6))
        levels = base + np.cumsum(np.r_[0, rng.uniform(4, 10, nst - 1) * rng.choice([-1, 1], nst - 1)])
        edges = t0 + dur * np.arange(nst) / nst
        chamber = levels[np.searchsorted(edges, t, side="right") - 1]
        tau = rng.uniform(0.03, 0.12) * dur
        true = first_order(chamber, t, tau)
        info.update(levels_c=[round(v, 2) for v in levels], tau_s=round(tau, 1))
    else:  # constant: a lab, a few hundredths of wander
        true = base + 0.03 * np.sin(2 * np.pi * (t - t0) / max(dur, 1)) + 0.0 * t
    lag = rng.uniform(20, 120) if (kind != "constant" and rng.random() < 0.3) else 0.0
    rec = first_order(true, t, lag) if lag else true.copy()
    q = rng.choice([0.01, 0.0625])
    rec = np.round((rec + 0.02 * rng.standard_normal(t.size)) / q) * q
    info.update(sensor_lag_s=round(lag, 1), quantum_c=float(q))
    return true, rec, info


def slow(noise, scale):
    """Scale the slow parts (Gauss-Markov and random walk) of a noise list: 0 leaves white noise only."""
    for nzd in noise:
        nzd["gm_sigma"] *= scale
        nzd["rw_k"] *= scale
    return noise


# ---------------------------------------------------------------- least-squares SNR


def ou_interval_cov(a1, b1, a2, b2, sigma, tau):
    """Covariance of the means of an OU process over [a1,b1] and [a2,b2] (matrices)."""
    L1, L2 = b1 - a1, b2 - a2
    same = np.isclose(a1, a2) & np.isclose(b1, b2)
    # ordered: interval 1 before 2 (or swap)
    first_a = np.where(a1 <= a2, a1, a2)
    first_b = np.where(a1 <= a2, b1, b2)
    sec_a = np.where(a1 <= a2, a2, a1)
    sec_b = np.where(a1 <= a2, b2, b1)
    gap = np.maximum(sec_a - first_b, 0.0)
    off = (
        sigma**2
        * tau**2
        * (
            np.exp(-gap / tau)
            - np.exp(-(sec_a - first_a) / tau)
            - np.exp(-(sec_b - first_b) / tau)
            + np.exp(-(sec_b - first_a) / tau)
        )
        / (L1 * L2)
    )
    x = L1 / tau
    diag = 2 * sigma**2 * (x - 1 + np.exp(-x)) / x**2
    return np.where(same, diag, off)


def rows_cov(a, b, proj, n_samples, noise):
    """Covariance of rows = proj · (mean of the axis noises over [a, b]).

    noise: per axis dict(white, gm_sigma, gm_tau, rw_k)."""
    A1, A2 = np.meshgrid(a, a, indexing="ij")
    B1, B2 = np.meshgrid(b, b, indexing="ij")
    C = np.zeros((a.size, a.size))
    for ax, nz in enumerate(noise):
        pp = np.outer(proj[:, ax], proj[:, ax])
        c = ou_interval_cov(A1, B1, A2, B2, nz["gm_sigma"], nz["gm_tau"])
        # random walk: cov of interval means ~ k^2 * mean time of the earlier one
        mid1, mid2 = (A1 + B1) / 2, (A2 + B2) / 2
        rw = nz["rw_k"] ** 2 * np.minimum(mid1, mid2)
        C += pp * (c + rw)
        C += np.diag(proj[:, ax] ** 2 * nz["white"] ** 2 / n_samples)
    return C


def gls_snr(sig, X, C):
    """|P⊥ s| in the metric of C⁻¹, baseline columns X projected out."""
    L = np.linalg.cholesky(C + 1e-12 * np.trace(C) / C.shape[0] * np.eye(C.shape[0]))
    sw = np.linalg.solve(L, sig)
    if X is None or X.size == 0:
        return float(np.linalg.norm(sw))
    Xw = np.linalg.solve(L, X)
    coef, *_ = np.linalg.lstsq(Xw, sw, rcond=None)
    return float(np.linalg.norm(sw - Xw @ coef))


# ---------------------------------------------------------------- helpers


def random_unit(rng):
    v = rng.standard_normal(3)
    return v / np.linalg.norm(v)


def smooth_step(x):
    return 0.5 - 0.5 * np.cos(np.pi * np.clip(x, 0, 1))


def normal_gravity(lat_deg, alt_m):
    """Somigliana normal gravity with a free-air correction (WGS-84)."""
    s2 = np.sin(np.radians(lat_deg)) ** 2
    g = 9.7803253359 * (1 + 0.00193185265241 * s2) / np.sqrt(1 - 0.00669437999013 * s2)
    return g - 3.086e-6 * alt_m


def site(rng):
    sites = [
        (39.98, 116.35, 52),
        (48.15, 11.57, 520),
        (-33.87, 151.21, 40),
        (64.14, -21.94, 30),
        (1.35, 103.82, 15),
        (37.39, -122.08, 30),
        (-23.55, -46.63, 760),
        (55.75, 37.62, 150),
        (60.17, 24.94, 20),
        (19.43, -99.13, 2240),
    ]
    lat, lon, alt = sites[rng.integers(len(sites))]
    lat += rng.uniform(-0.3, 0.3)
    lon += rng.uniform(-0.3, 0.3)
    return round(lat, 4), round(lon, 4), int(alt + rng.integers(-10, 10))


def date_str(rng, with_time):
    d = dt.datetime(2025, 1, 1) + dt.timedelta(days=int(rng.integers(0, 690)), seconds=int(rng.integers(0, 86400)))
    return d, (d.strftime("%Y-%m-%dT%H:%M:%SZ") if with_time else d.strftime("%Y-%m-%d"))


def fmt_col(x, digits):
    return np.char.mod(f"%.{digits}g", x)


def hold_timeline(rng, fs, n_holds, move_s, hold_s):
    """A bench's timeline: a hold, then a move and a hold for each further pose.

    move_s: (lo, hi) [s], each move's length drawn uniform; hold_s: a hold's length [s], or a
    function drawing one per hold (drawn after that hold's move). Returns the segments
    [(kind, t0 [s], t1 [s], k)], the sample times tt [s] at ``fs`` [Hz] and each sample's
    hold index (-1 while moving)."""
    segs, t = [], 0.0
    for k in range(n_holds):
        if k > 0:
            mv = rng.uniform(*move_s)
            segs.append(("move", t, t + mv, k))
            t += mv
        h = hold_s() if callable(hold_s) else hold_s
        segs.append(("hold", t, t + h, k))
        t += h
    tt = np.arange(0, t, 1 / fs)
    hold_of = np.full(tt.size, -1)
    for kind, a, b, k in segs:
        if kind == "hold":
            hold_of[(tt >= a) & (tt < b)] = k
    return segs, tt, hold_of


def write_capture(path, meta, cols, rng, shuffle_cols=True):
    """cols: list of (name, array or list of str, digits). Empty string = missing."""
    names = [c[0] for c in cols]
    order = list(range(len(cols)))
    if shuffle_cols:
        first = [i for i in order if names[i] == "t"]
        rest = [i for i in order if names[i] != "t"]
        if rng.random() < 0.5:
            rng.shuffle(rest)
        order = first + rest
    strs = []
    for i in order:
        name, val, digits = cols[i]
        if isinstance(val, np.ndarray) and val.dtype.kind == "f":
            s = fmt_col(val, digits)
            s = np.where(np.isnan(val), "", s)
        else:
            s = np.asarray(val, dtype=str)
        strs.append(s)
    body = strs[0].astype(object)
    for s in strs[1:]:
        body = body + "," + s.astype(object)
    with open(path, "w") as fh:
        fh.write("# station-capture: 1\n")
        for k, v in meta.items():
            fh.write(f"# {k}: {v}\n")
        fh.write(",".join(names[i] for i in order) + "\n")
        fh.write("\n".join(body.tolist()))
        fh.write("\n")


# ---------------------------------------------------------------- P1


def _face_rotation(rng, axis, sign, err_deg):
    a = np.zeros(3)
    a[axis] = sign
    r_align = Rotation.align_vectors([[0, 0, 1]], [a])[0]
    yaw = Rotation.from_euler("z", rng.uniform(0, 360), degrees=True)
    err = Rotation.from_rotvec(np.radians(err_deg) * random_unit(rng) * rng.random())
    return err * yaw * r_align


def gen_tabletop(seed, effect, out, snr=10.0, averages=None, slow_noise=1.0):
    rng = np.random.default_rng(seed)
    sc = {"procedure": "accel-tabletop", "seed": seed, "effect": effect}
    fs = float(rng.choice([50, 100, 200, 400, 1000]))
    n_pos = int(rng.integers(12, 31))
    order = rng.choice(["faces_first", "faces_shuffled", "random_tilts"])
    labels_mode = rng.choice(["source_faces", "strings", "none", "holds_only"], p=[0.3, 0.25, 0.25, 0.2])
    draw = effect != "time_drift" and rng.random() < 0.15  # (short-circuit kept: seeds stay reproducible)
    averages = draw if averages is None else bool(averages)
    if averages:
        labels_mode = "strings"
    max_rows = 160_000
    hold_s = float(min(rng.uniform(20, 90), max_rows / (fs * n_pos)))
    hold_s = max(hold_s, 8.0)
    # orientations
    rots, face_labels = [], []
    if order in ("faces_first", "faces_shuffled"):
        faces = [(0, 1), (0, -1), (1, 1), (1, -1), (2, 1), (2, -1)]
        idx = list(range(6))
        if order == "faces_shuffled":
            rng.shuffle(idx)
        for i in idx:
            rots.append(_face_rotation(rng, *faces[i], err_deg=rng.uniform(0.1, 1.0)))
            face_labels.append(i + 1)
    while len(rots) < n_pos:
        r = Rotation.random(random_state=rng)
        # a table holds a device on a fixture: keep it off exactly the faces, any tilt
        rots.append(r)
        face_labels.append(None)
    if order == "faces_shuffled":
        perm = rng.permutation(n_pos)
        rots = [rots[i] for i in perm]
        face_labels = [face_labels[i] for i in perm]
    # timeline: settle, hold, move
    segs, tt, hold_of = hold_timeline(rng, fs, n_pos, (2.5, 8.0), hold_s)
    dt_s = 1 / fs
    n = tt.size
    f_body = np.zeros((n, 3))
    moving = np.zeros(n, bool)
    lat, lon, alt = site(rng)
    g = normal_gravity(lat, alt)
    g_nav = np.array([0, 0, g])
    for kind, a, b, k in segs:
        m = (tt >= a) & (tt < b)
        if kind == "hold":
            f_body[m] = rots[k].inv().apply(g_nav)
        else:
            moving[m] = True
            x = (tt[m] - a) / (b - a)
            s = smooth_step(x)
            sl = Slerp([0, 1], Rotation.concatenate([rots[k - 1], rots[k]]))
            r_t = sl(s)
            T = b - a
            h = rng.uniform(0.03, 0.15)
            d = random_unit(rng) * np.r_[1, 1, 0] * rng.uniform(0.05, 0.3)
            a_vert = h * 2 * np.pi**2 / T**2 * np.cos(2 * np.pi * x)
            a_hor = (np.pi**2 / (2 * T**2)) * np.cos(np.pi * x)[:, None] * d[None, :]
            tremor = np.column_stack([gauss_markov(rng, x.size, dt_s, 0.3, 0.05) for _ in range(3)])
            acc_nav = a_hor + np.outer(a_vert, [0, 0, 1]) + tremor
            f_body[m] = r_t.inv().apply(acc_nav + g_nav)
    # temperature
    tkind = rng.choice(["warmup", "ramp", "steps", "constant"])
    if effect == "temperature_bias" and tkind == "constant":
        tkind = rng.choice(["warmup", "ramp", "steps"])
    T_true, T_rec, tinfo = temperature(rng, tt, tkind)
    # noise (input referred, m/s^2)
    noise = []
    for _ in range(3):
        nd = rng.uniform(8e-4, 4e-3)
        noise.append(
            {
                "white": nd * np.sqrt(fs / 2),
                "gm_sigma": rng.uniform(1e-4, 8e-4),
                "gm_tau": rng.uniform(20, 400),
                "rw_k": rng.uniform(2e-6, 2e-5),
            }
        )
    slow(noise, slow_noise)
    # SNR design: norm rows of 4 parts per hold (1 for a table of averages), projected on u_k
    parts = 1 if averages else 4
    ra, rb, proj, kk = [], [], [], []
    for kind, a, b, k in segs:
        if kind != "hold":
            continue
        a2, b2 = a + 1.0, b - 1.0
        e = np.linspace(a2, b2, parts + 1)
        u = rots[k].inv().apply([0, 0, 1.0])
        for j in range(parts):
            ra.append(e[j])
            rb.append(e[j + 1])
            proj.append(u)
            kk.append(k)
    ra, rb, proj, kk = map(np.asarray, (ra, rb, proj, kk))
    n_row = (rb - ra) * fs
    C = rows_cov(ra, rb, proj, n_row, noise)
    X = np.column_stack([proj] + [g * proj[:, i] * proj[:, j] for i in range(3) for j in range(i, 3)])

    def part_mean(x):
        return np.array([x[(tt >= a) & (tt < b)].mean(axis=0) for a, b in zip(ra, rb)])

    eff_info = {}
    delta = np.zeros((n, 3))  # effect in m/s^2, input side
    if effect == "temperature_bias":
        c = random_unit(rng)
        unit_sig = np.outer(T_true - T_true.mean(), c)
    elif effect == "time_drift":
        c = random_unit(rng)
        unit_sig = np.outer(tt - tt.mean(), c)
    elif effect == "quadratic":
        c = random_unit(rng)
        unit_sig = c * f_body**2
    elif effect == "scale_asymmetry":
        c = random_unit(rng)
        unit_sig = c * np.abs(f_body)
    else:
        c, unit_sig = None, None
    if unit_sig is not None:
        sig_rows = np.sum(part_mean(unit_sig) * proj, axis=1)
        s1 = gls_snr(sig_rows, X, C)
        size = snr / s1
        delta = unit_sig * size
        eff_info = {
            "vector": (c * size).tolist(),
            "snr_unit": s1,
            "snr": snr,
            "units": {
                "temperature_bias": "m/s^2/degC",
                "time_drift": "m/s^2/s",
                "quadratic": "1/(m/s^2) (f + D f^2)",
                "scale_asymmetry": "(f + a|f|)",
            }[effect],
        }
        null_snr = None
    else:
        null_snr = None
    # sensor: raw = K (f + delta + noise) + b
    unit = rng.choice(["V", "counts", "g", "m/s^2"])
    if unit == "V":
        k0, b0, q = rng.uniform(0.2, 0.8) / G0_MPS2, 1.65, 5e-5
        bias = b0 + rng.uniform(-0.06, 0.06, 3)
    elif unit == "counts":
        k0, q = float(rng.choice([4096, 8192, 16384])) / G0_MPS2, 1.0
        bias = rng.uniform(-120, 120, 3)
    elif unit == "g":
        k0, q = 1 / G0_MPS2, 1e-6
        bias = rng.uniform(-0.03, 0.03, 3)
    else:
        k0, q = 1.0, 1e-5
        bias = rng.uniform(-0.3, 0.3, 3)
    K = k0 * (np.eye(3) + np.diag(rng.uniform(-0.03, 0.03, 3)) + rng.uniform(-0.01, 0.01, (3, 3)) * (1 - np.eye(3)))
    nz = np.column_stack([axis_noise(rng, tt, **noise[i]) for i in range(3)])
    raw = (f_body + delta + nz) @ K.T + bias
    raw = np.round(raw / q) * q
    # saturation-free: all within +-4 g
    # write
    date, dstr = date_str(rng, rng.random() < 0.3)
    meta = {
        "procedure": "accel-tabletop",
        "device": f"BLIND-{seed}",
        "accel_unit": unit,
        "latitude_deg": lat,
        "longitude_deg": lon,
        "altitude_m": alt,
        "date": dstr,
    }
    if rng.random() < 0.4:
        meta["g_mps2"] = round(g, 5)
    if rng.random() < 0.5:
        meta["sample_rate_hz"] = fs
    if rng.random() < 0.5:
        meta["operator"] = "blind tester"
        meta["fixture"] = "granite plate, aluminium cube"
    keep = np.ones(n, bool)
    if labels_mode == "holds_only":
        keep = ~moving
    pos = None
    if labels_mode == "source_faces":
        lab = [str(face_labels[k]) if face_labels[k] is not None else str(13 + k) for k in range(n_pos)]
        pos = np.array([lab[k] if k >= 0 else "" for k in hold_of], dtype=object)
    elif labels_mode in ("strings", "holds_only"):
        lab = [f"h{k + 1:02d}" for k in range(n_pos)]
        pos = np.array([lab[k] if k >= 0 else "" for k in hold_of], dtype=object)
    digits = 8 if unit != "counts" else 7
    if averages:
        rows = []
        for k in range(n_pos):
            m = hold_of == k
            idx = np.flatnonzero(m)
            idx = idx[int(fs) : -int(fs)]
            rows.append((lab[k], raw[idx].mean(0), raw[idx].std(0, ddof=1), idx.size, T_rec[idx].mean()))
        cols = [("position", np.array([r[0] for r in rows]), 0)]
        for i, a in enumerate("xyz"):
            cols.append((f"a{a}", np.array([r[1][i] for r in rows]), 10))
            cols.append((f"a{a}_std", np.array([r[2][i] for r in rows]), 4))
        cols.append(("n", np.array([str(r[3]) for r in rows]), 0))
        cols.append(("temp_c", np.array([r[4] for r in rows]), 6))
        meta.pop("sample_rate_hz", None)
    else:
        cols = [("t", np.char.mod("%.6f" if fs > 100 else "%.3f", tt[keep]), 0)]
        if pos is not None:
            cols.append(("position", pos[keep], 0))
        for i, a in enumerate("xyz"):
            cols.append((f"a{a}", raw[keep, i], digits))
        cols.append(("temp_c", T_rec[keep], 6))
    write_capture(out, meta, cols, rng)
    sc.update(
        fs_hz=fs,
        n_positions=n_pos,
        order=str(order),
        labels=str(labels_mode),
        table_of_averages=bool(averages),
        hold_s=round(hold_s, 1),
        unit=str(unit),
        rows=int(keep.sum()) if not averages else n_pos,
        duration_s=round(float(tt[-1]), 1),
        temperature=tinfo,
        noise=[{k: float(f"{v:.3g}") for k, v in nzd.items()} for nzd in noise],
        hidden=eff_info,
        null_snr=null_snr,
    )
    return sc


# ---------------------------------------------------------------- compass


def igrf_enu(lat, lon, alt_m, date):
    import ppigrf

    be, bn, bu = ppigrf.igrf(lon, lat, alt_m / 1000.0, date)
    return np.array([float(np.ravel(be)[0]), float(np.ravel(bn)[0]), float(np.ravel(bu)[0])])


def gen_compass(seed, effect, out, snr=10.0, soft_iron="upper", slow_noise=1.0):
    rng = np.random.default_rng(seed)
    sc = {"procedure": "compass", "seed": seed, "effect": effect}
    fs = float(rng.choice([50, 100, 200]))
    n_holds = int(rng.integers(10, 31))
    hold_range = (1.0, 4.0) if rng.random() < 0.7 else (0.0, 0.3)  # held holds, or a tumbled record
    lat, lon, alt = site(rng)
    date, dstr = date_str(rng, rng.random() < 0.3)
    B_nav = igrf_enu(lat, lon, alt, date)
    F_igrf = np.linalg.norm(B_nav)
    g = normal_gravity(lat, alt)
    g_nav = np.array([0, 0, g])
    hand = rng.uniform(0.05, 0.6)  # m/s^2 rms of the hand, in motion
    rots = [Rotation.random(random_state=rng) for _ in range(n_holds)]
    segs, tt, hold_of = hold_timeline(rng, fs, n_holds, (1.0, 3.5), lambda: rng.uniform(*hold_range))
    dt_s = 1 / fs
    n = tt.size
    quats = np.zeros((n, 4))
    acc_nav = np.zeros((n, 3))
    for kind, a, b, k in segs:
        m = (tt >= a) & (tt < b)
        if not m.any():
            continue
        if kind == "hold":
            jit = Rotation.from_rotvec(
                np.column_stack([gauss_markov(rng, m.sum(), dt_s, np.radians(0.3), 0.5) for _ in range(3)])
            )
            quats[m] = (jit * rots[k]).as_quat()
            acc_nav[m] = np.column_stack([gauss_markov(rng, m.sum(), dt_s, 0.15 * hand, 0.15) for _ in range(3)])
        else:
            x = (tt[m] - a) / (b - a)
            sl = Slerp([0, 1], Rotation.concatenate([rots[k - 1], rots[k]]))
            quats[m] = sl(smooth_step(x)).as_quat()
            acc_nav[m] = np.column_stack([gauss_markov(rng, m.sum(), dt_s, hand, 0.2) for _ in range(3)])
    R = Rotation.from_quat(quats)
    f_body = R.inv().apply(acc_nav + g_nav)
    # body rate for the gyro columns
    dR = R[1:] * R[:-1].inv()
    w_nav = dR.as_rotvec() / dt_s
    w_body = R[:-1].inv().apply(w_nav)
    w_body = np.vstack([w_body, w_body[-1:]])
    # the field, maybe bent
    eff_info = {}
    B_loc = B_nav.copy()
    tkind = rng.choice(["warmup", "ramp", "steps", "constant"], p=[0.3, 0.2, 0.2, 0.3])
    if effect == "temperature_bias" and tkind == "constant":
        tkind = "warmup"
    T_true, T_rec, tinfo = temperature(rng, tt, tkind)
    mag_white_nT = rng.uniform(60, 400)
    noise = [
        {
            "white": mag_white_nT,
            "gm_sigma": rng.uniform(10, 80),
            "gm_tau": rng.uniform(20, 200),
            "rw_k": rng.uniform(0.5, 3),
        }
        for _ in range(3)
    ]
    slow(noise, slow_noise)
    acc_white = rng.uniform(0.005, 0.03)
    # dip-row noise per hold: per-sample dip noise from both sensors, plus the hand
    holds = [(a, b, k) for kind, a, b, k in segs if kind == "hold" and b - a >= 1.0]
    R_mis = Rotation.identity()
    if effect in ("mag_accel_misalignment", "field_anomaly"):
        n_per = np.array([max((b - a) * fs, 1) for a, b, _ in holds]) if holds else np.array([fs])
        sd_dip = np.sqrt(
            (acc_white / g) ** 2 / n_per
            + (mag_white_nT / F_igrf) ** 2 / n_per
            + (0.15 * hand / g) ** 2 / np.maximum(n_per * dt_s / 0.3, 1)
        )
        if effect == "mag_accel_misalignment":
            axis = random_unit(rng)
            if holds:
                fh = np.array([rots[k].inv().apply(g_nav) / g for _, _, k in holds])
                mh = np.array([rots[k].inv().apply(B_nav) / F_igrf for _, _, k in holds])
                d_unit = np.einsum("ij,ij->i", fh, np.cross(axis, mh))
                d_unit = d_unit - d_unit.mean()
                s1 = float(np.linalg.norm(d_unit / sd_dip))
            else:
                s1 = 1.0 / np.median(sd_dip) * 0.3
            ang = float(np.clip(snr / s1, np.radians(0.3), np.radians(6)))
            R_mis = Rotation.from_rotvec(axis * ang)
            eff_info = {"axis": axis.tolist(), "angle_deg": float(np.degrees(ang)), "snr_unit_rad": s1, "snr": ang * s1}
        else:
            incl = np.arctan2(-B_nav[2], np.hypot(B_nav[0], B_nav[1]))  # positive down
            s1 = float(np.cos(incl) * np.sqrt(np.sum(1 / sd_dip**2)))
            d_inc = float(np.clip(snr / s1, np.radians(0.3), np.radians(5))) * rng.choice([-1, 1])
            hor = np.array([B_nav[0], B_nav[1], 0.0])
            axis = np.cross(hor, [0, 0, 1.0])
            axis /= np.linalg.norm(axis)
            scale = 1 + rng.uniform(0.02, 0.08) * rng.choice([-1, 1])
            B_loc = scale * Rotation.from_rotvec(axis * d_inc).apply(B_nav)
            inc2 = np.arctan2(-B_loc[2], np.hypot(B_loc[0], B_loc[1]))
            eff_info = {
                "d_incl_deg": float(np.degrees(inc2 - incl)),
                "magnitude_scale": scale,
                "snr_unit_rad": s1,
                "snr": abs(d_inc) * s1,
            }
    m_body = R.inv().apply(B_loc)
    m_sens = R_mis.apply(m_body)
    # magnitude-row SNR for the hard-iron effects: block means along the field direction
    hi = np.zeros((n, 3))
    if effect in ("temperature_bias", "time_drift", "time_varying_hard_iron"):
        c = random_unit(rng)
        if effect == "temperature_bias":
            unit_sig = np.outer(T_true - T_true.mean(), c)
        elif effect == "time_drift":
            unit_sig = np.outer(tt - tt.mean(), c)
        else:
            t_on = float(tt[0] + rng.uniform(0.25, 0.75) * (tt[-1] - tt[0]))
            unit_sig = np.outer((tt >= t_on).astype(float), c)
        blk = max(int(0.5 * fs), 1)
        nb = n // blk
        sl_ = slice(0, nb * blk)
        mhat = m_sens / np.linalg.norm(m_sens, axis=1, keepdims=True)
        proj = mhat[sl_].reshape(nb, blk, 3).mean(1)
        proj /= np.linalg.norm(proj, axis=1, keepdims=True)
        a = tt[sl_].reshape(nb, blk)[:, 0]
        b = a + blk * dt_s
        sig_rows = np.sum(unit_sig[sl_].reshape(nb, blk, 3).mean(1) * proj, axis=1)
        C = rows_cov(a, b, proj, np.full(nb, blk), noise)
        mb = m_sens[sl_].reshape(nb, blk, 3).mean(1)
        X = np.column_stack([proj] + [proj[:, i] * mb[:, j] for i in range(3) for j in range(i, 3)])
        s1 = gls_snr(sig_rows, X, C)
        size = snr / s1
        hi = unit_sig * size
        eff_info = {"vector_nT": (c * size).tolist(), "snr_unit": s1, "snr": snr}
        if effect == "time_varying_hard_iron":
            eff_info["t_on_s"] = t_on
        eff_info["units"] = {"temperature_bias": "nT/degC", "time_drift": "nT/s", "time_varying_hard_iron": "nT"}[
            effect
        ]
    # soft and hard iron: raw = S m + h (+ wander)
    # soft iron in the spec's gauge: W = S^-1 upper triangular, so S upper triangular too. A full S
    # (symmetric soft iron, or a chip turned on its board) holds a rotation W cannot take: that is
    # a magnetometer frame rotated from the accelerometer's, i.e. the misalignment effect itself.
    S = np.eye(3) + np.diag(rng.uniform(-0.08, 0.08, 3)) + np.triu(rng.uniform(-0.04, 0.04, (3, 3)), 1)
    if soft_iron == "symmetric":
        S = (S + S.T) / 2
    h = rng.uniform(-40000, 40000, 3)
    nz = np.column_stack([axis_noise(rng, tt, **noise[i]) for i in range(3)])
    raw_nT = (m_sens + hi + nz) @ S.T + h
    unit = rng.choice(["uT", "nT", "gauss"])
    fac = {"uT": 1e-3, "nT": 1.0, "gauss": 1e-5}[unit]
    raw = raw_nT * fac
    if unit == "gauss":
        raw = np.round(raw / 1e-5) * 1e-5  # 1 nT steps below a 60+ nT noise: dithered
    acc_unit = rng.choice(["m/s^2", "g"])
    acc_bias = rng.uniform(-0.02, 0.02, 3)
    acc = f_body + acc_bias + acc_white * rng.standard_normal((n, 3))
    if acc_unit == "g":
        acc = acc / G0_MPS2
    gyro_cols = rng.choice(["none", "xy", "xyz"])
    gyro_unit = rng.choice(["rad/s", "deg/s"])
    gyro = w_body + rng.uniform(-0.01, 0.01, 3) + 0.004 * rng.standard_normal((n, 3))
    if gyro_unit == "deg/s":
        gyro = np.degrees(gyro)
    meta = {
        "procedure": "compass",
        "device": f"BLIND-{seed}",
        "mag_unit": unit,
        "accel_unit": acc_unit,
        "latitude_deg": lat,
        "longitude_deg": lon,
        "altitude_m": alt,
        "date": dstr,
    }
    if gyro_cols != "none":
        meta["gyro_unit"] = gyro_unit
    if rng.random() < 0.5:
        meta["sample_rate_hz"] = fs
    cols = [("t", np.char.mod("%.4f", tt), 0)]
    for i, a in enumerate("xyz"):
        cols.append((f"a{a}", acc[:, i], 7))
    for i, a in enumerate("xyz"):
        if gyro_cols == "xyz" or (gyro_cols == "xy" and a != "z"):
            cols.append((f"g{a}", gyro[:, i], 6))
    for i, a in enumerate("xyz"):
        cols.append((f"m{a}", raw[:, i], 8))
    cols.append(("temp_c", T_rec, 6))
    write_capture(out, meta, cols, rng)
    sc.update(
        soft_iron=soft_iron,
        fs_hz=fs,
        n_holds=n_holds,
        hold_s=list(hold_range),
        hand_accel_mps2=round(hand, 3),
        unit=str(unit),
        accel_unit=str(acc_unit),
        gyro=str(gyro_cols),
        rows=n,
        duration_s=round(float(tt[-1]), 1),
        site=[lat, lon, alt],
        date=dstr,
        igrf_nT=B_nav.round(1).tolist(),
        temperature=tinfo,
        noise=[{k: float(f"{v:.3g}") for k, v in nzd.items()} for nzd in noise],
        acc_bias_mps2=acc_bias.round(4).tolist(),
        hidden=eff_info,
    )
    return sc


# ---------------------------------------------------------------- P4


def _level_rot(heading_deg, pitch_deg, roll_deg):
    """Body (x fwd, y up, z right) to ENU."""
    psi = np.radians(heading_deg)
    x = np.array([np.sin(psi), np.cos(psi), 0.0])
    y = np.array([0, 0, 1.0])
    z = np.cross(x, y)
    R0 = Rotation.from_matrix(np.column_stack([x, y, z]))
    # pitch about body z (right), roll about body x (forward)
    return R0 * Rotation.from_euler("z", pitch_deg, degrees=True) * Rotation.from_euler("x", roll_deg, degrees=True)


def gen_gyrodrift(seed, effect, out, snr=10.0, slow_noise=1.0):
    rng = np.random.default_rng(seed)
    sc = {"procedure": "gyro-drift", "seed": seed, "effect": effect}
    fs = float(rng.choice([50, 100, 200, 400]))
    if effect in ("g_sensitivity", "earth_rate"):
        mode = "multi"
    else:
        mode = rng.choice(["single", "multi", "reference"], p=[0.4, 0.35, 0.25])
    lat, lon, alt = site(rng)
    g = normal_gravity(lat, alt)
    if mode == "multi":
        n_pos = int(rng.integers(4, 9))
        hold = float(min(rng.uniform(40, 150), 250_000 / (fs * n_pos)))
        poses = [
            (rng.uniform(0, 360), rng.uniform(-50, 50), rng.choice([rng.uniform(-40, 40), rng.choice([-90, 90, 180])]))
            for _ in range(n_pos)
        ]
        motion = rng.random() < 0.5
    else:
        n_pos = 1
        hold = float(min(rng.uniform(180, 900), 250_000 / fs))
        poses = [(rng.uniform(-4, 4), rng.uniform(-3, 3), rng.uniform(-3, 3))]
        motion = False
    rots = [_level_rot(*p) for p in poses]
    segs, tt, hold_of = hold_timeline(rng, fs, n_pos, (3, 8), hold)
    dt_s = 1 / fs
    n = tt.size
    quats = np.zeros((n, 4))
    for kind, a, b, k in segs:
        m = (tt >= a) & (tt < b)
        if kind == "hold":
            quats[m] = rots[k].as_quat()
        else:
            sl = Slerp([0, 1], Rotation.concatenate([rots[k - 1], rots[k]]))
            quats[m] = sl(smooth_step((tt[m] - a) / (b - a))).as_quat()
    R = Rotation.from_quat(quats)
    w_ie_nav = np.array([0, OMEGA_IE_RAD_S * np.cos(np.radians(lat)), OMEGA_IE_RAD_S * np.sin(np.radians(lat))])
    dR = R[1:] * R[:-1].inv()
    w_nav = np.vstack([dR.as_rotvec() / dt_s, np.zeros((1, 3))])
    w_true = R.inv().apply(w_nav + w_ie_nav)
    f_body = R.inv().apply([0, 0, g])
    tkind = rng.choice(["warmup", "ramp", "steps", "constant"], p=[0.4, 0.2, 0.15, 0.25])
    if effect == "temperature_bias" and tkind == "constant":
        tkind = "warmup"
    T_true, T_rec, tinfo = temperature(rng, tt, tkind)
    deg_h = np.radians(1) / 3600
    arw = rng.uniform(0.1, 0.6) * np.radians(1) / 60  # rad/sqrt(s)
    noise = [
        {
            "white": arw * np.sqrt(fs / 2),
            "gm_sigma": rng.uniform(2, 15) * deg_h,
            "gm_tau": rng.uniform(30, 300),
            "rw_k": rng.uniform(0.005, 0.03) * deg_h,
        }
        for _ in range(3)
    ]
    slow(noise, slow_noise)
    # rows: 5 s block means within holds, per axis (the axes' noises are independent)
    blk_s = 5.0
    ra, rb = [], []
    for kind, a, b, _ in segs:
        if kind != "hold":
            continue
        e = np.arange(a + 1.0, b - 1.0 - blk_s + 1e-9, blk_s)
        ra += list(e)
        rb += list(e + blk_s)
    ra, rb = np.asarray(ra), np.asarray(rb)

    def snr_axes(sig3):  # sig3: rows x 3, baseline: a constant per axis
        tot = 0.0
        for ax in range(3):
            p = np.zeros((ra.size, 3))
            p[:, ax] = 1
            C = rows_cov(ra, rb, p, (rb - ra) * fs, noise)
            tot += gls_snr(sig3[:, ax], np.ones((ra.size, 1)), C) ** 2
        return np.sqrt(tot)

    def rows_of(x):
        return np.array([x[(tt >= a) & (tt < b)].mean(0) for a, b in zip(ra, rb)])

    eff_info, extra = {}, np.zeros((n, 3))
    noise_scale = 1.0
    if effect in ("temperature_bias", "time_drift"):
        c = random_unit(rng)
        drv = (T_true - T_true.mean()) if effect == "temperature_bias" else (tt - tt.mean())
        unit_sig = np.outer(drv, c)
        s1 = snr_axes(rows_of(unit_sig))
        extra = unit_sig * snr / s1
        eff_info = {
            "vector": (c * snr / s1).tolist(),
            "units": "rad/s/degC" if effect == "temperature_bias" else "rad/s/s",
            "snr_unit": s1,
            "snr": snr,
        }
    elif effect == "g_sensitivity":
        Gm = rng.standard_normal((3, 3))
        Gm /= np.linalg.norm(Gm)
        unit_sig = f_body @ Gm.T
        s1 = snr_axes(rows_of(unit_sig))
        extra = unit_sig * snr / s1
        eff_info = {"G_rad_s_per_mps2": (Gm * snr / s1).tolist(), "snr_unit": s1, "snr": snr}
    elif effect == "earth_rate":
        s_now = snr_axes(rows_of(R.inv().apply(np.tile(w_ie_nav, (n, 1)))))
        noise_scale = float(np.clip(s_now / snr, 0.05, 1.0))
        for nzd in noise:
            for key in ("white", "gm_sigma", "rw_k"):
                nzd[key] *= noise_scale
        eff_info = {
            "earth_rate_rad_s": OMEGA_IE_RAD_S,
            "snr_at_drawn_noise": s_now,
            "noise_scaled_by": noise_scale,
            "snr": s_now / noise_scale,
        }
    bias = rng.uniform(-0.3, 0.3, 3) * np.radians(1)  # turn-on bias, rad/s
    nz = np.column_stack([axis_noise(rng, tt, **noise[i]) for i in range(3)])
    gyro = w_true + bias + extra + nz
    unit = rng.choice(["rad/s", "deg/s"])
    gy = np.degrees(gyro) if unit == "deg/s" else gyro
    acc_unit = rng.choice(["m/s^2", "g"])
    acc = f_body + rng.uniform(-0.03, 0.03, 3) + rng.uniform(0.005, 0.02) * rng.standard_normal((n, 3))
    if acc_unit == "g":
        acc /= G0_MPS2
    _, dstr = date_str(rng, rng.random() < 0.3)
    meta = {
        "procedure": "gyro-drift",
        "device": f"BLIND-{seed}",
        "gyro_unit": unit,
        "accel_unit": acc_unit,
        "date": dstr,
    }
    head_err = rng.uniform(-3, 3, n_pos)
    if mode == "reference":
        meta["gyro_mode"] = "reference"
    else:
        meta["gyro_mode"] = "static"
        if effect != "earth_rate":
            meta.update(latitude_deg=round(lat + rng.uniform(-0.2, 0.2), 3), longitude_deg=lon, altitude_m=alt)
        if mode == "single" and rng.random() < 0.6:
            meta["heading_deg"] = round(poses[0][0] + head_err[0], 1)
    if rng.random() < 0.5:
        meta["sample_rate_hz"] = fs
    keep = np.ones(n, bool)
    if mode == "multi" and not motion:
        keep = hold_of >= 0
    cols = [("t", np.char.mod("%.5f", tt[keep]), 0)]
    if mode == "multi":
        lab = np.array([str(k + 1) if k >= 0 else "" for k in hold_of], dtype=object)
        cols.append(("position", lab[keep], 0))
        hd = np.array([f"{(poses[k][0] + head_err[k]) % 360:.1f}" if k >= 0 else "" for k in hold_of], dtype=object)
        cols.append(("heading_deg", hd[keep], 0))
    for i, a in enumerate("xyz"):
        cols.append((f"g{a}", gy[keep, i], 9))
    if mode != "reference" or rng.random() < 0.5:
        for i, a in enumerate("xyz"):
            cols.append((f"a{a}", acc[keep, i], 7))
    if mode == "reference":
        ref = (
            w_true
            + rng.uniform(-0.3, 0.3, 3) * deg_h
            + 0.01 * np.radians(1) / 60 * np.sqrt(fs / 2) * rng.standard_normal((n, 3))
        )
        for i, a in enumerate("xyz"):
            cols.append((f"ref_g{a}", ref[keep, i], 9))
    cols.append(("temp_c", T_rec[keep], 6))
    write_capture(out, meta, cols, rng)
    sc.update(
        fs_hz=fs,
        mode=str(mode),
        n_positions=n_pos,
        hold_s=round(hold, 1),
        motion_rows=bool(motion),
        poses_deg=[[round(float(v), 1) for v in p] for p in poses],
        unit=str(unit),
        accel_unit=str(acc_unit),
        rows=int(keep.sum()),
        duration_s=round(float(tt[-1]), 1),
        latitude_in_meta="latitude_deg" in meta,
        temperature=tinfo,
        noise_deg_h=[{k: float(f"{v / (1 if k == 'gm_tau' else deg_h):.3g}") for k, v in nzd.items()} for nzd in noise],
        hidden=eff_info,
    )
    return sc


# ---------------------------------------------------------------- P2


def gen_centrifuge(seed, effect, out, snr=10.0, slow_noise=1.0, vibration=1.0):
    """A table of averages: one row per mounting and speed (time-ordered rows, no t column)."""
    rng = np.random.default_rng(seed)
    sc = {"procedure": "accel-centrifuge", "seed": seed, "effect": effect}
    R_m = round(float(rng.uniform(0.25, 1.5)), 4)  # the physics uses the radius the metadata states
    # f is in units of the rig's own g (gravity reads 1): the metadata gives it as g_mps2 or as the site
    lat, lon, alt = site(rng)
    g_loc = round(float(normal_gravity(lat, alt)), 6)
    g_meta = str(rng.choice(["g_mps2", "site", "both"]))
    a_max = float(rng.uniform(8, 40))  # g at the top speed
    w_max = np.sqrt(a_max * g_loc / R_m)
    n_mount = int(rng.integers(6, 21))
    n_speed = int(rng.integers(2, 6))
    zero_speed = rng.random() < 0.3
    mounts = [Rotation.random(random_state=rng) for _ in range(n_mount)]
    rows = []  # (mount, omega, t_s)
    t = 0.0
    for k in range(n_mount):
        ws = np.sort(rng.uniform(0.25, 1.0, n_speed)) * w_max
        if rng.random() < 0.3:
            ws = ws[::-1]
        if zero_speed:
            ws = np.r_[0.0, ws]
        for w in ws:
            dwell = rng.uniform(30, 90)
            rows.append((k, float(w), t, dwell))
            t += dwell + rng.uniform(20, 60)
        t += rng.uniform(120, 300)  # remount
    k_of = np.array([r[0] for r in rows])
    w = np.array([r[1] for r in rows])
    ta = np.array([r[2] for r in rows])
    tb = ta + np.array([r[3] for r in rows])
    A = w**2 * R_m / g_loc
    e_out = np.array([1.0, 0, 0])
    e_up = np.array([0, 0, 1.0])
    c_body = np.array([mounts[k].inv().apply(-e_out) for k in k_of])  # centripetal direction, body
    up_body = np.array([mounts[k].inv().apply(e_up) for k in k_of])
    f = A[:, None] * c_body + up_body  # g
    fhat = f / np.linalg.norm(f, axis=1, keepdims=True)
    # temperature: room drift in time plus heating with speed for some rigs
    tt = np.linspace(0, t, 2000)
    tkind = rng.choice(["warmup", "ramp", "steps", "constant"])
    if effect == "temperature_bias" and tkind == "constant":
        tkind = "ramp"
    T_true_t, _, tinfo = temperature(rng, tt, tkind)
    heat = float(rng.uniform(1, 6)) if rng.random() < 0.5 else 0.0
    T_row = np.interp((ta + tb) / 2, tt, T_true_t) + heat * (A / a_max) ** 1.5
    tinfo["speed_heating_c"] = round(heat, 2)
    T_rec = np.round(T_row + 0.02 * rng.standard_normal(T_row.size), 2)
    # noise, input referred (g): white per row growing with vibration at speed, GM over the run
    white = rng.uniform(3e-6, 3e-5)
    vib = rng.uniform(0, 2) * vibration  # white noise grows with speed: 1 + vib * A / a_max
    noise = [
        {
            "white": white,
            "gm_sigma": rng.uniform(2e-6, 2e-5),
            "gm_tau": rng.uniform(300, 3000),
            "rw_k": rng.uniform(1e-8, 1e-7),
        }
        for _ in range(3)
    ]
    slow(noise, slow_noise)
    wscale = 1 + vib * A / a_max
    C = rows_cov(ta, tb, fhat, np.ones(ta.size), noise)
    C += np.diag(white**2 * (wscale**2 - 1))
    X = np.column_stack([fhat] + [fhat * f] + [fhat * f**2])
    D = rng.uniform(2e-5, 8e-5, 3) * rng.choice([-1, 1], 3)
    u = f + D * f**2
    eff_info, delta = {}, np.zeros_like(f)
    if effect == "cubic":
        c = random_unit(rng)
        unit_d = c * f**3
    elif effect == "lever_arm":
        c = random_unit(rng)  # dr per axis, m
        unit_d = (w**2 / g_loc)[:, None] * c[None, :] * c_body
    elif effect == "misalignment":
        gam = rng.standard_normal(6)
        gam /= np.linalg.norm(gam)
        Phi = np.eye(3)
        Phi[0, 1], Phi[0, 2], Phi[1, 0], Phi[1, 2], Phi[2, 0], Phi[2, 1] = gam

        def unit_d_fn(x):
            P = np.eye(3) + (Phi - np.eye(3)) * x
            return u @ P.T - u

        unit_d = unit_d_fn(1.0)
    elif effect == "temperature_bias":
        c = random_unit(rng)
        unit_d = np.outer(T_row - T_row.mean(), c)
    else:
        unit_d = None
    if unit_d is not None:
        sig = np.sum(fhat * unit_d, axis=1)
        s1 = gls_snr(sig, X, C)
        size = snr / s1
        if effect == "misalignment":
            eff_info = {"gamma_rad [xy,xz,yx,yz,zx,zy]": (gam * size).tolist()}
            delta = unit_d_fn(size)
        else:
            eff_info = {
                "vector": (c * size).tolist(),
                "units": {"cubic": "g/g^3", "lever_arm": "m per axis", "temperature_bias": "g/degC"}[effect],
            }
            delta = unit_d * size
        eff_info.update(snr_unit=s1, snr=snr)
    # the misalignment acts on u (after D): delta for it is already in that space
    nz = np.zeros_like(f)
    for i in range(3):
        Ci = rows_cov(ta, tb, np.eye(3)[[i] * ta.size], np.ones(ta.size), [noise[i]] * 3)
        L = np.linalg.cholesky(Ci + 1e-18 * np.eye(ta.size))
        nz[:, i] = L @ rng.standard_normal(ta.size)
    nz += white * np.sqrt(np.maximum(wscale**2 - 1, 0))[:, None] * rng.standard_normal(f.shape)
    unit = rng.choice(["V", "g", "counts"])
    S = {"V": rng.uniform(0.8, 1.5, 3), "g": 1 + rng.uniform(-0.02, 0.02, 3), "counts": rng.uniform(800, 1200, 3)}[unit]
    b = rng.uniform(0.05, 0.6, 3) * S * rng.choice([-1, 1], 3)
    N = S * (u + delta + nz) + b
    digits = 9
    meta = {
        "procedure": "accel-centrifuge",
        "device": f"BLIND-{seed}",
        "accel_unit": str(unit),
        "radius_m": round(R_m, 4),
    }
    if g_meta in ("site", "both"):
        meta.update(latitude_deg=lat, longitude_deg=lon, altitude_m=alt)
    if g_meta in ("g_mps2", "both"):
        meta["g_mps2"] = g_loc
    _, dstr = date_str(rng, False)
    meta["date"] = dstr
    if rng.random() < 0.5:
        labels = np.array([f"m{k + 1:02d}" for k in k_of])
    else:
        labels = np.array([str(k + 1) for k in k_of])
    cols = [("position", labels, 0), ("speed_rad_s", w, 10)]
    for i, a in enumerate("xyz"):
        cols.append((f"a{a}", N[:, i], digits))
    cols.append(("temp_c", T_rec, 6))
    if rng.random() < 0.5:
        cols.append(("n", np.array([str(int(x * 100)) for x in (tb - ta)]), 0))
    write_capture(out, meta, cols, rng)
    sc.update(
        g_mps2=round(g_loc, 5),
        g_metadata=g_meta,
        radius_m=round(R_m, 3),
        a_max_g=round(a_max, 1),
        n_mountings=n_mount,
        n_speeds=n_speed,
        zero_speed=bool(zero_speed),
        rows=int(ta.size),
        unit=str(unit),
        vibration=round(vib, 2),
        temperature=tinfo,
        noise=[{k: float(f"{v:.3g}") for k, v in nzd.items()} for nzd in noise],
        D_true=D.tolist(),
        hidden=eff_info,
    )
    return sc


# ---------------------------------------------------------------- P5


def gen_ldv(seed, effect, out, snr=10.0, slow_noise=1.0):
    """A land-vehicle drive with turns, skids, reversing and bumps; body frame x fwd, y right, z down."""
    rng = np.random.default_rng(seed)
    sc = {"procedure": "ldv", "seed": seed, "effect": effect}
    fs = float(rng.choice([10, 20, 50, 100]))
    dur = float(min(rng.uniform(300, 1200), 100_000 / fs))
    dt_s = 1 / fs
    tt = np.arange(0, dur, dt_s)
    n = tt.size
    # forward speed: segments toward random targets through a first-order lag (accelerations 0.5-3 m/s^2)
    seg_t = np.cumsum(rng.uniform(8, 40, 200))
    targets = rng.uniform(-6, 25, 200)
    targets[rng.random(200) < 0.25] = 0.0
    target = targets[np.searchsorted(seg_t, tt)]
    v_f = first_order(target, tt, rng.uniform(2, 5))
    yaw_target = rng.uniform(-0.35, 0.35, 200) * (rng.random(200) < 0.6)
    yaw_rate = first_order(yaw_target[np.searchsorted(seg_t, tt)], tt, 1.0)
    skid = rng.uniform(0.05, 0.2)  # sideslip per rad/s of yaw rate... up to ~0.1 rad
    v_lat = v_f * np.tan(np.clip(skid * yaw_rate / 0.35 * rng.choice([1, 1]), -0.2, 0.2)) + gauss_markov(
        rng, n, dt_s, 0.1, 2.0
    )
    v_vert = gauss_markov(rng, n, dt_s, rng.uniform(0.05, 0.25), 0.4)
    v_b = np.column_stack([v_f, v_lat, v_vert])
    w_b = np.column_stack([gauss_markov(rng, n, dt_s, 0.05, 0.3), gauss_markov(rng, n, dt_s, 0.04, 0.4), yaw_rate])
    # a plain car keeps the body velocity within a few degrees of x (ill-conditioned, refused by design);
    # most drives are made with the LDV and INS on a turning plate that crabs the body against the travel
    rig = "car" if rng.random() < 0.15 else "crab_plate"
    if rig == "crab_plate":
        gy = first_order(np.radians(rng.uniform(-35, 35, 200))[np.searchsorted(seg_t, tt)], tt, 2.0)
        gp = first_order(np.radians(rng.uniform(-20, 20, 200))[np.searchsorted(seg_t, tt)], tt, 2.0)
        Rg = Rotation.from_euler("ZY", np.column_stack([gy, gp]))
        v_b = Rg.inv().apply(v_b)
        w_b = Rg.inv().apply(w_b) + np.column_stack([np.zeros(n), np.gradient(gp, dt_s), np.gradient(gy, dt_s)])
    # beams: pointing down and forward/back, each 50-70 deg from x, spread around z
    beams = []
    for j, phi in enumerate(np.radians([0, 120, 240]) + rng.uniform(0, 2 * np.pi)):
        al = np.radians(rng.uniform(50, 70)) * (1 if j != 2 or rng.random() < 0.5 else -1)
        b = np.array([np.cos(al), np.sin(al) * np.sin(phi) * 0.6, np.sin(al) * np.sqrt(1 - 0.36 * np.sin(phi) ** 2)])
        beams.append(b / np.linalg.norm(b))
    beams = np.array(beams)
    dK = rng.uniform(-0.02, 0.02, 3)
    tkind = rng.choice(["warmup", "ramp", "steps", "constant"])
    if effect == "temperature_bias" and tkind == "constant":
        tkind = "warmup"
    T_true, T_rec, tinfo = temperature(rng, tt, tkind)
    ldv_white = rng.uniform(0.005, 0.04) * np.sqrt(fs / 10)
    noise = [
        {
            "white": ldv_white,
            "gm_sigma": rng.uniform(0.002, 0.01),
            "gm_tau": rng.uniform(10, 120),
            "rw_k": rng.uniform(1e-5, 1e-4),
        }
        for _ in range(3)
    ]
    slow(noise, slow_noise)
    ref_white = rng.uniform(0.003, 0.02)
    # SNR rows: 1 s block means per beam, baseline X v per beam (3 columns)
    blk = max(int(fs), 1)
    nb = n // blk
    sl_ = slice(0, nb * blk)
    a_ = tt[sl_].reshape(nb, blk)[:, 0]
    b_ = a_ + blk * dt_s

    def bm(x):
        return x[sl_].reshape(nb, blk, *x.shape[1:]).mean(1)

    vbm = bm(v_b)
    eff_info, add = {}, np.zeros((n, 3))
    accel = np.gradient(v_b, dt_s, axis=0)
    r_lever = None
    if effect == "time_delay":
        unit_sig = -(accel @ beams.T) * (1 + dK)  # per second of delay
    elif effect == "lever_arm":
        r_lever = random_unit(rng)
        unit_sig = (np.cross(w_b, r_lever) @ beams.T) * (1 + dK)  # per metre
    elif effect == "offset":
        c = random_unit(rng)
        unit_sig = np.tile(c, (n, 1))
    elif effect == "temperature_bias":
        c = random_unit(rng)
        unit_sig = np.outer(T_true - T_true.mean(), c)
    elif effect == "time_drift":
        c = random_unit(rng)
        unit_sig = np.outer(tt - tt.mean(), c)
    else:
        unit_sig = None
    if unit_sig is not None:
        sb = bm(unit_sig)
        tot = 0.0
        for j in range(3):
            p = np.zeros((nb, 3))
            p[:, j] = 1
            C = rows_cov(a_, b_, p, np.full(nb, blk), noise)
            C += np.diag(np.full(nb, ref_white**2 / blk))
            tot += gls_snr(sb[:, j], vbm * (1 + dK[j]), C) ** 2
        s1 = float(np.sqrt(tot))
        size = snr / s1
        if effect == "time_delay":
            eff_info = {"delay_s": size}
        elif effect == "lever_arm":
            eff_info = {"r_m": (r_lever * size).tolist()}
        else:
            eff_info = {
                "vector_mps"
                + ("_per_degC" if effect == "temperature_bias" else "_per_s" if effect == "time_drift" else ""): (
                    c * size
                ).tolist()
            }
        eff_info.update(snr_unit=s1, snr=snr)
    v_use = v_b.copy()
    if effect == "time_delay":
        tau = eff_info["delay_s"]
        v_use = np.column_stack([np.interp(tt - tau, tt, v_b[:, i]) for i in range(3)])
    elif effect == "lever_arm":
        v_use = v_b + np.cross(w_b, r_lever * size)
    elif unit_sig is not None:
        add = unit_sig * size
    nz = np.column_stack([axis_noise(rng, tt, **noise[i]) for i in range(3)])
    vl = (v_use @ beams.T) * (1 + dK) + add + nz
    ref = (
        v_b
        + ref_white * rng.standard_normal((n, 3))
        + np.column_stack([gauss_markov(rng, n, dt_s, 0.003 * slow_noise, 60) for _ in range(3)])
    )
    lat, lon, alt = site(rng)
    _, dstr = date_str(rng, rng.random() < 0.5)
    meta = {
        "procedure": "ldv",
        "device": f"BLIND-{seed}",
        "latitude_deg": lat,
        "longitude_deg": lon,
        "altitude_m": alt,
        "date": dstr,
    }
    if rng.random() < 0.5:
        meta["sample_rate_hz"] = fs
    frame = rng.choice(["body", "nav"])
    cols = [("t", np.char.mod("%.4f", tt), 0)]
    for j in range(3):
        cols.append((f"vl{j + 1}", vl[:, j], 7))
    if frame == "body":
        for i, a in enumerate("xyz"):
            cols.append((f"v{a}", ref[:, i], 7))
    else:
        yaw = np.cumsum(yaw_rate) * dt_s + rng.uniform(0, 2 * np.pi)
        pitch = np.cumsum(w_b[:, 1]) * dt_s
        roll = np.cumsum(w_b[:, 0]) * dt_s
        pitch = pitch - first_order(pitch, tt, 5.0)  # bumps, no lasting tilt
        roll = roll - first_order(roll, tt, 5.0)
        Rn = Rotation.from_euler("ZYX", np.column_stack([yaw, pitch, roll]))
        vn = Rn.apply(ref)
        for i, a in enumerate(["vn", "ve", "vd"]):
            cols.append((a, vn[:, i], 7))
        cols += [
            ("roll_deg", np.degrees(roll), 7),
            ("pitch_deg", np.degrees(pitch), 7),
            ("yaw_deg", np.degrees(np.mod(yaw, 2 * np.pi)), 7),
        ]
    rate_cols = effect == "lever_arm" or rng.random() < 0.6
    if rate_cols:
        wr = w_b + 0.002 * rng.standard_normal((n, 3))
        for i, a in enumerate("xyz"):
            cols.append((f"w{a}", wr[:, i], 6))
    cols.append(("temp_c", T_rec, 6))
    write_capture(out, meta, cols, rng)
    H = v_b
    cond = float(np.linalg.cond(H.T @ H))
    sc.update(
        rig=rig,
        fs_hz=fs,
        duration_s=round(dur, 1),
        frame=str(frame),
        rate_columns=bool(rate_cols),
        rows=n,
        beams=beams.round(4).tolist(),
        dK=dK.round(4).tolist(),
        cond_HtH=round(cond, 1),
        temperature=tinfo,
        noise=[{k: float(f"{v:.3g}") for k, v in nzd.items()} for nzd in noise],
        ref_white_mps=round(ref_white, 4),
        hidden=eff_info,
    )
    return sc


GENERATORS = {
    "ldv": gen_ldv,
    "accel-centrifuge": gen_centrifuge,
    "accel-tabletop": gen_tabletop,
    "compass": gen_compass,
    "gyro-drift": gen_gyrodrift,
}


def generate(procedure, effect, seed, out, snr=10.0, **opts):
    eff = None if effect in (None, "none", "") else effect
    return GENERATORS[procedure](seed, eff, out, snr, **opts)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--procedure", required=True, choices=sorted(GENERATORS))
    ap.add_argument("--effect", default="none")
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--snr", type=float, default=10.0)
    ap.add_argument("--out", required=True)
    ap.add_argument("--soft-iron", default="upper", choices=["upper", "symmetric"], help="compass only")
    ap.add_argument("--slow-noise", type=float, default=1.0, help="scale of the Gauss-Markov and random-walk noise")
    ap.add_argument("--averages", type=int, choices=[0, 1], default=None, help="P1: force a table of averages or not")
    a = ap.parse_args(argv)
    opts = {"soft_iron": a.soft_iron} if a.procedure == "compass" else {}
    if a.procedure == "accel-tabletop" and a.averages is not None:
        opts["averages"] = bool(a.averages)
    if a.slow_noise != 1.0:
        opts["slow_noise"] = a.slow_noise
    sc = generate(a.procedure, a.effect, a.seed, a.out, a.snr, **opts)
    json.dump(sc, sys.stdout, indent=1, default=float)
    print()


if __name__ == "__main__":
    main()
