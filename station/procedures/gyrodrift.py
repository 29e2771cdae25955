"""P4 gyro drift from a capture: mode A (reference IMU) and mode B (static base).

``calibrate(capture, method=None, *, accuracy_deg_h=None) -> dict`` (calibrate.md).

Mode: ``method`` ('reference' | 'static'), else the ``gyro_mode`` metadata, else
'reference' when ``ref_gx ref_gy ref_gz`` are present. Metadata read:

- ``gyro_unit`` (rad/s, deg/s, ...; ``counts`` needs ``gyro_counts_per_deg_s``, e.g. 131
  for an MPU-6050 at ±250 °/s); ``accel_unit`` (any: only the direction is used);
- ``latitude_deg``, ``heading_deg`` (default 0 with a warning), ``heading_sigma_deg``
  (default 3), ``accuracy_deg_h`` (the 1-sigma asked; also the keyword argument);
- ``reference_drift_deg_h``: the reference IMU's own drift, 1 sigma (default 1 °/h);
- axis conventions, when the capture is not in P4's body frame: ``frame`` (e.g.
  ``x forward, y left, z up``), ``accel_sign`` (``specific_force`` default, or
  ``gravity`` for data that report the gravity direction), ``gyro_flip`` (axes whose sign
  is reversed, e.g. ``x``). Known devices (``KNOWN_CONVENTIONS``) get theirs with a
  warning. Every conversion is stated in ``warnings``; ``drift`` is in P4's body frame
  (x fwd, y up, z right) and ``drift_raw`` in the capture's own axes and gyro unit.

Positions (mode B): a ``position`` column splits the record; without one, static intervals
are found (solvers.stillness) and moving samples dropped; intervals of different orientation
(or of a different per-row ``heading_deg``, which labels the holds but does not bound them)
become positions. Two or more positions: ε and the
Earth-rate scale together (solvers.gyrodrift.drift_multi).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from solvers import allan, frames
from solvers import gyrodrift as gd
from solvers.errors import SolverError
from solvers.models import gyro as gyro_model
from solvers.units import si_factor
from station.capture import fill_missing, span_step_s, strictly_increasing_t
from station.errors import InputError, UnsupportedError
from station.procedures.contract import DiagnosisInput

MODEL = "ω' = ω − ε (P4); mode B: ε^b = ω̄^b − C_b_n ω_ie^n, body x fwd, y up, z right, nav N-U-E"
DIAGNOSIS_BASELINE = False  # diagnosis_input fits its own baseline (the drift is a block of the problem)
# station.guard: columns read as measurements (present but empty in every row: refused), and
# the parameters this procedure exists to deliver (any of them non-finite: refused)
MEASURED = ("gx", "gy", "gz", "ax", "ay", "az", "ref_gx", "ref_gy", "ref_gz")
CORE_PARAMS = ("drift",)
# station.procedures.review: each parameter block's unit; a drift indistinguishable from zero
# is a good gyro, not a failed fit
PARAM_UNITS = {"drift": "rad/s", "earth_rate_body": "rad/s"}
PARAM_SHAPES = {"drift": (3,), "earth_rate_body": (3,), "pitch_deg": (), "roll_deg": ()}  # every parameter
# what the screens show them in (a bench engineer reads gyro drift in °/h); the result, its
# exports and the database keep rad/s
# what residual_rms is over, said beside it (the Results screen, `station calibrate`): the
# samples about the fitted drift; `station diagnose` fits block means and says so beside its own
RESIDUAL_OF = "per sample"
DISPLAY_UNITS = {k: ("°/h", 1.0 / gd.DEG_H_RAD_S) for k in ("drift", "earth_rate_body", "residual_rms")}
LIMIT_EXAMPLE = "e.g. drift=-10:10  (°/h)"  # the limits box's example, in the unit shown
# why a stated sample_rate_hz that the t column contradicts is refused (Capture.series_rate_hz)
RATE_CONSEQUENCE = "the drift's error (Allan deviation) and the record's length scale with the rate"
ZERO_IS_A_RESULT = True
# rad/s per sample and axis: the least rate noise the stillness detector assumes (mode B without
# positions). P4's gyros are low-cost MEMS, whose samples carry 1e-4 to 1e-2 rad/s of noise (the
# best, ADIS16490 class, 8e-5 rad/s at 10 Hz); noise-free simulated rates measure ~0, and a bias
# drifting by 2e-7 rad/s per s was then a turn (6.6 s of 300 kept, refused as too short). With
# it a window is a turn above 10·√3·3e-5 = 5e-4 rad/s (0.03 °/s, 100 °/h), far below a turn by hand
GYRO_STD_FLOOR_RAD_S = 3e-5

# Devices whose captures are known to break the conventions (their SOURCE.md).
KNOWN_CONVENTIONS = {
    "sunsided-mpu6050-hmc5883l": {"frame": "x forward, y left, z up", "accel_sign": "gravity", "gyro_flip": "x"},
}

_DIRS = {
    "forward": (1, 0, 0),
    "fwd": (1, 0, 0),
    "front": (1, 0, 0),
    "back": (-1, 0, 0),
    "backward": (-1, 0, 0),
    "up": (0, 1, 0),
    "down": (0, -1, 0),
    "right": (0, 0, 1),
    "left": (0, 0, -1),
}


def frame_matrix(text: str) -> np.ndarray:
    """``C_fur_cap``: the capture's axes (described as 'x forward, y left, z up') → P4's
    body frame (x fwd, y up, z right). ValueError when not a right-handed triad."""
    found = dict(
        re.findall(r"\b([xyz])\s*[:=]?\s*(forward|fwd|front|backward|back|up|down|right|left)\b", text.lower())
    )
    if set(found) != {"x", "y", "z"}:
        raise ValueError(f"frame {text!r}: say where x, y and z point (forward/back/up/down/left/right)")
    M = np.column_stack([_DIRS[found[a]] for a in "xyz"]).astype(float)
    if abs(np.linalg.det(M) - 1.0) > 1e-9:
        raise ValueError(f"frame {text!r} is not a right-handed triad")
    return M


BODY_AXES = "x forward, y up, z right"  # P4's body frame, the axes of its drift


def body_axes(meta: dict) -> tuple[np.ndarray, np.ndarray]:
    """``(C_fur_cap, gyro_flips)`` from capture metadata alone (``frame``, ``gyro_flip``, a
    known device's conventions): what :func:`prepare` applies to the gyro columns, so
    ``C_fur_cap @ (gyro_flips * ω_capture)`` is a rate in P4's body frame, the drift's
    axes (without a ``frame`` the capture's axes are taken as P4's). InputError for a
    frame that is not a right-handed triad."""
    from station.capture import Capture

    C, _, flips = _conventions(Capture(meta=dict(meta), columns={}), [])
    return C, flips


def _line(capture, key):
    return capture.meta_lines.get(key) if hasattr(capture, "meta_lines") else None


def _conventions(capture, warnings: list[str]):
    """(C_fur_cap, accel_sign, gyro_signs) from metadata or the known-device table."""
    meta = capture.meta
    known = KNOWN_CONVENTIONS.get(meta.get("device", ""), {})
    conv = {}
    for key in ("frame", "accel_sign", "gyro_flip"):
        if key in meta:
            conv[key] = meta[key]
        elif key in known:
            conv[key] = known[key]
            warnings.append(
                f"device {meta.get('device')!r}: {key} '{known[key]}' assumed from its known "
                "conventions (SOURCE.md); say so in the metadata to silence this"
            )
    C = np.eye(3)
    if "frame" in conv:
        try:
            C = frame_matrix(conv["frame"])
        except ValueError as exc:
            raise InputError(capture.path, _line(capture, "frame"), str(exc)) from None
        if not np.allclose(C, np.eye(3)):
            warnings.append(f"capture axes '{conv['frame']}' rotated into P4's body frame (x forward, y up, z right)")
    sign = conv.get("accel_sign", "specific_force").strip().lower().replace("-", "_").replace(" ", "_")
    if sign not in ("specific_force", "gravity"):
        raise InputError(
            capture.path,
            _line(capture, "accel_sign"),
            f"accel_sign {conv['accel_sign']!r}: use 'specific_force' or 'gravity'",
        )
    if sign == "gravity":
        warnings.append("accelerometer reports the gravity direction (not specific force): sign flipped for tilt")
    flips = np.ones(3)
    for axis in re.findall(r"[xyz]", conv.get("gyro_flip", "").lower()):
        flips["xyz".index(axis)] = -1.0
    if (flips < 0).any():
        warnings.append(f"gyro axis {conv['gyro_flip']} sign reversed to right-handed before use")
    return C, (-1.0 if sign == "gravity" else 1.0), flips


def _gyro_factor(capture, warnings: list[str]) -> float:
    unit = capture.meta.get("gyro_unit")
    if unit is None:
        warnings.append("no gyro_unit: gyro taken as rad/s")
        return 1.0
    if unit == "counts":
        lsb = capture.float_meta_within("gyro_counts_per_deg_s", None, 1e9)
        if lsb is None or lsb <= 0:
            raise UnsupportedError(
                f"{capture.path or 'capture'}: gyro_unit is 'counts' and no 'gyro_counts_per_deg_s' gives "
                "the scale (MPU-6050 at ±250 °/s: 131); add it to the metadata"
            )
        warnings.append(f"gyro in counts: nominal scale {lsb:g} counts per °/s used (its error scales the drift)")
        return math.radians(1.0) / lsb
    f = si_factor("gyro", unit)
    if f is None:
        raise InputError(capture.path, _line(capture, "gyro_unit"), f"gyro_unit {unit!r} is not a rate unit")
    return f


def _dt(capture) -> float:
    if not capture.is_time_series and "n" in capture.columns:
        raise UnsupportedError(
            f"{capture.path or 'capture'}: a table of averages cannot give a drift's error (Allan "
            "deviation): gyro-drift needs the time series"
        )
    coarse_step = None
    if capture.is_time_series:
        capture.series_rate_hz(RATE_CONSEQUENCE)  # a file that contradicts itself: t in ms, or the wrong rate
        t = capture.columns["t"]
        d = np.diff(t[np.isfinite(t)])
        if len(d) and np.median(d) > 0:
            return float(np.median(d))
        # coarse time stamps (whole seconds, host clock ticks): most rows share their t with the
        # previous one (t is non-decreasing), so the median step is 0; the rows over the span give the step
        coarse_step = span_step_s(t)
    rate = capture.float_meta("sample_rate_hz")
    if (rate is None or rate <= 0) and coarse_step is not None:
        return coarse_step
    if rate is None or rate <= 0:
        raise UnsupportedError(
            f"{capture.path or 'capture'}: gyro drift needs a time series: a 't' column with at least two "
            "increasing times, or sample_rate_hz"
        )
    return 1.0 / rate


def _need(capture, names):
    missing = [c for c in names if c not in capture.columns]
    if missing:
        raise InputError(
            capture.path,
            capture.header_line,
            f"gyro-drift needs column(s) {', '.join(missing)} (have {', '.join(capture.columns)})",
        )
    return np.column_stack([capture.columns[c] for c in names]).astype(float, copy=False)


def _finite_rows(arrays, warnings, what):
    ok = np.ones(len(arrays[0]), dtype=bool)
    for a in arrays:
        if a is not None:
            ok &= np.all(np.isfinite(a), axis=1)
    if not ok.all():
        warnings.append(f"{int((~ok).sum())} rows with missing {what} values left out")
    return ok


@dataclass
class Prepared:
    """A P4 capture read once: its axis conventions and the gyro rates in P4's body frame."""

    C_fur_cap: np.ndarray  # the capture's axes → P4 body (x fwd, y up, z right)
    accel_sign: float  # +1 specific force, −1 gravity direction
    gyro_flips: np.ndarray  # per-axis sign making the gyro right-handed
    gyro_factor: float  # capture's gyro unit → rad/s (1.0 when unknown, see gyro_unit_error)
    gyro_unit_error: str | None  # why the gyro cannot be put in rad/s (counts without a scale), else None
    w_b: np.ndarray  # gyro (n, 3) in P4's body frame: rad/s, or the raw unit with gyro_unit_error
    warnings: list[str] = field(default_factory=list)


def prepare(capture) -> Prepared:
    """Axis conventions, the gyro unit and the rotated gyro rates of ``capture``."""
    warnings: list[str] = []
    C, asign, flips = _conventions(capture, warnings)
    err = None
    try:
        k = _gyro_factor(capture, warnings)
    except UnsupportedError as exc:  # counts without a scale: calibrate refuses, diagnose works in counts
        k, err = 1.0, str(exc)
    w_b = (_need(capture, ["gx", "gy", "gz"]) * flips * k) @ C.T
    return Prepared(C, asign, flips, k, err, w_b, warnings)


def calibrate(
    capture, method: str | None = None, *, accuracy_deg_h: float | None = None, prepared: Prepared | None = None
) -> dict:
    mode = (
        (method or capture.meta.get("gyro_mode") or ("reference" if "ref_gx" in capture.columns else "static"))
        .strip()
        .lower()
    )
    if mode in ("a", "ref"):
        mode = "reference"
    if mode in ("b", "static-base"):
        mode = "static"
    if mode not in ("reference", "static"):
        raise UnsupportedError(f"gyro-drift mode {mode!r}: use 'reference' (mode A) or 'static' (mode B)")
    prep = prepared if prepared is not None else prepare(capture)
    if prep.gyro_unit_error:
        raise UnsupportedError(prep.gyro_unit_error)
    warnings = list(prep.warnings)
    C, asign, flips, k = prep.C_fur_cap, prep.accel_sign, prep.gyro_flips, prep.gyro_factor
    w_b = prep.w_b  # rad/s, P4 body frame
    dt = _dt(capture)
    if accuracy_deg_h is None:
        accuracy_deg_h = capture.float_meta_within("accuracy_deg_h", None, 1e6)
    acc_rad_s = None if accuracy_deg_h is None else accuracy_deg_h * gd.DEG_H_RAD_S
    try:
        if mode == "reference":
            res, me_for_acc, n_pos, resid = _mode_a(capture, w_b, C, flips, dt, warnings)
        else:
            res, me_for_acc, n_pos, resid = _mode_b(capture, w_b, C, asign, dt, warnings)
    except SolverError as exc:
        raise UnsupportedError(f"{capture.path or 'capture'}: {exc}") from None
    warnings[:0] = []
    warnings += res.warnings
    acc, acc_w = gd.accuracy_statement(me_for_acc, res.sigma_rad_s, acc_rad_s)
    warnings += acc_w
    return _result(capture, res, mode, n_pos, resid, acc, me_for_acc, C, flips, k, warnings)


def _mode_a(capture, w_b, C, flips, dt, warnings):
    ref = _need(capture, ["ref_gx", "ref_gy", "ref_gz"])
    ref_b = ref @ C.T  # reference in rad/s (capture-format.md), same axes as the gyro columns
    ok = _finite_rows([w_b, ref_b], warnings, "gyro or reference")
    ref_drift = capture.float_meta_within("reference_drift_deg_h", 1.0, 1e6, zero=True) * gd.DEG_H_RAD_S
    res = gd.drift_reference(w_b[ok], ref_b[ok], dt, ref_drift)
    resid = w_b[ok] - ref_b[ok] - res.drift_rad_s
    return res, res.mean_error, 1, resid


def _segments(capture, w_b, f_b, dt, ok, warnings):
    """[(row mask, heading_deg, label)] for mode B. Headings are known (for several
    positions) when there is a ``heading_deg`` column or the metadata gives one for all."""
    head0 = capture.float_meta("heading_deg")
    if head0 is None:
        head0 = 0.0
        if capture.float_meta("latitude_deg") is not None and "heading_deg" not in capture.columns:
            warnings.append(
                "no heading_deg: forward axis taken as pointing north (heading 0) for a single "
                "position; with several positions the headings count as unknown"
            )
    hcol = capture.columns.get("heading_deg")
    pcol = capture.columns.get("position")
    if pcol is not None and np.any(pcol != ""):
        labels = [p for p in dict.fromkeys(pcol) if p != ""]
        segs = []
        for lab in labels:
            m = ok & (pcol == lab)
            h = hcol[m] if hcol is not None else np.array([head0])
            h = h[np.isfinite(h)]
            segs.append((m, float(np.median(h)) if len(h) else head0, str(lab)))
        return segs
    heads = hcol is not None and bool(np.any(np.isfinite(hcol)))
    if (f_b is None or not capture.is_time_series) and heads:
        return _heading_runs(hcol, ok)
    if f_b is None or not capture.is_time_series:
        return [(ok, head0, "1")]
    from solvers.stillness import detect_static_intervals

    idx = np.flatnonzero(ok)
    rows = slice(None) if len(idx) == len(ok) else idx  # every row finite: views, not (N, 3) copies
    st, why = None, "no static interval found"
    try:
        st = detect_static_intervals(
            strictly_increasing_t(capture.columns["t"][rows]), f_b[rows], w_b[rows], gyro_std_floor=GYRO_STD_FLOOR_RAD_S
        )
    except SolverError as exc:
        why = f"stillness detection failed ({exc})"
    if st is None or not st.intervals:
        if heads:  # the heading column still tells the holds apart
            warnings.append(f"{why}; each heading's rows taken as static")
            return _heading_runs(hcol, ok)
        if st is None:
            warnings.append(f"{why}; the whole record taken as static")
            return [(ok, head0, "1")]
        raise UnsupportedError(f"{capture.path or 'capture'}: {why}; mode B needs the unit at rest")
    # group intervals of the same orientation (accelerometer direction within 5°) and, with a
    # heading column, the same heading: the column labels the holds, it does not bound them (it
    # changes somewhere in the turn between two holds, whose samples are not at rest)
    groups: list[list] = []
    for iv in st.intervals:
        u = iv.accel_mean / np.linalg.norm(iv.accel_mean)
        rows_iv = idx[iv.start : iv.stop]
        parts = [(rows_iv, head0)]
        if heads:
            h = np.round(hcol[rows_iv], 6)
            parts = [(rows_iv[h == v], float(v)) for v in dict.fromkeys(h[np.isfinite(h)])]
        for r, hd in parts:
            for g in groups:
                if g[2] == hd and float(np.dot(u, g[0])) > math.cos(math.radians(5.0)):
                    g[1].append(r)
                    break
            else:
                groups.append([u, [r], hd])
    segs = []
    for j, (_, parts, hd) in enumerate(groups):
        m = np.zeros(len(ok), dtype=bool)
        for r in parts:
            m[r] = True
        segs.append((m, hd, f"heading {hd:g}" if heads else str(j + 1)))
    if heads and len({s[2] for s in segs}) < len(segs):  # one heading, two tilts: tell them apart
        segs = [(m, hd, f"{lab} #{j + 1}") for j, (m, hd, lab) in enumerate(segs)]
    used = sum(int(s[0].sum()) for s in segs)
    if used < ok.sum():
        warnings.append(f"{int(ok.sum()) - used} moving samples left out (stillness detection)")
    if len(segs) > 1 and not heads and capture.float_meta("heading_deg") is not None:
        warnings.append(
            f"{len(segs)} static orientations found with no heading column: all taken as "
            f"heading {head0:g}° (the metadata's); the Earth-rate scale checks this"
        )
    return segs


def _heading_runs(hcol, ok):
    """[(row mask, heading_deg, label)]: each heading value's rows, moving or not (a table, or a
    record the stillness detector cannot read)."""
    vals = [v for v in dict.fromkeys(np.round(hcol[np.isfinite(hcol)], 6))]
    return [(ok & (np.round(hcol, 6) == v), float(v), f"heading {v:g}") for v in vals]


def _mode_b(capture, w_b, C, asign, dt, warnings):
    have_acc = all(c in capture.columns for c in ("ax", "ay", "az"))
    f_b = None
    unit = capture.meta.get("accel_unit")
    offset = capture.meta.get("accel_offset")
    if have_acc and unit in ("V", "mV") and offset is None:
        have_acc = False
        warnings.append(
            f"accelerometer in {unit} with no 'accel_offset' metadata: its zero-g output is "
            "unknown, so pitch and roll cannot be measured and are not used (give accel_offset: "
            "x, y, z in the accelerometer's unit, e.g. from its P1 calibration)"
        )
    if have_acc:
        raw = _need(capture, ["ax", "ay", "az"])
        if offset is not None:
            try:
                off = np.array([float(v) for v in offset.replace(",", " ").split()])
            except ValueError:
                off = np.zeros(0)
            if off.shape != (3,) or not np.all(np.isfinite(off)):  # float() reads 'nan' and 'inf' too
                raise InputError(
                    capture.path,
                    _line(capture, "accel_offset"),
                    f"accel_offset {offset!r}: give three numbers x, y, z in {unit or 'the accelerometer unit'}",
                )
            raw = raw - off
        f_b = (raw * asign) @ C.T
        del raw  # (N, 3): not needed past here, while the stillness detector runs
        if unit == "counts" and offset is None:
            warnings.append(
                "accelerometer in counts: only its direction is used for pitch and roll "
                "(its bias, uncalibrated, tilts them)"
            )
    ok = _finite_rows([w_b, f_b], warnings, "gyro or accelerometer")
    if f_b is not None and ok.any() and not np.linalg.norm(f_b[ok].mean(axis=0)) > 0:
        raise UnsupportedError(
            f"{capture.path or 'capture'}: the accelerometer reads zero on average, so mode B has no "
            "pitch and roll (a dead or unconnected sensor?): check the ax ay az columns"
        )
    lat = capture.float_meta("latitude_deg")
    hsig = capture.float_meta_within("heading_sigma_deg", 3.0, 180.0)
    segs = _segments(capture, w_b, f_b, dt, ok, warnings)
    if len(segs) == 1:
        m, head, _ = segs[0]
        res = gd.drift_static(w_b[m], None if f_b is None else f_b[m], dt, lat, head, heading_sigma_deg=hsig)
        e = res.earth_rate_body_rad_s if res.earth_rate_body_rad_s is not None else 0.0
        return res, res.mean_error, 1, w_b[m] - res.drift_rad_s - e
    positions = []
    for m, head, lab in segs:
        if m.sum() < 64:
            warnings.append(f"position {lab}: {int(m.sum())} samples, too few; left out")
            continue
        positions.append(
            gd.Position(
                allan.mean_standard_error(w_b[m], dt),
                None if f_b is None else allan.mean_standard_error(f_b[m], dt),
                head,
                lab,
            )
        )
    if len(positions) == 1:
        m = segs[0][0]
        res = gd.drift_static(
            w_b[m], None if f_b is None else f_b[m], dt, lat, positions[0].heading_deg, heading_sigma_deg=hsig
        )
        return res, res.mean_error, 1, w_b[m] - res.drift_rad_s
    known = "heading_deg" in capture.columns or capture.float_meta("heading_deg") is not None
    res = gd.drift_multi(positions, lat, heading_sigma_deg=hsig, headings_known=known)
    total = sum(p.omega.duration_s for p in positions)
    if total < gd.SOURCE_DURATION_S:
        warnings.append(f"static positions total {total:.0f} s, shorter than the 3 min P4 asks for")
    # accuracy statement on the pooled record: the Allan curve of the longest position
    me = max((p.omega for p in positions), key=lambda e: e.duration_s)
    me = allan.MeanError(res.drift_rad_s, res.sigma_rad_s, me.se_white, me.tau_at_max_s, total, me.taus_s, me.adev)
    resid = np.asarray(res.extra.pop("residuals_rad_s"))
    return res, me, len(positions), resid


def _f(x):
    return None if x is None else float(x)


def _result(capture, res: gd.DriftResult, mode, n_pos, resid, acc, me, C, flips, k, warnings) -> dict:
    drift = np.asarray(res.drift_rad_s, dtype=float)
    sig = np.asarray(res.sigma_rad_s, dtype=float)
    raw_drift = (C.T @ drift) / (flips * k)  # back to the capture's axes and unit
    raw_sig = np.abs((C.T @ sig) / (flips * k))
    params = {"drift": drift, "mode": res.mode}
    unc = {"drift": sig}
    if mode == "static":
        params.update(
            {"pitch_deg": res.pitch_deg, "roll_deg": res.roll_deg, "earth_rate_body": res.earth_rate_body_rad_s}
        )
        unc.update(
            {
                "pitch_deg": res.sigma_pitch_deg,
                "roll_deg": res.sigma_roll_deg,
                "earth_rate_body": res.sigma_earth_rate_body_rad_s,
            }
        )
    out = {
        "procedure": "gyro-drift",
        "device": capture.meta.get("device"),
        "model": MODEL,
        "params": params,
        "uncertainty": unc,
        "residual_rms": float(np.sqrt(np.mean(np.asarray(resid) ** 2))) if np.size(resid) else 0.0,
        "n_positions": n_pos,
        "warnings": warnings,
        "frame": "body x forward, y up, z right (rad/s)",
        "drift_deg_h": drift / gd.DEG_H_RAD_S,
        "drift_raw": {
            "value": raw_drift,
            "sigma": raw_sig,
            "unit": capture.meta.get("gyro_unit", "rad/s"),
            "axes": "the capture's gx gy gz",
        },
        "accuracy": acc,
        "allan": {"tau_s": me.taus_s, "adev_rad_s": me.adev.T if me.adev.size else []},
    }
    if res.extra:
        out["fit"] = {k2: v for k2, v in res.extra.items()}
    return out


def format_text(result: dict) -> str:
    """The result for a person, in the units the screens show (drift and rates in °/h,
    ``DISPLAY_UNITS``); ``--json`` keeps rad/s."""
    from station.formatting import device_text
    from station.procedures.review import shown_residual, shown_unit, shown_value

    p, u = result["params"], result["uncertainty"]
    unit = shown_unit(result, "drift")
    d = [shown_value(result, "drift", float(v)) for v in p["drift"]]
    s = [shown_value(result, "drift", float(v)) for v in u["drift"]]
    lines = [
        f"procedure  gyro-drift ({p['mode']})",
        f"device     {device_text(result)}",
        f"model      {result['model']}",
        "drift      " + "  ".join(f"{a} {v:+.2f} ± {e:.2g}" for a, v, e in zip("xyz", d, s)) + f" {unit}",
        f"           body axes {BODY_AXES}",
    ]
    if p.get("earth_rate_body") is not None:
        e = [shown_value(result, "earth_rate_body", float(v)) for v in p["earth_rate_body"]]
        unit_e = shown_unit(result, "earth_rate_body")
        lines.append("earth rate " + "  ".join(f"{a} {v:+.3f}" for a, v in zip("xyz", e)) + f" {unit_e} removed")
    if "pitch_deg" in p:
        pr = p["pitch_deg"]
        if isinstance(pr, list):
            lines.append("tilt       " + "; ".join(f"pitch {a:.2f}° roll {b:.2f}°" for a, b in zip(pr, p["roll_deg"])))
        else:
            lines.append(f"tilt       pitch {pr:.2f}° roll {p['roll_deg']:.2f}°")
    fit = result.get("fit", {})
    if "earth_rate_scale" in fit:
        lines.append(
            f"earth-rate scale {fit['earth_rate_scale']:.3f} ± {fit['sigma_earth_rate_scale']:.3f} (1 expected)"
        )
    acc = result.get("accuracy", {})
    if acc:
        lines.append(
            f"record     {acc['duration_s']:.0f} s; achieved 1σ "
            + ", ".join(f"{v:.3g}" for v in np.asarray(acc["achieved_sigma_deg_h"]))
            + " °/h"
            + (
                f"; asked {acc['accuracy_rad_s'] / gd.DEG_H_RAD_S:g} °/h: "
                + ("enough" if acc["enough"] else "NOT enough")
                if "accuracy_rad_s" in acc
                else ""
            )
        )
    res, res_unit = shown_residual(result)
    lines.append(f"residual   {res:.4g} {res_unit} RMS {RESIDUAL_OF} (noise about the model)")
    lines.append(f"positions  {result['n_positions']}")
    for w in result.get("warnings", []):
        lines.append(f"warning    {w}")
    return "\n".join(lines)


def _step(w_rad_s) -> float | None:
    """The smallest grid step of the rates' axes (unit − reference in mode A), or None when an axis
    is not written on a grid."""
    from solvers.diagnose.problems import quantisation_step

    steps = [quantisation_step(w_rad_s[:, i]) for i in range(3)]
    return None if any(s is None for s in steps) else min(steps)


def diagnosis_input(capture, base: dict | None = None, prepared: Prepared | None = None) -> DiagnosisInput:
    """The P4 diagnosis problem (it fits its own baseline: ``base`` is not used)."""
    from solvers.diagnose import problems as DP
    from solvers.gyrodrift import check_length

    prep = prepared if prepared is not None else prepare(capture)
    warnings = list(prep.warnings)
    C, asign = prep.C_fur_cap, prep.accel_sign
    # counts without a scale: diagnose in the capture's own unit (effects are relative)
    unit = "rad/s" if prep.gyro_unit_error is None else capture.meta.get("gyro_unit", "raw")
    w_b = prep.w_b
    f_b = None
    if all(c in capture.columns for c in ("ax", "ay", "az")):
        f_b = (_need(capture, ["ax", "ay", "az"]) * asign) @ C.T
    if "ref_gx" in capture.columns:
        w_b = w_b - _need(capture, ["ref_gx", "ref_gy", "ref_gz"]) @ C.T
        lat = None
        mode_ref = True
    else:
        lat = capture.float_meta("latitude_deg")
        mode_ref = False
    dt = _dt(capture)
    ok = _finite_rows([w_b, f_b], warnings, "gyro or accelerometer")
    segs = _segments(capture, w_b, f_b, dt, ok, warnings) if not mode_ref else [(ok, 0.0, "1")]
    if mode_ref and f_b is not None:
        # mode A on several positions (the pair turned between holds, labelled or found still as in
        # mode B): each its own orientation, so a gyro bias that follows the specific force
        # (g_sensitivity) can be told from the constant one; the turns between them are left out.
        # One position, or a record never still (a vehicle): the whole record, as before
        try:
            held = _segments(capture, prep.w_b, f_b, dt, ok, [])
        except (UnsupportedError, SolverError):
            held = []
        if len(held) >= 2:
            segs = held
    # several orientations with no heading per position: pitch and roll come from the accelerometer,
    # the heading is unknown (taken as 0 below), so only the Earth rate's up part can be fitted
    hcol = capture.columns.get("heading_deg")
    headings_known = (
        len(segs) <= 1
        or capture.float_meta("heading_deg") is not None
        or (hcol is not None and bool(np.any(np.isfinite(hcol))))
    )
    n = len(w_b)
    t = np.asarray(capture.columns["t"], float) if "t" in capture.columns else np.arange(n) * dt
    label = np.full(n, "", dtype=object)
    E = np.zeros((n, 3))
    Cbn = np.zeros((n, 3, 3))
    for m, head, lab in segs:
        if m.sum() < 8:
            continue
        label[m] = lab
        if f_b is not None:
            p, r = frames.p4_pitch_roll_from_accel(np.mean(f_b[m], axis=0))
        else:
            p, r = 0.0, 0.0
        Cnb = frames.p4_C_n_b(p, r, math.radians(head))
        Cbn[m] = Cnb.T
        if lat is not None and (headings_known or f_b is None):  # else each heading is fitted (gyro_problem)
            E[m] = gyro_model.earth_rate_body(lat, Cnb)
    # the data-quality screen: gaps, saturated samples, moved positions are left out
    from station.procedures.diagnose import moved_positions, screen

    bad, screened = screen(capture, moved_positions(capture))
    use = (label != "") & ~bad
    order = np.flatnonzero(use)
    if len(order) < 16:
        raise UnsupportedError(
            f"{capture.path or 'capture'}: gyro-drift: {len(order)} static samples; diagnosis needs a "
            "static record (P4 asks for >= 3 min)"
        )
    f_mps2 = None
    if f_b is not None:
        gnorm = float(np.median(np.linalg.norm(f_b[use], axis=1)))
        if not gnorm > 0:
            raise UnsupportedError(
                f"{capture.path or 'capture'}: the accelerometer reads zero on average (a dead or "
                "unconnected sensor?): check the ax ay az columns"
            )
        f_mps2 = f_b[use] * (frames.G_STANDARD_MPS2 / gnorm)
    # what calibrate refuses diagnose refuses: a few seconds hold no drift, nor an effect on it
    check_length(len(order), dt, "mode A" if mode_ref else "mode B")
    temp = fill_missing(capture.columns["temp_c"], t)[order] if "temp_c" in capture.columns else None
    prob = DP.gyro_problem(
        t[order],
        w_b[order],
        f_mps2,
        temp,
        E[order] if ((lat is not None and (headings_known or f_b is None)) or mode_ref) else None,
        label[order],
        C_b_n=Cbn[order],
        reference=mode_ref,
        headings_known=headings_known,
        step_rad_s=_step(w_b[order]) if unit == "rad/s" else None,
        latitude_deg=lat,
    )
    prob.unit = unit
    if unit != "rad/s" and "g_sensitivity" in prob.could_be:  # a gyro in counts: Ω's size in them is unknown
        why = f"no latitude, no heading per position, and the gyro in {unit} with no scale: it may be the Earth rate"
        prob.could_be["g_sensitivity"] = ("earth_rate", lambda P, S: why)
    prob.screened = screened
    return DiagnosisInput(prob, {"rows": order}, "a block far off the others: a knock, the unit moved, or a bias jump")
