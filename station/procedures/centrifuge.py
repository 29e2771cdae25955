"""P2 centrifuge norm-observation calibration for the CLI and the TUI (source 001, Wang & Li 2021).

Numerics in ``solvers/centrifuge.py``. The capture is a table of averages (one row per
orientation and speed: ``speed_rad_s``, ``ax ay az``, optional ``n`` and ``<col>_std``) or a
time series (each run of one ``position``/``speed_rad_s`` pair is averaged). Metadata:
``radius_m`` (required), ``g_mps2`` (else normal gravity at ``latitude_deg``, else standard).

Methods: ``exact`` (default; exact nonlinear fit of ``|f(N)|² = A² + 1``), ``exact-gamma``
(also the installation angles: all 6 when identifiable), ``paper`` (the paper's eqs 13-22 with its
own second-order coefficients, printing errors corrected), ``paper-3rd`` (the same closed
forms with consistent third-order coefficients). Each takes the suffix ``-all`` to fit every
row; otherwise rows that disagree with the model far beyond the others (found by a robust
fit, ``solvers.centrifuge.screen_rows``) are left out, and each is named in ``warnings`` and
``rejected_rows`` with the sign flip that would make it agree, if one does. Nothing in the
data is changed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from solvers import centrifuge as C
from solvers.errors import SolverError
from solvers.models.accel import inverse as accel_inverse
from station.capture import fill_missing
from station.errors import InputError, UnsupportedError
from station.procedures.contract import DiagnosisInput

MODEL = "N = S Φ [f + D f∘f] + b,  |f|² = A² + 1,  A = ω²R/g"
DIAGNOSIS_BASELINE = True  # diagnosis_input starts from the calibrate result
# station.guard: columns read as measurements (present but empty in every row: refused), and
# the parameters this procedure exists to deliver (any of them non-finite: refused)
MEASURED = ("ax", "ay", "az", "speed_rad_s")
CORE_PARAMS = ("S", "b", "D")
# station.procedures.review: each parameter block's unit; the residual above which the model
# does not describe the data at all (5 % of g, in the result's g)
PARAM_UNITS = {"S": "g per g", "b": "g", "D": "g/g^2", "gamma": "rad"}
PARAM_SHAPES = {"S": (3,), "b": (3,), "D": (3,), "gamma": (6,)}  # every parameter the result can hold
LIMIT_EXAMPLE = "e.g. b[0]=-0.05:0.05  S[0]=0.9:1.1  D[0]=:0.001"  # the limits box's example (screens/limits.py)
RESIDUAL_LIMIT = 0.05
BASES = ("exact", "exact-gamma", "paper", "paper-3rd")


def _where(capture) -> str:
    return capture.path or "capture"


def _rows(capture):
    """(N (n,3), speed (n,), labels, sigma_N (n,3) or None, data line numbers)."""
    a = np.column_stack([np.asarray(capture.column(c), dtype=float) for c in ("ax", "ay", "az")])
    w = np.asarray(capture.column("speed_rad_s"), dtype=float)
    pos = capture.columns.get("position")
    first = (capture.header_line or 0) + 1
    if not capture.is_time_series:
        lines = [first + k for k in range(len(a))]
        stds = [capture.columns.get(c + "_std") for c in ("ax", "ay", "az")]
        n = capture.columns.get("n")
        sig = None
        if all(s is not None for s in stds) and n is not None:
            sig = np.column_stack(stds) / np.sqrt(np.asarray(n, float))[:, None]
            if not np.all(np.isfinite(sig)) or np.any(sig <= 0):
                sig = None
        labels = [str(p) for p in pos] if pos is not None else [str(k + 1) for k in range(len(a))]
        for k in range(len(a)):
            if not (np.all(np.isfinite(a[k])) and np.isfinite(w[k])):
                raise InputError(capture.path, lines[k], "row has an empty ax/ay/az/speed_rad_s")
        return a, w, labels, sig, lines
    if pos is None:
        raise UnsupportedError(
            f"{_where(capture)}: accel-centrifuge: a time series needs a 'position' column to "
            "tell the orientations apart (or give a table of averages, one row per "
            "orientation and speed)"
        )
    key = [(str(pos[k]), w[k]) for k in range(len(a))]
    N, W, L, S, lines = [], [], [], [], []
    k = 0
    while k < len(a):
        j = k + 1
        while j < len(a) and key[j] == key[k]:
            j += 1
        seg = a[k:j][np.all(np.isfinite(a[k:j]), axis=1)]
        if len(seg) >= 2 and np.isfinite(w[k]) and key[k][0]:
            N.append(seg.mean(axis=0))
            W.append(w[k])
            L.append(key[k][0])
            S.append(seg.std(axis=0, ddof=1) / math.sqrt(len(seg)))
            lines.append(first + k)
        k = j
    return np.array(N).reshape(-1, 3), np.array(W), L, np.array(S).reshape(-1, 3), lines


def _hold_means(capture, lines: list[int], column: str) -> np.ndarray | None:
    """A time series' ``column`` (``t``, ``temp_c``) averaged over each hold that :func:`_rows`
    made a row (the hold starting at data line ``lines[i]``, one mounting at one speed): the
    elapsed time and temperature the diagnosis needs for ``time_drift`` and ``temperature_bias``.
    None without the column, or where a hold has no value of it."""
    x = capture.columns.get(column)
    if x is None or not lines:
        return None
    x = np.asarray(x, float)
    a = np.column_stack([np.asarray(capture.column(c), dtype=float) for c in ("ax", "ay", "az")])
    out = []
    for rows in _hold_slices(capture, lines):
        ok = np.all(np.isfinite(a[rows]), axis=1) & np.isfinite(x[rows])
        if not ok.any():
            return None
        out.append(float(np.mean(x[rows][ok])))
    return np.array(out)


def _hold_slices(capture, lines: list[int]) -> list[slice]:
    """The capture rows of each hold that :func:`_rows` made a row (starting at data line ``lines[i]``)."""
    w = np.asarray(capture.column("speed_rad_s"), dtype=float)
    pos = capture.columns["position"]
    first = (capture.header_line or 0) + 1
    out = []
    for ln in lines:
        k = ln - first
        j = k + 1
        while j < len(w) and str(pos[j]) == str(pos[k]) and w[j] == w[k]:
            j += 1
        out.append(slice(k, j))
    return out


def _white_density(capture, lines: list[int]) -> np.ndarray | None:
    """Per axis, the white noise density N (output unit · √s) of the samples within holds
    (``solvers.allan.white_density``: the Allan model's white term, the median over the holds)."""
    from solvers.allan import white_density

    a = np.column_stack([np.asarray(capture.column(c), dtype=float) for c in ("ax", "ay", "az")])
    t = np.asarray(capture.column("t"), dtype=float)
    return white_density((a[sl], t[sl]) for sl in _hold_slices(capture, lines))


@dataclass
class Prepared:
    """A P2 capture read once: the rows of mean outputs, the radius and local gravity."""

    N: np.ndarray  # mean outputs (n, 3), the capture's accel_unit
    speed_rad_s: np.ndarray  # (n,)
    labels: list[str]  # mounting (position) per row
    sigma_N: np.ndarray | None  # standard error of each mean (n, 3), None when not measured
    lines: list[int]  # the capture's line of each row
    radius_m: float
    g_mps2: float
    warnings: list[str] = field(default_factory=list)


def prepare(capture) -> Prepared:
    """The radius, local gravity and averaged rows of ``capture`` (refusals as calibrate's)."""
    warnings: list[str] = []
    R = capture.float_meta("radius_m")
    if R is None or R <= 0:
        raise InputError(
            capture.path,
            capture.meta_lines.get("radius_m"),
            "metadata needs 'radius_m' (the centrifuge radius, m) for A = ω²R/g",
        )
    g = capture.local_gravity_mps2(warnings)
    N, w, labels, sigma_N, lines = _rows(capture)
    return Prepared(N, w, labels, sigma_N, lines, R, g, warnings)


# An accelerometer's scale in a physical unit is 1 per that unit within a few per cent: beyond this
# factor the unit is said wrongly (g data declared m/s² gives S of 0.1 m/s² per g)
UNIT_MISTAKE_FACTOR = 3.0


def _unit_mistake(accel_unit, S, g_mps2: float) -> str | None:
    """A warning when the fitted scale factors ``S`` (unit per g), in the physical ``accel_unit``
    the capture declares, are more than UNIT_MISTAKE_FACTOR from what that unit reads per g; it
    names the unit that would read closest."""
    from solvers.units import ACCEL_UNITS

    factor = ACCEL_UNITS.get(accel_unit) if accel_unit else None
    if not factor or S is None:
        return None
    size = float(np.mean(np.abs(np.asarray(S, float))))
    ratio = size / (g_mps2 / factor)
    if not size > 0 or 1 / UNIT_MISTAKE_FACTOR <= ratio <= UNIT_MISTAKE_FACTOR:
        return None
    best = min(("g", "m/s^2", "mg"), key=lambda u: abs(math.log(size * ACCEL_UNITS[u] / g_mps2)))
    return (
        f"the scale factors read {size:.4g} {accel_unit} per g, {ratio:.3g}x the {g_mps2 / factor:.4g} an "
        f"accelerometer in {accel_unit} reads: is accel_unit right? (the outputs look like {best})"
    )


def calibrate(capture, method: str | None = None, *, prepared: Prepared | None = None) -> dict:
    """The calibrate.md result for an ``accel-centrifuge`` capture."""
    key = method or "exact"
    all_rows = key.endswith("-all")
    base = key[:-4] if all_rows else key
    if base not in BASES:
        raise UnsupportedError(
            f"accel-centrifuge: unknown method {key!r} (methods: {', '.join(BASES)}, each optionally with -all)"
        )
    unit = capture.meta.get("accel_unit") or "raw"
    prep = prepared if prepared is not None else prepare(capture)
    warnings = list(prep.warnings)
    R, g = prep.radius_m, prep.g_mps2
    N, w, labels, sigma_N, lines = prep.N, prep.speed_rad_s, prep.labels, prep.sigma_N, prep.lines
    rho = C.norm_target(w, R, g)
    n_all = len(N)
    if len(np.unique(np.round(w, 9))) < 2:
        warnings.append(
            "one centrifuge speed only: the quadratic term D is poorly separated from the scale "
            "factor; use several speeds"
        )
    used = np.ones(n_all, bool)
    rejected = []
    try:
        if not all_rows and n_all >= 15:
            scr = C.screen_rows(N, rho, gamma=(base == "exact-gamma"))
            if (~scr.used).sum() and scr.used.sum() >= max(15, n_all // 2):
                used = scr.used
                for k in np.flatnonzero(~used):
                    rejected.append(
                        {
                            "row": int(k + 1),
                            "line": lines[k],
                            "position": labels[k],
                            "speed_rad_s": float(w[k]),
                            "residual_g": float(scr.residuals[k]),
                            "hint": scr.hints.get(int(k)),
                        }
                    )
                spread = scr.scale
                warnings.append(
                    f"{len(rejected)} of {n_all} rows disagree with the model far beyond the others "
                    f"(|f| off by {np.min(np.abs([r['residual_g'] for r in rejected])):.2g}–"
                    f"{np.max(np.abs([r['residual_g'] for r in rejected])):.2g} g against a spread of "
                    f"{spread:.2g} g) and are left out of the fit (use --method {base}-all to keep them)"
                )
                for r in rejected:
                    warnings.append(
                        f"line {r['line']} (position {r['position']}, ω {r['speed_rad_s']:.4g} rad/s): "
                        f"|f| − ρ = {r['residual_g']:+.3g} g" + (f"; {r['hint']}" if r["hint"] else "")
                    )
        Nu, ru = N[used], rho[used]
        sN = sigma_N[used] if sigma_N is not None else None
        if base in ("exact", "exact-gamma"):
            res = C.exact_fit(Nu, ru, sigma_N=sN, gamma=(base == "exact-gamma"))
        else:
            res = C.paper_fit(Nu, ru, variant="paper" if base == "paper" else "third-order")
    except SolverError as exc:
        raise UnsupportedError(f"{_where(capture)}: accel-centrifuge: {exc}") from None
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise UnsupportedError(f"{_where(capture)}: accel-centrifuge: the fit failed: {exc}") from None
    if res.fit is not None:
        if res.noise_known and res.fit.misfit_scaled:
            warnings.append(
                f"residuals are {math.sqrt(res.fit.reduced_chi2):.1f}× the measured noise: the model "
                "does not explain everything (installation angles, lever arm, cubic term?); "
                "uncertainties scaled up"
            )
        if not res.noise_known:
            warnings.append("no per-row noise (n, *_std columns): uncertainties come from the residual scatter")
    if base.startswith("paper"):
        warnings.append(
            "the paper's method truncates the inverse's series (error O(D³x⁵)) and fits 13 lumped "
            "coefficients without weights; its uncertainties are propagated from that fit"
        )
    params = {k: v for k, v in res.params.items()}
    mistake = _unit_mistake(capture.meta.get("accel_unit"), params.get("S"), g)
    if mistake:
        warnings.append(mistake)
    result = {
        "procedure": "accel-centrifuge",
        "device": capture.meta.get("device"),
        "model": MODEL,
        "params": params,
        "uncertainty": res.sigma,
        "residual_rms": res.residual_rms,
        "n_positions": int(used.sum()),
        "warnings": warnings,
        "method": key,
        "units": {
            "f": "g",
            "N": unit,
            "S": f"{unit} per g",
            "b": unit,
            "D": "g/g^2",
            "gamma": "rad",
            "residual_rms": "g (|f| − sqrt(A² + 1))",
        },
        "g_mps2": g,
        "radius_m": R,
        "n_rows": n_all,
        "rows_used": int(used.sum()),
        "rejected_rows": rejected,
        "noise": "measured (std/sqrt(n))" if res.noise_known else "estimated from the residuals",
    }
    if base == "exact-gamma":
        if res.extra.get("gamma_gauge") == "all":
            result["gamma_gauge"] = (
                "all 6 angles fitted: the quadratic term acts on the sensor's own axes, which "
                "makes a rotation of the whole triad visible at these accelerations"
            )
        else:
            result["gamma_gauge"] = (
                "γxy = γxz = γyz = 0: these data cannot see a rotation of the whole triad, so "
                "the frame's x axis is the x accelerometer's and its y axis lies in the x-y "
                "input plane"
            )
            warnings.append(
                "installation angles: only their non-orthogonal part is identifiable here; the triad's "
                "rotation is fixed by convention (γxy = γxz = γyz = 0)"
            )
    if res.fit is not None:
        result["reduced_chi2"] = res.fit.reduced_chi2
        result["condition_number"] = res.fit.condition_number
    if base.startswith("paper"):
        result["paper_coefficients"] = {
            "C0": res.extra["coefficients"][0],
            "C1": res.extra["coefficients"][1:4],
            "C2": res.extra["coefficients"][4:7],
            "C3": res.extra["coefficients"][7:10],
            "C4": res.extra["coefficients"][10:13],
        }
    return result


# the Results table's columns (review.residual_table adds the residual's unit to the last two)
RESIDUAL_COLUMNS = ("mounting @ ω rad/s", "|f|", "residual |f| − ρ")


def position_residuals(capture, result: dict) -> list[tuple[str, float, float]]:
    """The TUI's Results table of P2: per row (mounting @ speed, |f| [g], |f| − ρ [g]) with
    ``f`` the fitted model's inverse of the row's mean output and ρ = sqrt(A² + 1); a row the
    robust screen left out of the fit is marked so ([] when the result has no S, b, D)."""
    try:
        params = {k: np.asarray(v, dtype=float) for k, v in result["params"].items()}
        prep = prepare(capture)
        rho = C.norm_target(prep.speed_rad_s, prep.radius_m, prep.g_mps2)
        f = np.linalg.norm(accel_inverse(prep.N, params), axis=1)
    except (KeyError, TypeError, ValueError, InputError, UnsupportedError, np.linalg.LinAlgError):
        return []
    left_out = {r.get("row") for r in result.get("rejected_rows") or [] if isinstance(r, dict)}
    return [
        (f"{lab} @ {w:.2f}" + (" left out" if k + 1 in left_out else ""), float(fk), float(fk - rk))
        for k, (lab, w, fk, rk) in enumerate(zip(prep.labels, prep.speed_rad_s, f, rho))
    ]


def format_text(result: dict) -> str:
    from station.calibrate import jsonable
    from station.formatting import device_text, param_lines

    r = jsonable(result)
    u = r["units"]
    lines = [
        f"procedure  accel-centrifuge (P2, {r['method']})",
        f"device     {device_text(r)}",
        f"model      {r['model']}   (f in g, N in {u['N']})",
    ]
    for k in ("S", "b", "D", "gamma"):
        if k in r["params"]:
            lines += param_lines(f"{k} [{u[k]}]", r["params"][k], r["uncertainty"].get(k))
    lines.append(f"residual   {r['residual_rms']:.3g} g RMS of |f| − sqrt(A²+1)")
    lines.append(f"rows       {r['rows_used']} used of {r['n_rows']} (R = {r['radius_m']} m, g = {r['g_mps2']} m/s^2)")
    for w in r["warnings"]:
        lines.append(f"warning    {w}")
    return "\n".join(lines)


def diagnosis_input(capture, base: dict, prepared: Prepared | None = None) -> DiagnosisInput:
    """The P2 diagnosis problem around the baseline ``base`` (a calibrate result)."""
    from solvers.diagnose import problems as DP

    prep = prepared if prepared is not None else prepare(capture)
    N, w, labels, sigma_N, lines = prep.N, prep.speed_rad_s, prep.labels, prep.sigma_N, prep.lines
    p0 = {k: np.asarray(v, float) for k, v in base["params"].items() if k in ("S", "b", "D")}
    temp = (
        np.asarray(capture.columns["temp_c"], float)
        if "temp_c" in capture.columns and not capture.is_time_series
        else None
    )
    el = (
        np.asarray(capture.columns["elapsed_s"], float)
        if "elapsed_s" in capture.columns and not capture.is_time_series
        else None
    )
    if capture.is_time_series:  # each hold's mean time and temperature (they were left out: no time_drift)
        temp = _hold_means(capture, lines, "temp_c")
        el = _hold_means(capture, lines, "t")
    if temp is not None:  # a few empty temp_c fields: interpolated, not the whole temperature candidate lost
        temp = fill_missing(temp, el)
    # the calibration's own screen (solvers.centrifuge.screen_rows): rows that disagree with the
    # model far beyond the others are left out of the effect search too, and named by line
    rejected = {r["line"]: r for r in base.get("rejected_rows") or []}
    screened = []
    if rejected:
        keep = np.array([ln not in rejected for ln in lines])
        N, w = N[keep], w[keep]
        sigma_N = sigma_N[keep] if sigma_N is not None else None
        labels = [x for x, k in zip(labels, keep) if k]
        lines = [x for x, k in zip(lines, keep) if k]
        temp = temp[keep] if temp is not None else None
        el = el[keep] if el is not None else None
        for ln, r in rejected.items():
            screened.append(
                {
                    "kind": "outlier",
                    "line": ln,
                    "position": str(r["position"]),
                    "where": f"line {ln} (position {r['position']}, ω={r['speed_rad_s']:.3g} rad/s)",
                    "speed_rad_s": r["speed_rad_s"],
                    "residual_g": r["residual_g"],
                    "screened": True,
                    "explanation": f"|f| − ρ = {r['residual_g']:+.3g} g, far beyond the other rows' spread "
                    "(the calibration leaves it out; so does the effect search)"
                    + (f"; {r['hint']}" if r.get("hint") else ""),
                }
            )
    prob = DP.centrifuge_problem(
        N, w, prep.radius_m, prep.g_mps2, p0, labels=labels, sigma_N=sigma_N, temp_c=temp, elapsed_s=el
    )
    prob.row_labels = [f"line {ln} (position {lab}, ω={x:.3g} rad/s)" for ln, lab, x in zip(lines, labels, w)]
    prob.screened = screened
    if capture.is_time_series and el is not None:
        # the hold means share a slow bias wander that the rows' white σ leaves out: a prior on
        # its size from the white noise measured within the holds (the Allan model's white term)
        dens = _white_density(capture, lines)
        if dens is not None:
            DP.set_slow_bias_prior(prob, el, dens)
    else:
        # no samples within the rows to size the bias wander: a bias per mounting, sized on the table
        prob.slow_noise = {
            "modelled": False,
            "reason": "a table of averages has no samples within holds, and no bias per mounting could be "
            "sized (no mounting has two rows, or too few rows are left beside the model): the bias "
            "instability between rows is not sized, and effects are tested against the rows' white noise alone",
        }
        DP.set_mounting_bias_noise(prob)
    return DiagnosisInput(
        prob,
        {"position": labels, "speed_rad_s": w},
        "a row that disagrees with the norm condition: a transcription error or a mounting that shifted",
        group_kind="mounting",
    )


def firmware_accel(params: dict, k: float, unit: str) -> tuple[list[float], list[float], list[str]]:
    """P2 as a flight firmware's accelerometer offsets and scales (``station.firmware_export``:
    ``a = (a_fw - offset) * scale``, a_fw in m/s²); ``k`` m/s² per ``unit`` of the capture's N.
    Returns (offsets m/s², scales, notes for the export's comments)."""
    from solvers.frames import G_STANDARD_MPS2
    from station.firmware_export import vector

    S, b = vector(params, "S"), vector(params, "b")
    scales = [G_STANDARD_MPS2 / (k * S[i]) for i in range(3)]
    offsets = [k * b[i] for i in range(3)]
    dropped = ["D (second-order, g/g^2)"]
    if "gamma" in params:
        dropped.append("gamma (misalignment)")
    notes = [
        f"from N = S Phi [f + D f^2] + b (P2), f in g, N in {unit}: scale = g0 / (S_i * {k:.6g} m/s^2 per {unit}), "
        f"offset = b_i in m/s^2 (g0 = {G_STANDARD_MPS2} m/s^2, the firmware's)",
        "dropped: " + ", ".join(dropped) + "; the firmware model is offset and scale only",
    ]
    return offsets, scales, notes
