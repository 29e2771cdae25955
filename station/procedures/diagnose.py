"""`station diagnose`: capture → per-procedure problem → engine → the diagnose.md dict.

Each procedure module (``station/procedures/<stem>.py``, listed in the registry) prepares
its capture once (``prepare``), calibrates the baseline from it and builds its problem
(``diagnosis_input``); the numerics are ``solvers.diagnose``.
"""

from __future__ import annotations

import re
import textwrap

import numpy as np

from solvers.diagnose import diagnose
from solvers.diagnose import quality as Q
from solvers.diagnose.engine import WHITE_P
from solvers.errors import SolverError
from station.capture import strictly_increasing_t
from station.errors import UnsupportedError
from station.procedures.contract import DiagnosisInput


def _where(capture) -> str:
    return capture.path or "capture"


def file_line(capture, row: int) -> int | None:
    """The file line of capture row ``row`` (0-based), None for a capture not read from a file."""
    return None if capture.header_line is None else int(capture.header_line) + 1 + int(row)


_line = file_line


# ---------------------------------------------------------------- quality

SENSOR_COLUMNS = ("ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "vl1", "vl2", "vl3")


def moved_positions(capture) -> list[dict]:
    """Labelled positions of a time series during which the unit moved (rows: capture row
    indices; ``solvers.diagnose.quality.moved_positions`` on the stillness detector's mask)."""
    if not (capture.is_time_series and "position" in capture.columns and any(capture.columns["position"])):
        return []
    from solvers.stillness import detect_static_intervals

    a = np.column_stack([np.asarray(capture.columns[c], float) for c in ("ax", "ay", "az") if c in capture.columns])
    if a.shape[1] != 3:
        return []
    g = (
        np.column_stack([np.asarray(capture.columns[c], float) for c in ("gx", "gy", "gz")])
        if all(c in capture.columns for c in ("gx", "gy", "gz"))
        else None
    )
    try:
        t = strictly_increasing_t(capture.columns["t"])
        st = detect_static_intervals(t, a, g, nan_policy="omit")
        return Q.moved_positions(st.still_mask, capture.columns["position"], t, st.config.window_n)
    except (SolverError, ValueError):
        return []


def screen(capture, moved=()) -> tuple[np.ndarray, list[dict]]:
    """The data-quality screen of a time-series capture (``solvers.diagnose.quality.screen``):
    ``(bad, findings)``, ``bad`` per capture row (left out of the effect search), the findings
    by file line (``line``, ``line_stop``) with ``"screened": True``. A procedure's
    ``diagnosis_input`` calls it before building its problem and puts the findings in
    ``problem.screened``; ``moved`` are its moved-position findings (rows as row indices)."""
    n = capture.n_rows
    if not (capture.is_time_series and "t" in capture.columns):
        return np.zeros(n, bool), []
    cols = {c: capture.columns[c] for c in SENSOR_COLUMNS if c in capture.columns}
    bad, found = Q.screen(n, capture.columns["t"], cols, moved)
    for q in found:
        q["line"] = _line(capture, q.pop("row"))
        if "row_stop" in q:
            q["line_stop"] = _line(capture, q.pop("row_stop") - 1)
    return bad, found


def _noise_free(diag) -> bool:
    """Whether the extended model fits the measured rows to within the problem's noise floor
    (``Problem.noise_floor``, data units, RMS): exact, noise-free data. Outliers and a
    non-white test are then about the rounding, studentized by a noise of ~0 (an exact P1 time
    series had 2 rows "beyond 5σ" and "residuals not noise-like: something remains" at 1e-16 m/s²),
    and are not reported; the candidates say why nothing was sought."""
    prob = diag.problem
    if prob.noise_floor is None:
        return False
    r = np.asarray(diag.extended.residuals, float)
    if prob.row_types is not None:
        r = r[np.isin(np.asarray(prob.row_types), sorted(prob.measured_kinds))]
    return bool(r.size) and float(np.sqrt(np.mean(r * r))) <= prob.noise_floor


def _quality(capture, diag, inp) -> list[dict]:
    out: list[dict] = list(diag.problem.screened)  # rows the data-quality screen left out, by line
    out += [dict(q) for q in diag.problem.findings]
    seen = {(q.get("kind"), q.get("line"), q.get("column")) for q in out}
    if capture.is_time_series and "t" in capture.columns:
        for q in Q.gaps(capture.columns["t"]):
            q["line"] = _line(capture, q.pop("row"))
            if (q["kind"], q["line"], None) not in seen:
                out.append(q)
    num = {
        c: v
        for c, v in capture.columns.items()
        if c in ("ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "vl1", "vl2", "vl3")
    }
    if capture.is_time_series:
        for q in Q.saturation(num):
            q["line"] = _line(capture, q.pop("row"))
            q.pop("runs", None)
            if (q["kind"], q["line"], q["column"]) not in seen:
                out.append(q)
    for q in inp.quality:
        q = dict(q)
        q["line"] = _line(capture, q.pop("row"))
        if "row_stop" in q:
            q["line_stop"] = _line(capture, q.pop("row_stop") - 1)
        out.append(q)
    exact = _noise_free(diag)
    for q in [] if exact else Q.outliers(diag.studentized, diag.problem.row_labels, inp.explain):
        out.append(q)
    if diag.residual_test.get("white") is False and not exact:
        rt = diag.residual_test
        drivers = [
            {"driver": d["driver"], "correlation": d["correlation"], "explained_by_trend": d["explained_by_trend"]}
            for d in rt.get("drivers", [])[:3]
        ]
        top = (
            ", ".join(
                f"{d['driver']} ({100 * d['explained_by_trend']:.0f} % of the residual variance follows it)"
                for d in drivers
            )
            or "no driver of this capture"
        )
        finding = {
            "kind": "residuals_not_white",
            "test": rt["test"],
            "p_value": rt.get("p_value"),
            "drivers": drivers,
            "explanation": "the extended model's residuals are not noise-like: something remains that no "
            f"candidate explains (or the noise is correlated); they follow most: {top}",
        }
        if rt.get("wander"):
            unit = diag.problem.unit
            names = diag.problem.series_names
            finding["wander"] = [
                {
                    "series": names.get(w["series"], str(w["series"])),
                    "sigma": w["sigma"],
                    "tau_s": w["tau_s"],
                    "unit": unit,
                }
                for w in rt["wander"]
            ]
            scale, shown = _said_in(diag.problem.procedure, unit)
            finding["explanation"] += (
                "; a slow wander (bias instability, first-order Gauss–Markov) fits them: "
                + ", ".join(
                    f"{w['series']} σ {scale * w['sigma']:.3g} {shown} over τ ≈ {w['tau_s']:.0f} s"
                    for w in finding["wander"]
                )
            )
        out.append(finding)
    return out


# ---------------------------------------------------------------- entry point


def _explained(diag, flagged) -> bool:
    """Whether the extended model of ``diag`` leaves none of the ``flagged`` groups an outlier."""
    prob = diag.problem
    primary = None if prob.row_types is None else np.asarray(prob.row_types) == 0
    return not Q.group_outliers(diag.studentized, prob.groups, list(flagged), primary)


def analyse(capture, progress=None) -> tuple[dict, object, DiagnosisInput]:
    """(diagnose.md dict, the engine's Diagnosis, the procedure's diagnosis input).

    ``progress``: called with the step begun, in words ("searching the candidate effects"),
    before each (the TUI says it while it works; a step may take a minute)."""
    from station.calibrate import calibrate_capture, guarded, procedure_module
    from station.guard import check_extremes, quiet_stdout

    def step(what: str) -> None:
        if progress is not None:
            progress(what)

    module = procedure_module(capture.procedure, capture.path)  # unknown/missing procedure → InputError
    if not hasattr(module, "diagnosis_input"):
        raise UnsupportedError(f"{capture.procedure}: no diagnosis for this procedure")
    step("checking and preparing the capture")
    check_extremes(capture)
    with quiet_stdout():  # a dependency's print never reaches stdout (the result carries the findings)
        prepared = guarded(capture, module.prepare, capture)
    if module.DIAGNOSIS_BASELINE:
        step("calibrating (the baseline model)")
    base = calibrate_capture(capture, prepared=prepared) if module.DIAGNOSIS_BASELINE else None

    def run():
        try:
            inp = module.diagnosis_input(capture, base, prepared)
            return inp, diagnose(inp.problem)
        except SolverError as exc:
            raise UnsupportedError(f"{_where(capture)}: {capture.procedure}: diagnosis failed: {exc}") from None

    step("fitting the baseline and searching the candidate effects")
    with quiet_stdout():
        inp, diag = guarded(capture, run)
        if inp.kept is not None:
            step("searching again with the outlier positions kept")
            # groups the screen left out as outliers may be the effect itself (a temperature bias
            # shows most on the positions along it): searched with them kept, the result stands
            # when it names effects under which none of them is an outlier any more
            try:
                inp2 = inp.kept()
                diag2 = diagnose(inp2.problem)
            except SolverError:
                diag2 = None
            if diag2 is not None and diag2.verdict and _explained(diag2, inp2.flagged_groups):
                inp, diag = inp2, diag2
    out = _result(capture, capture.procedure, diag, inp)
    # a second sensor the same session calibrates (P1's gyro: station.procedures.tabletop_gyro)
    subs = getattr(module, "SUB_DIAGNOSES", {})
    for key, (name, make) in subs.items():

        def run_sub(make=make):
            try:
                sub = make(capture, base, prepared)
                return None if sub is None else (sub, diagnose(sub.problem))
            except SolverError as exc:  # the first sensor's diagnosis stands on its own
                return str(exc)

        step(f"diagnosing the second sensor ({name})")
        with quiet_stdout():
            got = guarded(capture, run_sub)
        if isinstance(got, str):
            out[key] = {"procedure": name, "error": f"diagnosis failed: {got}"}
        elif got is not None:
            out[key] = _result(capture, name, got[1], got[0])
            diag.subs[key] = (got[1], got[0])
    return out, diag, inp


def _result(capture, procedure, diag, inp) -> dict:
    bp = diag.baseline
    return {
        "procedure": procedure,
        "baseline": {
            "model": diag.model,
            "params": bp.params,
            "residual_rms": diag.rms(bp),
            "cv_rms": diag.baseline_cv_rms,
            # not in diagnose.md: the slow noise the candidates were tested against, or why none
            **({"slow_noise": diag.problem.slow_noise} if diag.problem.slow_noise else {}),
        },
        "candidates": diag.candidates,
        "effects": diag.effects,
        "extended": {
            "model": diag.extended_model,
            "params": diag.extended.params,
            "residual_rms": diag.rms(diag.extended),
            "cv_rms": diag.extended_cv_rms,
        },
        "quality": _quality(capture, diag, inp),
        "verdict": diag.verdict,
        # not in diagnose.md: which unit the numbers are in, where a parameter's is not the residuals'
        **(
            {"units": {"residuals": diag.problem.unit} | {k: u[0] for k, u in inp.param_units.items()}}
            if inp.param_units
            else {}
        ),
    }


def _hang(line: str, width: int) -> list[str]:
    """``line`` in lines of at most ``width`` columns, each continuation under the line's
    text column (after its label and the spaces that follow it), so that it never reads as
    a new entry (a screen's own wrapping starts it at the left edge)."""
    if len(line) <= width:
        return [line]
    m = re.match(r"\s*\S+(?: \S+)*?\s{2,}", line)  # the label and the run of spaces after it
    indent = len(m.group(0)) if m and len(m.group(0)) <= width // 2 else len(line) - len(line.lstrip()) + 2
    return textwrap.wrap(line, width, subsequent_indent=" " * indent, break_on_hyphens=False) or [line]


def _said_in(procedure: str | None, unit: str) -> tuple[float, str]:
    """(factor, unit) the residuals are said in: the unit the screens show the procedure's
    residual in (``review.display_unit``, e.g. P4's °/h) when they are in its stored unit;
    else as they are (1, ``unit``). The JSON keeps the stored unit."""
    from station.procedures.review import display_unit, result_unit

    if unit != result_unit({"procedure": procedure}):
        return 1.0, unit
    return display_unit({"procedure": procedure}, "residual_rms") or (1.0, unit)


def format_text(
    result: dict, diag, inp: DiagnosisInput, plots: bool = True, plot_width: int = 78, width: int | None = None
) -> str:
    """The findings for a person, residuals in the unit the screens show them in
    (:func:`_said_in`); ``width``: wrap the text lines to it (the TUI's), each continuation
    indented under its text (the plots take ``plot_width``)."""
    from station.calibrate import jsonable

    r = jsonable(result)
    scale, unit = _said_in(r.get("procedure"), diag.problem.unit)
    # what the RMS is over (P4: block means, where calibrate's residual is per sample)
    of = f" of {diag.problem.rows_are}" if getattr(diag.problem, "rows_are", "") else ""
    L = [f"procedure   {r['procedure']}"]
    for q in r["quality"]:  # structured residuals are said first, before any verdict
        if q["kind"] == "residuals_not_white":
            L.append(
                f"WARNING     residuals not noise-like ({q['test']}, p = {q['p_value']:.3g}): "
                + q["explanation"].split("; ", 1)[-1]
            )
    L += [
        f"baseline    {r['baseline']['model']}",
        f"            residual {scale * r['baseline']['residual_rms']:.4g} {unit} RMS{of}, "
        f"held-out {scale * r['baseline']['cv_rms']:.4g} {unit} RMS",
        # the bound is the exact F test's on the degrees of freedom left (engine.deviance_quantile),
        # which is F·χ²_k only for many rows
        "candidates  (selected: deviance / serial-correlation inflation > the F test's level-0.05/m bound "
        f"on the degrees of freedom left, scaled by F = {_f_text(diag.problem)} (F·χ²_k(1 − 0.05/m) for many rows), "
        "and a lower held-out RMS; refitted and re-tested after each pick)",
    ]
    for c in r["candidates"]:
        if c.get("resolvable") is False:
            L.append(f"  {c['name']:<24} unresolvable: {c['reason']}")
        else:
            mark = "  <- selected" if c["selected"] else ""
            L.append(
                f"  {c['name']:<24} ΔBIC {c['delta_bic']:+10.1f}   held-out RMS {scale * c['cv_rms']:.4g} {unit}{mark}"
            )
    for e in r["effects"]:
        L.append(
            f"effect      {e['name']}: held-out RMS {scale * e['cv_rms_before']:.4g} → {scale * e['cv_rms_after']:.4g} {unit} "
            f"(gain {100 * e['gain']:.1f} %)"
        )
        for c in e["confused_with"]:
            if "why" in c:
                L.append(f"            cannot be told apart from {c['name']} ({c['why']})")
            else:
                L.append(f"            cannot be told apart from {c['name']} (correlation {c['correlation']:+.3f})")
        if e["name"].startswith("residual:"):
            corr = ", ".join(f"{k} {v:.2f}" for k, v in e.get("correlation", {}).items())
            L.append(
                f"            outside the library: a {e.get('shape')} function of {e.get('driver')}"
                f"{' that steps back (a pulse: on at `at`, off at `until`)' if 'until' in e['params'] else ''}"
                f"{' acting on the scale' if e['params'].get('acts_on') == 'scale' else ''}; "
                f"correlation with the library's signatures: {corr or 'none resolvable'}"
            )
        for k, v in e["params"].items():
            if k not in e["uncertainty"]:  # a residual effect's description (step place, period, knots)
                L.append(f"            {k} = {_described(v)}{_driver_unit(e, k)}")
                continue
            L.append(f"            {k} = {_value_sigma_unit(v, e['uncertainty'][k], inp.param_units.get(k))}")
    L.append(f"extended    {r['extended']['model']}")
    L.append(
        f"            residual {scale * r['extended']['residual_rms']:.4g} {unit} RMS{of}, "
        f"held-out {scale * r['extended']['cv_rms']:.4g} {unit} RMS"
    )
    rt = diag.residual_test
    if rt.get("p_value") is not None:
        L.append(
            f"            residual test {rt['test']}: p = {rt['p_value']:.3g} "
            f"({f'noise-like: p > {WHITE_P:g}' if rt['white'] else f'NOT noise-like: p ≤ {WHITE_P:g}'})"
        )
    for q in r["quality"]:
        if q.get("screened"):
            where = q.get("where") or q.get("column") or ""
        else:
            where = q.get("position") or q.get("where") or q.get("column") or ""
        where = str(where)
        line = f"line {q['line']}" if q.get("line") and f"line {q['line']} " not in f"{where} " else ""
        head = " ".join(x for x in (q["kind"], where, line) if x)
        L.append(f"quality     {head}: {q['explanation']}")
    L.append("verdict     " + (", ".join(r["verdict"]) if r["verdict"] else "none"))
    L += _per_group(diag, inp.group_kind, scale, unit)
    if width is not None:
        L = [part for line in L for part in _hang(line, width)]
    if plots:
        L.append(_plots(diag, plot_width, scale, unit))
    for key, val in result.items():
        if isinstance(val, dict) and "error" in val and "procedure" in val:
            L.append(f"--- {key}: {val['procedure']}: {val['error']}")
    for key, (sdiag, sinp) in diag.subs.items():
        if key in result:
            L.append("")
            L.append(f"--- {key}: {result[key]['procedure']} (the same session's second sensor)")
            L.append(format_text(result[key], sdiag, sinp, plots=False, plot_width=plot_width, width=width))
    return "\n".join(L)


def _value_sigma_unit(v, s, units) -> str:
    """An effect's parameter ± its 1σ (8 decimals), its unit where the procedure names one
    (``DiagnosisInput.param_units``), and in the residuals' unit too where a factor exists (the
    compass's hard-iron step in uT, = nT beside the residuals in nT). A σ of exactly 0 (a place
    found by a scan, not estimated) is "—" (``station.formatting.sigma``)."""
    from station.formatting import MISSING

    value = np.asarray(v, dtype=float)
    sig = np.asarray(s, dtype=float)
    not_estimated = bool(sig.size) and bool(np.all(sig == 0))
    text = f"{np.round(value, 8).tolist()} ± {MISSING if not_estimated else np.round(sig, 8).tolist()}"
    if not units:
        return text
    unit, factor, converted = units
    text += f" {unit}"
    if factor and factor != 1.0:
        text += f" (= {_g(value * factor, '.6g')}"
        text += "" if not_estimated else f" ± {_g(sig * factor, '.2g')}"
        text += f" {converted})"
    return text


def _g(x: np.ndarray, fmt: str) -> str:
    """A number or a list of numbers, each as ``format(x, fmt)``."""
    return format(float(x), fmt) if x.ndim == 0 else "[" + ", ".join(format(float(a), fmt) for a in x.ravel()) + "]"


# the unit a residual term's place (a step's "at", a pulse's "until") or period is measured in, by its driver
DRIVER_UNITS = {"time": "s", "temperature": "°C", "speed": "rad/s", "rate": "rad/s"}


def _described(v):
    """A residual term's description value, numbers to 6 significant figures."""
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, (list, tuple)) and all(isinstance(x, (int, float)) for x in v):
        return "[" + ", ".join(f"{x:.6g}" for x in v) + "]"
    return v


def _driver_unit(e: dict, key: str) -> str:
    """The unit of a residual term's place or period: its driver's (time in s, …)."""
    if key not in ("at", "until", "period") or not isinstance(e["params"].get(key), (int, float)):
        return ""
    unit = DRIVER_UNITS.get(str(e.get("driver")))
    return f" {unit}" if unit else ""


def _f_text(prob) -> str:
    """The procedure's F, and any candidate's own (measured on nulls) beside it."""
    own = {k: v for k, v in prob.cand_thresholds.items() if v != prob.threshold}
    return f"{prob.threshold:g}" + "".join(f", {k} {v:g}" for k, v in own.items())


def _per_group(diag, kind: str, k: float = 1.0, unit: str | None = None) -> list[str]:
    """Measured − simulated per CV group (position, mounting or time block), baseline and extended."""
    prob = diag.problem
    keep = np.ones(len(prob.sigma), bool) if prob.row_types is None else np.asarray(prob.row_types) == 0
    g = np.asarray(prob.groups)
    base, ext = -k * diag.baseline.residuals, -k * diag.extended.residuals  # measured − simulated, said in unit
    uniq = list(dict.fromkeys(g[keep].tolist()))
    if not uniq or len(uniq) > 40:
        return []
    out = [f"measured − simulated per {kind} [{unit or prob.unit}]: mean (RMS), baseline → extended"]
    rows = []
    for u in uniq:
        m = keep & (g == u)
        first = int(np.flatnonzero(m)[0])
        name = prob.row_labels[first].split(" |f|")[0] if prob.row_labels else str(u)
        hit = re.search(r"position ([^,) ]+)", name)
        if hit:
            name = f"position {hit.group(1)}"
        if kind == "time block" and "time [s]" in prob.drivers:
            tt = np.asarray(prob.drivers["time [s]"])[m]
            name = f"t {np.nanmin(tt):.1f}–{np.nanmax(tt):.1f} s"
        elif kind == "block of positions" and "position #" in prob.drivers:
            pp = np.asarray(prob.drivers["position #"])[m]
            name = f"positions {np.nanmin(pp):.0f}–{np.nanmax(pp):.0f}"
        rows.append(
            (
                name,
                f"{np.mean(base[m]):+.3e} ({np.sqrt(np.mean(base[m] ** 2)):.2e})  →  "
                f"{np.mean(ext[m]):+.3e} ({np.sqrt(np.mean(ext[m] ** 2)):.2e})",
            )
        )
    w = max(len(name) for name, _ in rows)  # as wide as the longest name: a row fits 80 columns
    return out + [f"  {name:<{w}}  {text}" for name, text in rows]


def _plots(diag, width: int = 78, k: float = 1.0, unit: str | None = None) -> str:
    """Measured − simulated (the fitted baseline, primary rows) against each driver, each
    ``width`` columns wide (the screen passes its own width: a wider plot wraps)."""
    try:
        import plotext as plt
    except ImportError:  # pragma: no cover - plotext is a dependency
        return ""
    prob = diag.problem
    res = -k * np.asarray(diag.baseline.residuals, float)  # measured − simulated, said in unit
    keep = np.ones(len(res), bool) if prob.row_types is None else np.asarray(prob.row_types) == 0
    out = []
    series = dict(prob.drivers) or {"row": np.arange(len(res), dtype=float)}
    for name, x in list(series.items())[:3]:
        x = np.asarray(x, float)
        ok = keep & np.isfinite(x)
        if ok.sum() < 2:
            continue
        step = max(1, int(ok.sum()) // 2000)
        xs, ys = x[ok][::step], res[ok][::step]
        plt.clear_figure()
        plt.theme("clear")
        plt.plot_size(width, 13)
        plt.scatter(xs.tolist(), ys.tolist(), marker="dot")
        plt.title(f"measured − simulated baseline [{unit or prob.unit}] against {name}")
        out.append(plt.uncolorize(plt.build()))  # the "clear" theme still ends lines with a colour reset
    return "\n".join(out)
