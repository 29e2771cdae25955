"""P1 level-table accelerometer calibration for the CLI and the TUI: capture in, calibrate.md dict out.

The numerics are in ``solvers/tabletop.py`` (step 8, step 10, the gauge). This module:

- finds the static positions: a table of averages (one row per position, optional ``n`` and
  ``<col>_std``); a time series with a ``position`` column (each run of one label is a
  position); a time series without one (``solvers.stillness.detect_static_intervals``, with
  the gyro when the capture has one);
- knows each labelled position's gravity direction (``solvers.tabletop.known_direction``);
- refuses, with the reason, what cannot be calibrated: a saturated axis, fewer than 9
  distinct orientations (``--method six-position`` then offers step 8 alone when the six
  ±axis positions are labelled), positions too alike to determine the coefficients;
- reports every position used with its time span and norm residual.

Methods: ``norm`` (default: step 8 where labels allow, then the norm fit in the ``table``
gauge, or ``upper-triangular`` without labels), ``upper-triangular`` (that gauge even with
labels), ``six-position`` (step 8 only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from solvers import tabletop as T
from solvers.allan import hold_mean_se
from solvers.errors import SolverError
from solvers.models import accel as accel_model
from solvers.units import ACCEL_UNITS
from station.capture import fill_missing, span_step_s, strictly_increasing_t
from station.errors import InputError, UnsupportedError
from station.procedures.contract import DiagnosisInput

MODEL = "A = B + M V"
DIAGNOSIS_BASELINE = True  # diagnosis_input starts from the calibrate result
# station.guard: columns read as measurements (present but empty in every row: refused), and
# the parameters this procedure exists to deliver (any of them non-finite: refused)
MEASURED = ("ax", "ay", "az")
CORE_PARAMS = ("B", "M")
# station.procedures.review: each parameter block's unit; the residual above which the model
# does not describe the data at all (5 % of g, in the result's m/s²)
PARAM_UNITS = {"B": "m/s^2", "M": "m/s^2 per raw unit"}
PARAM_SHAPES = {"B": (3,), "M": (3, 3)}  # every parameter the result can hold (calibrate.md)
LIMIT_EXAMPLE = "e.g. B[0]=-0.5:0.5  M[0][0]=0.98:1.02"  # the limits box's example (screens/limits.py)
RESIDUAL_LIMIT = 0.05 * 9.80665
METHODS = {
    "norm": ("norm", "auto"),
    "upper-triangular": ("norm", "upper-triangular"),
    "six-position": ("six-position", "auto"),
    "step8": ("six-position", "auto"),
}


# why a stated sample_rate_hz that the t column contradicts is refused when the positions are
# found by stillness detection (its windows are seconds of t); labelled positions do not need t
STILLNESS_RATE_CONSEQUENCE = "the static positions are found over windows of t seconds"


def _labelled(capture) -> bool:
    labels = capture.columns.get("position")
    return labels is not None and any(labels)


def rate_consequence(capture) -> str | None:
    """What a stated ``sample_rate_hz`` that ``t`` contradicts makes wrong where calibrate refuses
    it (``station inspect`` asks): the positions of a time series without a ``position`` column.
    None otherwise (labelled positions, a table; a gyro block is then left uncalibrated, saying why)."""
    return STILLNESS_RATE_CONSEQUENCE if capture.is_time_series and not _labelled(capture) else None


def rate_note(capture) -> str | None:
    """What calibrate does with such a rate where it does not refuse it (``station inspect``'s
    warning says so): a gyro time series is left uncalibrated."""
    from station.procedures import tabletop_gyro

    if not tabletop_gyro.has_gyro(capture):
        return None
    return f"calibrate leaves the gyro uncalibrated, {tabletop_gyro.RATE_CONSEQUENCE}"


# A sample this many robust standard deviations (1.4826 MAD, at least one quantum) from its
# labelled hold's median is a glitch (a bus error, a stray byte): one such sample of 1e4 V among
# 2000 at 2.4 V moved the hold's mean by 5 V and P1's residual from 0.0002 to 17 m/s^2, with no
# warning (the hold's standard deviation grew with it). Left out only where such samples are at
# most GLITCH_SHARE of the hold: more is motion, which the data-quality screen judges.
GLITCH_SIGMAS = 1000.0
GLITCH_SHARE = 0.01


def _glitches(seg: np.ndarray, good: np.ndarray) -> np.ndarray:
    """Rows of one labelled hold (n x 3) that are glitches (see GLITCH_SIGMAS)."""
    out = np.zeros(len(seg), dtype=bool)
    if good.sum() < 20:
        return out
    x = seg[good]
    med = np.median(x, axis=0)
    dev = np.abs(x - med)
    scale = 1.4826 * np.median(dev, axis=0)
    for i in range(3):
        if scale[i] == 0.0:  # a quiet quantised axis: one count
            nonzero = dev[:, i][dev[:, i] > 0]
            scale[i] = nonzero.min() if len(nonzero) else np.inf
    far = np.any(dev > GLITCH_SIGMAS * scale, axis=1)
    if 0 < far.sum() <= GLITCH_SHARE * len(x):
        out[np.flatnonzero(good)[far]] = True
    return out


def _glitch_text(capture, row: int, value: np.ndarray, label: str) -> str:
    line = f"line {(capture.header_line or 0) + 1 + row}: " if capture.header_line else ""
    shown = ", ".join(f"{c} {v:.6g}" for c, v in zip(("ax", "ay", "az"), value, strict=True))
    return f"{line}{shown} in {label}"


def _where(capture) -> str:
    return capture.path or "capture"


def _accel(capture) -> np.ndarray:
    return np.column_stack([np.asarray(capture.column(c), dtype=float) for c in ("ax", "ay", "az")])


def _runs(labels: np.ndarray) -> list[tuple[int, int, str]]:
    """Contiguous runs of one non-empty label: (start, stop, label)."""
    out, k, n = [], 0, len(labels)
    while k < n:
        lab = labels[k]
        j = k + 1
        while j < n and labels[j] == lab:
            j += 1
        if lab:
            out.append((k, j, str(lab)))
        k = j
    return out


def static_positions(capture, warnings: list[str]) -> tuple[list[T.Position], str, bool]:
    """The positions of a capture, how they were found, and whether their noise is measured."""
    a = _accel(capture)
    labels = capture.columns.get("position")
    if not capture.is_time_series:
        stds = [capture.columns.get(c + "_std") for c in ("ax", "ay", "az")]
        n = capture.columns.get("n")
        noise_known = all(s is not None for s in stds) and n is not None
        out = []
        first = (capture.header_line or 0) + 1
        unmeasured = []  # lines of rows without their n or standard deviations
        for k in range(len(a)):
            if not np.all(np.isfinite(a[k])):
                raise InputError(
                    capture.path, first + k if capture.header_line else None, "accelerometer average is missing"
                )
            lab = str(labels[k]) if labels is not None and labels[k] else str(k + 1)
            d, s = T.known_direction(lab)
            std = np.array([float(x[k]) for x in stds]) if noise_known else None
            nk = int(n[k]) if n is not None and np.isfinite(n[k]) and n[k] >= 1 else 1
            if noise_known and (not np.all(np.isfinite(std)) or nk < 2):
                unmeasured.append(first + k)
            out.append(T.Position(lab, a[k], std, nk, direction=d, placement_sigma_rad=s))
        if unmeasured:  # one policy for the table: the noise of every row, or of none
            noise_known = False
            shown = ", ".join(map(str, unmeasured[:5])) + (" …" if len(unmeasured) > 5 else "")
            warnings.append(
                f"{len(unmeasured)} of {len(a)} rows (line {shown}) without n >= 2 and their standard deviations: "
                "the given noise of the others is not used either"
            )
        if not noise_known:
            for p in out:
                p.std = None
        return out, "table of averages", noise_known
    t = np.asarray(capture.column("t"), dtype=float)
    missing = int((~np.all(np.isfinite(a), axis=1)).sum())
    if missing:  # never a silently shortened dataset
        warnings.append(f"{missing} of {len(a)} rows with a missing accelerometer value left out")
    if _labelled(capture):
        out = []
        glitches: list[str] = []
        for start, stop, lab in _runs(labels):
            seg = a[start:stop]
            good = np.all(np.isfinite(seg), axis=1)
            glitch = _glitches(seg, good)
            if glitch.any():
                rows = start + np.flatnonzero(glitch)
                glitches += [_glitch_text(capture, r, a[r], lab) for r in rows]
                good &= ~glitch
            t_hold = t[start:stop][good]
            seg = seg[good]
            if len(seg) < 2:
                continue
            d, s = T.known_direction(lab)
            out.append(
                T.Position(
                    lab,
                    seg.mean(axis=0),
                    seg.std(axis=0, ddof=1),
                    len(seg),
                    float(t[start]),
                    float(t[stop - 1]),
                    d,
                    s,
                    se=hold_mean_se(seg, t_hold),
                )
            )
        if glitches:  # never a silently shortened dataset
            shown = "; ".join(glitches[:3]) + (f"; and {len(glitches) - 3} more" if len(glitches) > 3 else "")
            warnings.append(
                f"{len(glitches)} sample{'' if len(glitches) == 1 else 's'} left out of {'its hold' if len(glitches) == 1 else 'their holds'}, "
                f"more than {GLITCH_SIGMAS:g} times the hold's spread from its median (a glitch, not the unit's "
                f"attitude): {shown}"
            )
        return out, "position column", True
    from solvers.stillness import detect_static_intervals

    capture.series_rate_hz(STILLNESS_RATE_CONSEQUENCE)  # t in ms would make every sample a position
    gyro = None
    if all(c in capture.columns for c in ("gx", "gy", "gz")):
        gyro = np.column_stack([np.asarray(capture.columns[c], dtype=float) for c in ("gx", "gy", "gz")])
    try:
        st = detect_static_intervals(strictly_increasing_t(t), a, gyro, nan_policy="omit")
    except (SolverError, ValueError) as exc:
        raise UnsupportedError(f"{_where(capture)}: accel-tabletop: cannot find static positions: {exc}") from None
    warnings += [f"stillness: {w}" for w in st.warnings]
    out = [
        T.Position(
            str(k + 1),
            np.asarray(iv.accel_mean, float),
            np.asarray(iv.accel_std, float),
            int(iv.n),
            float(iv.t_start_s),
            float(iv.t_stop_s),
            se=hold_mean_se(a[iv.start : iv.stop], t[iv.start : iv.stop]),
        )
        for k, iv in enumerate(st.intervals)
    ]
    return out, "static intervals found automatically (no position column)", True


def check_saturation(capture, positions: list[T.Position]) -> None:
    """Refuse when an axis sits at its range limit: within a position the axis is exactly
    constant at the capture's extreme reading while the other axes show noise."""
    a = _accel(capture)
    hi, lo = np.nanmax(a, axis=0), np.nanmin(a, axis=0)
    for p in positions:
        if p.std is None:
            continue
        tol = 1e-9 * np.maximum(1.0, np.abs(p.mean))
        flat = p.std <= tol
        for i in range(3):
            at_edge = abs(p.mean[i] - hi[i]) <= tol[i] or abs(p.mean[i] - lo[i]) <= tol[i]
            if flat[i] and not flat.all() and at_edge and p.n >= 2:
                where = f" (t {p.t_start_s:.1f}–{p.t_stop_s:.1f} s)" if p.t_start_s is not None else ""
                raise UnsupportedError(
                    f"{_where(capture)}: accel-tabletop: axis {'xyz'[i]} is saturated in position {p.label}{where}: "
                    f"stuck at {p.mean[i]:g} {capture.meta.get('accel_unit', '')}, its extreme reading, while the "
                    "other axes are noisy; the range is too small for 1 g (or the sensor clips): cannot calibrate"
                )


@dataclass
class Prepared:
    """A P1 capture read once: local gravity and the static positions (calibrate and diagnose)."""

    g_mps2: float
    positions: list[T.Position]
    found_by: str
    noise_known: bool
    warnings: list[str] = field(default_factory=list)


def prepare(capture) -> Prepared:
    """Local gravity and the static positions of ``capture``, with the warnings they raise."""
    warnings: list[str] = []
    g = capture.local_gravity_mps2(warnings)
    positions, found, noise_known = static_positions(capture, warnings)
    return Prepared(g, positions, found, noise_known, warnings)


def calibrate(capture, method: str | None = None, *, prepared: Prepared | None = None) -> dict:
    """The calibrate.md result for an ``accel-tabletop`` capture."""
    key = method or "norm"
    if key not in METHODS:
        raise UnsupportedError(f"accel-tabletop: unknown method {key!r} (methods: {', '.join(METHODS)})")
    est, gauge = METHODS[key]
    unit = capture.meta.get("accel_unit") or "raw"
    prep = prepared if prepared is not None else prepare(capture)
    warnings = list(prep.warnings)
    g, positions, found, noise_known = prep.g_mps2, prep.positions, prep.found_by, prep.noise_known
    if not positions:
        raise UnsupportedError(f"{_where(capture)}: accel-tabletop: no static positions found")
    check_saturation(capture, positions)
    try:
        res = T.calibrate(positions, g, method=est, gauge=gauge, noise_known=noise_known)
    except SolverError as exc:
        raise UnsupportedError(f"{_where(capture)}: accel-tabletop: {exc}", alternative=exc.alternative) from None
    warnings += res.warnings
    if unit in ACCEL_UNITS and est == "norm":
        s = ACCEL_UNITS[unit]
        dev = np.abs(np.diag(res.M) / s - 1.0)
        if np.any(dev > 0.2):
            warnings.append(
                f"scale factors differ from the nominal {s:g} m/s^2 per {unit} by up to "
                f"{100 * dev.max():.0f} %: check accel_unit"
            )
    if res.labels_used:  # labels that contradicted the data were set aside, saying so
        warnings += mislabelled(capture, positions, res.B, res.M)
    t_known = [p for p in positions if p.direction is not None]
    rows = []
    for k, p in enumerate(positions):
        rows.append(
            {
                "label": p.label,
                "t_start_s": p.t_start_s,
                "t_stop_s": p.t_stop_s,
                "n": p.n,
                "mean_raw": p.mean,
                "residual_mps2": float(res.norm_residuals[k]),
                "sigma_mps2": float(res.norm_sigma[k]),
                "known_direction": p.direction if p.direction is not None else None,
                "orientation": int(res.clusters[k]),
                "outlier": k in res.outliers,
            }
        )
    result = {
        "procedure": "accel-tabletop",
        "device": capture.meta.get("device"),
        "model": MODEL,
        "params": {"B": res.B, "M": res.M},
        "uncertainty": {"B": res.sigma_B, "M": res.sigma_M},
        "residual_rms": res.residual_rms,
        "n_positions": len(positions),
        "warnings": warnings,
        "method": res.method,
        "gauge": res.gauge,
        "gauge_description": res.gauge_text,
        "units": {"V": unit, "A": "m/s^2", "B": "m/s^2", "M": f"m/s^2 per {unit}", "residual_rms": "m/s^2"},
        "g_mps2": g,
        "positions_found_by": found,
        "n_labelled_positions": len(t_known),
        "labels_used": bool(res.labels_used and t_known),
        "n_distinct_orientations": res.n_distinct,
        "position_set_condition": res.position_condition,
        "noise": (
            "estimated from the residuals"
            if not noise_known
            else "measured per position: standard error of each hold's mean, bias instability included "
            "(fitted Allan noise model)"
            if any(p.se is not None for p in positions)
            else "measured per position (std/sqrt(n))"
        ),
        "reduced_chi2": res.fit.reduced_chi2 if res.fit is not None else None,
        "positions": rows,
        "step8": res.step8,
    }
    from station.procedures import tabletop_gyro

    gyro = tabletop_gyro.block(capture, positions, res.B, res.M, g)
    if gyro is not None:  # the same session's rotations calibrate the gyro triad (docs/tabletop-gyro.md)
        result["gyro"] = gyro
    return result


MISLABEL_DEG = 20.0  # beyond any placement error; the P1 set's positions lie 45° or more apart


def mislabelled(capture, positions, B, M) -> list[str]:
    """A warning for each labelled position whose calibrated reading A = B + M V lies more
    than MISLABEL_DEG from its label's direction: a typo or a step recorded under another
    name, which the table gauge (fixed by the labels) takes as the truth."""
    out = []
    table = "t" not in capture.columns
    for k, p in enumerate(positions):
        if p.direction is None:
            continue
        a = np.asarray(B, dtype=float) + np.asarray(M, dtype=float) @ np.asarray(p.mean, dtype=float)
        d = np.asarray(p.direction, dtype=float)
        cos = float(a @ d / (np.linalg.norm(a) * np.linalg.norm(d)))
        angle = math.degrees(math.acos(min(1.0, max(-1.0, cos)))) if math.isfinite(cos) else math.nan
        if angle > MISLABEL_DEG:
            where = f"row {k + 1}" if table else f"the hold at t = {p.t_start_s:g}..{p.t_stop_s:g} s"
            out.append(
                f"position {p.label!r} ({where}) reads {angle:.0f}° from its label's direction: mislabelled? "
                "(the labels fix the fit's orientation: correct the label, or leave it empty)"
            )
    return out


def format_text(result: dict) -> str:
    from station.calibrate import jsonable
    from station.formatting import device_text, num, param_lines

    r = jsonable(result)
    unit = r["units"]["V"]
    lines = [
        f"procedure  accel-tabletop (P1, {r['method']})",
        f"device     {device_text(r)}",
        f"model      {r['model']}   (V in {unit}, A in m/s^2)",
        f"gauge      {r['gauge_description']}",
    ]
    lines += param_lines("B [m/s^2]", r["params"]["B"], r["uncertainty"]["B"])
    lines += param_lines(f"M [m/s^2 per {unit}]", r["params"]["M"], r["uncertainty"]["M"])
    lines.append(f"residual   {r['residual_rms']:.3g} m/s^2 RMS of |A| − g (g = {r['g_mps2']:.5f} m/s^2)")
    lines.append(
        f"positions  {r['n_positions']} ({r['positions_found_by']}), {r['n_distinct_orientations']} "
        f"distinct orientations, condition {num(r['position_set_condition'], '.3g', '∞ (singular)')}"
    )
    for p in r["positions"]:
        span = f"{p['t_start_s']:8.1f}–{p['t_stop_s']:8.1f} s" if p["t_start_s"] is not None else " " * 21
        flag = "  <- disagrees" if p["outlier"] else ""
        lines.append(f"  {p['label']:>8} {span} n={p['n']:<6} |A|−g = {p['residual_mps2']:+.2e} m/s^2{flag}")
    for w in r["warnings"]:
        lines.append(f"warning    {w}")
    if r.get("gyro") is not None:
        from station.procedures.tabletop_gyro import format_lines

        lines += format_lines(r["gyro"])
    return "\n".join(lines)


def _col(capture, name):
    x = capture.columns.get(name)
    return None if x is None else np.asarray(x, float)


def _gyro_diagnosis(capture, base, prepared):
    from station.procedures import tabletop_gyro

    return tabletop_gyro.diagnosis_input(capture, base, prepared)


# diagnoses of the session's second sensor: result key → (procedure name, input builder or None)
SUB_DIAGNOSES = {"gyro": ("gyro-tabletop", _gyro_diagnosis)}
MIN_SCREENED_POSITIONS = 10  # positions left out by the screen only while this many remain


def _screen(
    capture, positions, base, keep_flagged: bool = False
) -> tuple[list, np.ndarray | None, list[dict], list[int]]:
    """The data-quality screen (``station.procedures.diagnose.screen``) for P1: the positions
    the effect search uses, the capture rows it leaves out (time series) and the findings.
    Left out: gaps, saturated samples, moved positions, and the positions the calibration
    flags as disagreeing with the rest far beyond the noise (``outlier`` in its result) —
    while MIN_SCREENED_POSITIONS remain, else they are named and kept. ``keep_flagged``: the
    flagged positions are kept (named, ``"screened": false``), for an effect search that may
    explain them; the last item lists where the flagged positions kept are in the first."""
    from station.procedures.diagnose import file_line, screen

    moved = _moved_positions(capture)
    bad, found = screen(capture, moved)
    rows = (base or {}).get("positions") or []
    flagged = {k for k, r in enumerate(rows) if r.get("outlier") and k < len(positions)}
    t = _col(capture, "t") if capture.is_time_series else None
    span = {}
    for k, p in enumerate(positions):
        if t is not None and p.t_start_s is not None:
            i0, i1 = int(np.searchsorted(t, p.t_start_s)), int(np.searchsorted(t, p.t_stop_s, side="right"))
            span[k] = (i0, i1)
    for k in sorted(flagged):
        r, p = rows[k], positions[k]
        i0, i1 = span.get(k, (k, k + 1))
        found.append(
            {
                "kind": "outlier",
                "position": p.label,
                "where": f"position {p.label}",
                "line": file_line(capture, i0),
                "line_stop": file_line(capture, i1 - 1),
                "residual_mps2": r.get("residual_mps2"),
                "screened": True,
                "explanation": f"|A| − g = {r.get('residual_mps2', float('nan')):+.3g} m/s^2, far beyond the other "
                "positions' spread (the calibration flags it: was it still, or touching something?); "
                "left out of the effect search",
            }
        )
    drop = set() if keep_flagged else set(flagged)
    if keep_flagged:
        for q in found:
            if q["kind"] == "outlier":
                q["screened"] = False
                q["explanation"] = q["explanation"].split("; left out")[0] + "; kept: the effects named explain it"
    for k, (i0, i1) in span.items():  # mostly screened samples (a moved position): the position goes
        if i1 > i0 and bad[i0:i1].mean() > 0.5:
            drop.add(k)
    keep = [k for k in range(len(positions)) if k not in drop]
    if len(keep) < MIN_SCREENED_POSITIONS:
        keep = list(range(len(positions)))
        if moved:  # the moved positions stay: only gaps and saturated samples are left out
            bad, _ = screen(capture)
        for q in found:
            if q["kind"] in ("outlier", "moved"):
                q["screened"] = False
                q["explanation"] = q["explanation"].split("; left out")[0].split("; the position is left")[0]
                q["explanation"] += f"; kept: fewer than {MIN_SCREENED_POSITIONS} positions would remain"
    out = []
    for k in keep:
        p = positions[k]
        if k in span and bad is not None:
            i0, i1 = span[k]
            a = _accel(capture)[i0:i1][~bad[i0:i1]]
            a = a[np.all(np.isfinite(a), axis=1)]
            if len(a) < i1 - i0 and len(a) >= 2:  # some samples screened (a gap's margin): the mean of the rest
                p = replace(
                    p,
                    mean=a.mean(axis=0),
                    std=a.std(axis=0, ddof=1),
                    n=len(a),
                    se=hold_mean_se(a, t[i0:i1][~bad[i0:i1]]) if len(a) >= 16 else p.se,
                )
        out.append(p)
    kept_flagged = [i for i, k in enumerate(keep) if k in flagged]
    return out, (bad if capture.is_time_series else None), found, kept_flagged


def diagnosis_input(
    capture, base: dict, prepared: Prepared | None = None, keep_flagged: bool = False
) -> DiagnosisInput:
    """The P1 diagnosis problem around the baseline ``base`` (a calibrate result), on what
    the data-quality screen (``_screen``) leaves. Where the screen left positions out as
    outliers, ``kept`` gives the same problem with them in (``keep_flagged``): an effect
    concentrated on a few orientations (a temperature bias along one axis) puts those
    positions far from the rest, and screened out, the evidence for it went with them."""
    from solvers.diagnose import problems as DP

    prep = prepared if prepared is not None else prepare(capture)
    g, noise_known = prep.g_mps2, prep.noise_known
    positions, bad, screened, kept_flagged = _screen(capture, prep.positions, base, keep_flagged)
    any_left_out = any(q["kind"] == "outlier" and q["screened"] for q in screened)
    B, M = np.asarray(base["params"]["B"], float), np.asarray(base["params"]["M"], float)
    dirs = [p.direction for p in positions]
    if base.get("labels_used") is False:
        # the calibration set the labels aside (holds numbered 1..N in the bench's own order: they
        # read far from P1's directions): their direction rows would pull the fit as it did not
        dirs = [None] * len(positions)
    if sum(d is not None for d in dirs) < 3:
        B, M = T.to_upper(B, M)
    fw = accel_model.p1_to_forward(B, M)
    t_mean, temp_mean, rate_mean = None, None, None
    temp = _col(capture, "temp_c")
    rate = _temp_rate(capture) if capture.is_time_series else None
    if capture.is_time_series:
        t = _col(capture, "t")
        t_mean = np.array([0.5 * (p.t_start_s + p.t_stop_s) for p in positions])
        if temp is not None:
            inside = [(t >= p.t_start_s) & (t <= p.t_stop_s) for p in positions]
            temp_mean = np.array([np.nanmean(temp[i]) for i in inside])
            rate_mean = None if rate is None else np.array([np.nanmean(rate[i]) for i in inside])
    else:
        keep = [k for k, p in enumerate(prep.positions) if any(p is q for q in positions)]
        temp_mean = fill_missing(temp, _col(capture, "t"))[keep] if temp is not None else None
        t_mean = _col(capture, "t")
        t_mean = t_mean[keep] if t_mean is not None else None
    std = np.array([p.std if p.std is not None else np.full(3, np.nan) for p in positions])
    se = np.array([p.se for p in positions]) if all(p.se is not None for p in positions) else None
    prob = DP.tabletop_problem(
        np.array([p.mean for p in positions]),
        std if noise_known else None,
        np.array([p.n for p in positions]),
        g,
        fw["K"],
        fw["b"],
        labels=[p.label for p in positions],
        directions=dirs,
        placement_sigma_rad=[p.placement_sigma_rad for p in positions],
        t_s=t_mean,
        temp_c=temp_mean,
        temp_rate_c_s=rate_mean,
        noise_known=noise_known,
        se=se,
        sub=_sub_holds(capture, positions, bad, rate) if capture.is_time_series else None,
    )
    prob.screened = screened
    drivers = {"position": [p.label for p in positions], "time_s": t_mean, "temp_c": temp_mean}
    return DiagnosisInput(
        prob,
        drivers,
        "a position that disagrees with the others: the unit moved, a wrong label, or a knock",
        group_kind="position",
        kept=(lambda: diagnosis_input(capture, base, prepared, keep_flagged=True)) if any_left_out else None,
        flagged_groups=tuple(kept_flagged) if keep_flagged else (),
    )


SUB_HOLDS = 4  # parts a hold is cut into for diagnosis (time-resolved evidence)
MIN_SUB_SAMPLES = 25  # a hold shorter than SUB_HOLDS × this stays one row


def _sub_holds(capture, positions, bad=None, rate=None) -> dict | None:
    """Each position's samples cut into SUB_HOLDS consecutive parts: their means and standard
    errors from the same Allan model the calibration uses (solvers.allan.mean_standard_error);
    ``rate`` (:func:`_temp_rate`, per capture row) is averaged over each part as the temperature is."""
    from solvers.allan import mean_standard_error

    t = _col(capture, "t")
    a = _accel(capture)
    temp = _col(capture, "temp_c")
    out: dict[str, list] = {"V": [], "se": [], "pos": [], "part": [], "t": [], "temp": [], "temp_rate": []}
    # coarse stamps (whole seconds): a chunk's median step is 0; the rows over the capture's span give it
    step_all = span_step_s(t) or 1.0
    for k, p in enumerate(positions):
        if p.t_start_s is None or p.t_stop_s is None:
            return None
        inside = (t >= p.t_start_s) & (t <= p.t_stop_s) & np.all(np.isfinite(a), axis=1)
        idx = np.flatnonzero(inside if bad is None else inside & ~bad)
        if len(idx) < 2:  # all of it screened (kept only because too few positions would remain)
            idx = np.flatnonzero(inside)
        parts = SUB_HOLDS if len(idx) >= SUB_HOLDS * MIN_SUB_SAMPLES else 1
        for j, chunk in enumerate(np.array_split(idx, parts)):
            dt = float(np.median(np.diff(t[chunk]))) if len(chunk) > 1 else step_all
            dt = dt if dt > 0 else step_all
            me = mean_standard_error(a[chunk], dt)
            out["V"].append(me.mean)
            out["se"].append(me.se)
            out["pos"].append(k)
            out["part"].append(j)
            out["t"].append(float(np.mean(t[chunk])))
            out["temp"].append(float(np.nanmean(temp[chunk])) if temp is not None else np.nan)
            out["temp_rate"].append(float(np.nanmean(rate[chunk])) if rate is not None else np.nan)
    res = {k: np.array(v) for k, v in out.items()}
    if temp is None:
        res["temp"] = None
    if rate is None:
        res["temp_rate"] = None
    return res


def _temp_rate(capture) -> np.ndarray | None:
    """dT/dt per row of a time series (``solvers.models.temperature_rate`` over the rows with a
    temperature; NaN on the others), None without a temperature."""
    from solvers.models import temperature_rate

    temp, t = _col(capture, "temp_c"), _col(capture, "t")
    if temp is None or t is None:
        return None
    ok = np.isfinite(temp) & np.isfinite(t)
    if ok.sum() < 3:
        return None
    out = np.full(len(temp), np.nan)
    out[ok] = temperature_rate(t[ok], temp[ok])
    return out


def _moved_positions(capture) -> list[dict]:
    from station.procedures.diagnose import moved_positions

    return moved_positions(capture)


def report_figures(result: dict, meta: dict, columns: dict) -> list[tuple[str, str]]:
    """The calibration report's figures of P1 (``station.report``): (caption, svg) of the
    residual per position."""
    from station import svgplot
    from station.capture import Capture
    from station.procedures.review import p1_residuals

    figs: list[tuple[str, str]] = []
    if not all(c in columns for c in ("ax", "ay", "az")):
        return figs
    positions = result.get("positions")
    if isinstance(positions, list) and positions and "residual_mps2" in positions[0]:
        # a time series: the fit's own per-position holds
        res = [(str(p.get("label") or i + 1), None, p["residual_mps2"]) for i, p in enumerate(positions)]
    else:  # a table of averages: one row per position
        res = p1_residuals(Capture(dict(meta), dict(columns), None), result)
    if res:
        figs.append(
            (
                "Residual per position: |B + M V| − g, mm/s^2 (the norm the fit makes equal to local g)",
                svgplot.bar_plot(
                    [r[0] for r in res],
                    [1000.0 * r[2] for r in res],
                    y_label="|B + M V| − g  [mm/s^2]",
                    title="residual per position",
                ),
            )
        )
    return figs


# the Results table's columns (review.residual_table adds the residual's unit to the last two)
RESIDUAL_COLUMNS = ("position", "|B+MV|", "residual |B+MV| − g")


def position_residuals(capture, result: dict) -> list[tuple[str, float, float]]:
    """The TUI's Results table of P1: per position (name, |B + M V| [m/s²], |B + M V| − g [m/s²])."""
    from station.procedures.review import p1_residuals

    return p1_residuals(capture, result)


def firmware_accel(params: dict, k: float, unit: str) -> tuple[list[float], list[float], list[str]]:
    """P1 as a flight firmware's accelerometer offsets and scales (``station.firmware_export``:
    ``a = (a_fw - offset) * scale``, a_fw in m/s²); ``k`` m/s² per ``unit`` of the capture's V.
    Returns (offsets m/s², scales, notes for the export's comments)."""
    from station.firmware_export import matrix, vector

    B, M = vector(params, "B"), matrix(params, "M")
    scales = [M[i][i] / k for i in range(3)]
    offsets = [-B[i] / scales[i] for i in range(3)]
    off_diag = max(abs(M[i][j] / M[i][i]) for i in range(3) for j in range(3) if i != j)
    notes = [
        f"from A = B + M V (P1) with V in {unit}: scale = M_ii / ({k:.6g} m/s^2 per {unit}), "
        "offset = -B_i / scale_i (sign flipped: the firmware subtracts it before scaling)",
        f"dropped: off-diagonal M_ij (cross-axis, largest |M_ij/M_ii| = {off_diag:.3g}); "
        "the firmware has no cross-axis accelerometer terms",
    ]
    return offsets, scales, notes
