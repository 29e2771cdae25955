"""The gyro half of a P1 tabletop session: the ``gyro`` block of the accel-tabletop result.

A time series with ``gx gy gz`` holds the rotations between the static positions; with the
accelerometer calibrated, each hold's gravity direction is known, and
``solvers.tabletop_gyro`` fits the gyro's scale factors, misalignment, bias and (when the
holds span enough orientations) g-sensitivity to them. This module turns the capture and
the accelerometer result into its inputs and the block into plain data.

Metadata read: ``gyro_unit`` (rad/s, deg/s, ... or ``counts``; for counts a
``gyro_counts_per_rad_s`` or ``gyro_counts_per_deg_s`` starting scale, else one is searched
for), ``latitude_deg`` (the Earth rate's vertical part removed where given).
"""

from __future__ import annotations

import math

import numpy as np

from solvers import tabletop_gyro as TG
from solvers.allan import hold_mean_se
from solvers.errors import SolverError
from solvers.models import accel
from solvers.units import si_factor
from station.errors import InputError

MODEL = "y = K ω + ε + G f"
# why a stated sample_rate_hz that the t column contradicts leaves the gyro uncalibrated: the
# rotations are integrated over t (the accelerometer's holds do not depend on it)
RATE_CONSEQUENCE = "the rotations between the holds are integrated over t"


def has_gyro(capture) -> bool:
    """Whether the capture holds a gyro time series (the rotations between the holds)."""
    return capture.is_time_series and all(c in capture.columns for c in ("gx", "gy", "gz", "t"))


def _gyro(capture) -> np.ndarray | None:
    if not has_gyro(capture):
        return None
    return np.column_stack([np.asarray(capture.columns[c], dtype=float) for c in ("gx", "gy", "gz")])


def _start_scale(capture, holds, motions, notes: list[str]) -> float:
    unit = capture.meta.get("gyro_unit")
    if unit == "counts":
        per_rad = capture.float_meta_within("gyro_counts_per_rad_s", None, 1e12)
        per_deg = capture.float_meta_within("gyro_counts_per_deg_s", None, 1e10)
        if per_rad:
            return per_rad
        if per_deg:
            return per_deg * 180.0 / math.pi
        s = TG.scale_search(holds, motions)
        notes.append(
            f"gyro in counts with no nominal scale: starting scale {s:.4g} counts per rad/s found by "
            "matching the rotations"
        )
        return s
    f = si_factor("gyro", unit) if unit else 1.0
    if f is None:
        raise SolverError(f"gyro_unit {unit!r} is not a rate unit")
    return 1.0 / f


def inputs(capture, positions, B, M) -> tuple[list[TG.Hold], list[TG.Motion], np.ndarray, list[str]] | None:
    """Holds, motions between consecutive holds, the per-sample gyro noise and notes; None
    when the capture has no gyro time series."""
    y = _gyro(capture)
    if y is None or not positions or any(p.t_start_s is None for p in positions):
        return None
    t = np.asarray(capture.columns["t"], dtype=float)
    raw_a = np.column_stack([np.asarray(capture.column(c), dtype=float) for c in ("ax", "ay", "az")])
    f_all = accel.p1_apply(raw_a, B, M)
    notes: list[str] = []
    holds, spans, stds = [], [], []
    for p in sorted(positions, key=lambda q: q.t_start_s):
        i0, i1 = int(np.searchsorted(t, p.t_start_s)), int(np.searchsorted(t, p.t_stop_s, side="right")) - 1
        seg = y[i0 : i1 + 1]
        ok = np.all(np.isfinite(seg), axis=1)
        if ok.sum() < 16:
            continue
        se = hold_mean_se(seg[ok], t[i0 : i1 + 1][ok])
        sd = seg[ok].std(axis=0, ddof=1)
        se = se if se is not None else sd / math.sqrt(ok.sum())
        f = accel.p1_apply(p.mean[None], B, M)[0]
        a_se = p.se if p.se is not None else (p.std / math.sqrt(max(p.n, 1)) if p.std is not None else np.zeros(3))
        dir_sig = float(np.linalg.norm(np.asarray(M) @ a_se) / np.linalg.norm(f) / math.sqrt(3.0))
        holds.append(TG.Hold(p.label, seg[ok].mean(axis=0), se, f, dir_sig, p.t_start_s, p.t_stop_s))
        spans.append((i0, i1))
        stds.append(sd)
    lo, hi = np.nanmin(y, axis=0), np.nanmax(y, axis=0)
    motions = []
    for k in range(len(holds) - 1):
        a, b = spans[k][1], spans[k + 1][0]
        seg = y[a : b + 1]
        if b <= a or not np.all(np.isfinite(seg)) or not np.all(np.isfinite(f_all[a : b + 1])):
            notes.append(
                f"gyro: the motion from hold {holds[k].label} to {holds[k + 1].label} has missing samples: left out"
            )
            continue
        clipped = np.any((seg <= lo) | (seg >= hi), axis=0) & (hi - lo > 0) & _at_limit(capture, lo, hi)
        if clipped.any():
            notes.append(
                f"gyro: the motion from hold {holds[k].label} to {holds[k + 1].label} reaches the "
                f"range limit on {', '.join('xyz'[i] for i in np.flatnonzero(clipped))}: left out"
            )
            continue
        a, b = _moving_span(t, y, a, b, holds[k].y_mean, holds[k + 1].y_mean, stds[k])
        motions.append(TG.Motion(k, k + 1, t[a : b + 1], y[a : b + 1], f_all[a : b + 1]))
    noise = np.median(np.array(stds), axis=0) if stds else np.ones(3)
    return holds, motions, noise, notes


def _moving_span(t, y, a: int, b: int, y0, y1, sd, margin_s: float = 0.5) -> tuple[int, int]:
    """The part of samples a..b where the unit turns (any axis beyond 6σ of both holds' means),
    with ``margin_s`` either side: the still stretches around a turn (placing, settling) add
    only noise and bias to the integral."""
    seg = y[a : b + 1]
    sd = np.maximum(np.asarray(sd, dtype=float), 1e-12)
    moving = np.any(np.abs(seg - y0) > 6 * sd, axis=1) & np.any(np.abs(seg - y1) > 6 * sd, axis=1)
    idx = np.flatnonzero(moving)
    if len(idx) == 0:
        return a, b
    lo = int(np.searchsorted(t, t[a + idx[0]] - margin_s))
    hi = int(np.searchsorted(t, t[a + idx[-1]] + margin_s, side="right")) - 1
    return max(a, lo), min(b, hi)


def _at_limit(capture, lo, hi) -> np.ndarray:
    """Per axis: is the extreme reading a plausible range limit (the 16-bit ends for counts)?"""
    if capture.meta.get("gyro_unit") == "counts":
        return (lo <= 0) | (hi >= 65535) | (np.abs(lo) >= 32768) | (np.abs(hi) >= 32767)
    return np.zeros(3, dtype=bool)


def block(capture, positions, B, M, g_mps2: float) -> dict | None:
    """The ``gyro`` block of the accel-tabletop result, or None when the capture has no gyro
    time series. A gyro fit that cannot be done is a block with ``error`` (the accelerometer
    result stands on its own)."""
    got = inputs(capture, positions, B, M)
    if got is None:
        return None
    holds, motions, noise, notes = got
    try:
        capture.series_rate_hz(RATE_CONSEQUENCE)
    except InputError as exc:  # t in ms, or the wrong rate: the turns would come out 1000 times too large
        where = f"line {exc.line}: " if exc.line else ""
        return {
            "procedure": "gyro-tabletop",
            "error": where + exc.message,
            "warnings": notes,
            "n_rotations": len(motions),
        }
    unit = capture.meta.get("gyro_unit") or "rad/s"
    lat = capture.float_meta("latitude_deg")
    try:
        K0 = np.eye(3) * _start_scale(capture, holds, motions, notes)
        r = TG.calibrate(holds, motions, K0, noise_raw=noise, latitude_deg=lat)
    except (SolverError, np.linalg.LinAlgError) as exc:
        return {"procedure": "gyro-tabletop", "error": str(exc), "warnings": notes, "n_rotations": len(motions)}
    warnings = notes + r.warnings
    if lat is None:
        warnings.append(
            "gyro: no latitude_deg: the Earth rate (≤ 7.3e-5 rad/s) stays in the bias and in G's "
            "uncertainty (its vertical part is indistinguishable from a g-sensitivity)"
        )
    A = np.linalg.inv(r.K)
    params = {"K": r.K, "eps": r.eps}
    unc = {"K": r.sigma_K, "eps": r.sigma_eps}
    if r.G is not None:
        params["G"], unc["G"] = r.G, r.sigma_G
    scale = np.diag(r.K)
    return {
        "procedure": "gyro-tabletop",
        "model": MODEL,
        "params": params,
        "uncertainty": unc,
        "units": {
            "y": unit,
            "K": f"{unit} per rad/s",
            "eps": unit,
            "G": f"{unit} per m/s^2",
            "omega": "rad/s",
            "f": "m/s^2 (calibrated accelerometer)",
        },
        "frame": "the accelerometer calibration's frame (its gauge): K's off-diagonal is the gyro's misalignment "
        "to the accelerometer triad",
        "scale": scale,
        "sigma_scale": np.diag(r.sigma_K),
        "misalignment": r.K / scale[:, None] - np.eye(3),
        "inverse": {"A": A, "note": "ω = A (y − ε − G f), A = K⁻¹ (imu_tk's T·K)"},
        "residual_rms": r.direction_rms_rad,
        "direction_residual_deg": np.degrees(r.direction_residual_rad),
        "direction_rms_deg": math.degrees(r.direction_rms_rad),
        "n_holds": len(holds),
        "n_rotations": len(motions),
        "earth_rate": (
            {"removed_up_rad_s": r.earth_rate_up_rad_s, "latitude_deg": lat}
            if lat is not None
            else {"fitted_up_rad_s": r.earth_rate_up_rad_s, "sigma_up_rad_s": r.sigma_earth_rate_up_rad_s}
        ),
        "reduced_chi2": r.fit.reduced_chi2,
        "g_sensitivity_fitted": r.G is not None,
        "warnings": warnings,
    }


def format_lines(block: dict) -> list[str]:
    """The gyro block in the plain report."""
    from station.calibrate import jsonable
    from station.formatting import param_lines

    if block is None:
        return []
    b = jsonable(block)
    if "error" in b:
        return [f"gyro       not calibrated: {b['error']}"] + [f"warning    {w}" for w in b.get("warnings", [])]
    u = b["units"]
    lines = [
        f"gyro       {b['model']} (y in {u['y']}, ω in rad/s, f in m/s^2), from {b['n_rotations']} rotations "
        f"between {b['n_holds']} holds"
    ]
    lines += param_lines(f"K [{u['K']}]", jsonable(b["params"]["K"]), jsonable(b["uncertainty"]["K"]))
    lines += param_lines(f"ε [{u['eps']}]", jsonable(b["params"]["eps"]), jsonable(b["uncertainty"]["eps"]))
    if "G" in b["params"]:
        lines += param_lines(f"G [{u['G']}]", jsonable(b["params"]["G"]), jsonable(b["uncertainty"]["G"]))
    lines.append(f"gyro residual {b['direction_rms_deg']:.3g}° RMS (gravity direction carried across each rotation)")
    for w in b["warnings"]:
        lines.append(f"warning    {w}")
    return lines


def diagnosis_input(capture, base: dict, prepared):
    """The gyro problem of a P1 session for ``station diagnose`` (the ``gyro`` part of the
    accel-tabletop diagnosis, ``tabletop.SUB_DIAGNOSES``): the holds' gyro samples in rad/s
    through the session's fitted ``K``, the
    calibrated specific force, one label per hold. The baseline is a constant bias; the gyro
    model's effects (temperature, time drift, g-sensitivity, Earth rate) are the candidates
    (``solvers.diagnose.problems.gyro_problem``). ``prepared``: ``tabletop.prepare(capture)``,
    the holds the accelerometer's calibration used (this module never imports tabletop: it is
    the lower of the two). None when the result has no gyro block."""
    from solvers.diagnose import problems as DP
    from station.procedures.contract import DiagnosisInput
    from station.procedures.diagnose import moved_positions, screen

    gb = (base or {}).get("gyro")
    if not isinstance(gb, dict) or "params" not in gb:
        return None
    prep = prepared
    B, M = np.asarray(base["params"]["B"], float), np.asarray(base["params"]["M"], float)
    A = np.linalg.inv(np.asarray(gb["params"]["K"], float))
    t = np.asarray(capture.columns["t"], dtype=float)
    y = _gyro(capture)
    raw_a = np.column_stack([np.asarray(capture.column(c), dtype=float) for c in ("ax", "ay", "az")])
    temp = capture.columns.get("temp_c")
    bad, screened = screen(capture, moved_positions(capture))  # the data-quality screen, as the accelerometer's
    rows, labels = [], []
    for p in sorted(prep.positions, key=lambda q: q.t_start_s):
        i = np.flatnonzero((t >= p.t_start_s) & (t <= p.t_stop_s) & np.all(np.isfinite(y), axis=1) & ~bad)
        rows.append(i)
        labels += [p.label] * len(i)
    idx = np.concatenate(rows)
    prob = DP.gyro_problem(
        t[idx],
        y[idx] @ A.T,
        accel.p1_apply(raw_a[idx], B, M),
        None if temp is None else np.asarray(temp, float)[idx],
        None,
        np.array(labels, dtype=object),
    )
    prob.screened = screened
    drivers = {"position": labels, "time_s": t[idx]}
    return DiagnosisInput(
        prob, drivers, "a hold whose gyro mean disagrees: the unit moved, or the bias jumped", group_kind="time block"
    )
