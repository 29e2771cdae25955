"""`station diagnose`: capture → per-procedure problem → engine → the diagnose.md dict.

Data preparation is the calibrators' own (their position finding, unit and sign handling
are imported from ``station/procedures/<name>.py``); the baseline starts from
``station.calibrate.calibrate_capture``; the numerics are ``solvers.diagnose``.
"""
from __future__ import annotations

import math
import re

import numpy as np

from solvers import frames
from solvers.diagnose import diagnose
from solvers.diagnose import problems as DP
from solvers.diagnose import quality as Q
from solvers.errors import SolverError
from solvers.models import accel as accel_model
from solvers.models import gyro as gyro_model
from solvers.units import si_factor
from station.errors import InputError, UnsupportedError


def _where(capture) -> str:
    return capture.path or "capture"


def _col(capture, name):
    x = capture.columns.get(name)
    return None if x is None else np.asarray(x, float)


def _line(capture, row: int) -> int | None:
    return None if capture.header_line is None else int(capture.header_line) + 1 + int(row)


# ---------------------------------------------------------------- per procedure

def _tabletop(capture, base: dict):
    from solvers import tabletop as T
    from station.procedures import tabletop as P1

    warnings: list[str] = []
    g = P1.gravity(capture, warnings)
    positions, _, noise_known = P1.static_positions(capture, warnings)
    B, M = np.asarray(base["params"]["B"], float), np.asarray(base["params"]["M"], float)
    dirs = [p.direction for p in positions]
    if sum(d is not None for d in dirs) < 3:
        B, M = T.to_upper(B, M)
    fw = accel_model.p1_to_forward(B, M)
    t_mean, temp_mean = None, None
    temp = _col(capture, "temp_c")
    if capture.is_time_series:
        t = _col(capture, "t")
        t_mean = np.array([0.5 * (p.t_start_s + p.t_stop_s) for p in positions])
        if temp is not None:
            temp_mean = np.array([np.nanmean(temp[(t >= p.t_start_s) & (t <= p.t_stop_s)]) for p in positions])
    else:
        temp_mean = temp
        t_mean = _col(capture, "t")
    std = np.array([p.std if p.std is not None else np.full(3, np.nan) for p in positions])
    prob = DP.tabletop_problem(np.array([p.mean for p in positions]), std if noise_known else None,
                               np.array([p.n for p in positions]), g, fw["K"], fw["b"],
                               labels=[p.label for p in positions], directions=dirs,
                               placement_sigma_rad=[p.placement_sigma_rad for p in positions],
                               t_s=t_mean, temp_c=temp_mean, noise_known=noise_known)
    drivers = {"position": [p.label for p in positions], "time_s": t_mean, "temp_c": temp_mean}
    n_norm = len(positions)
    return prob, drivers, n_norm, "a position that disagrees with the others: the unit moved, a wrong label, or a knock"


def _gyro(capture, base: dict):
    from solvers.gyrodrift import earth_rate_body_sigma  # noqa: F401  (same frames as mode B)
    from station.procedures import gyrodrift as P4

    warnings: list[str] = []
    C, asign, flips = P4._conventions(capture, warnings)
    unit = "rad/s"
    try:
        k = P4._gyro_factor(capture, warnings)
    except UnsupportedError:
        # counts without a scale: diagnose in the capture's own unit (effects are relative)
        k, unit = 1.0, capture.meta.get("gyro_unit", "raw")
    w_b = (P4._need(capture, ["gx", "gy", "gz"]) * flips * k) @ C.T
    f_b = None
    if all(c in capture.columns for c in ("ax", "ay", "az")):
        f_b = (P4._need(capture, ["ax", "ay", "az"]) * asign) @ C.T
    if "ref_gx" in capture.columns:
        w_b = w_b - P4._need(capture, ["ref_gx", "ref_gy", "ref_gz"]) @ C.T
        lat = None
        mode_ref = True
    else:
        lat = capture.float_meta("latitude_deg")
        mode_ref = False
    dt = P4._dt(capture)
    ok = P4._finite_rows([w_b, f_b], warnings, "gyro or accelerometer")
    segs = [((m, h, lab)) for m, h, lab in P4._segments(capture, w_b, f_b, dt, ok, warnings)] if not mode_ref \
        else [(ok, 0.0, "1")]
    n = len(w_b)
    t = _col(capture, "t")
    if t is None:
        t = np.arange(n) * dt
    label = np.full(n, "", dtype=object)
    E = np.zeros((n, 3))
    Cbn = np.zeros((n, 3, 3))
    gnorm = None
    for m, head, lab in segs:
        if m.sum() < 8:
            continue
        label[m] = lab
        if f_b is not None:
            fm = np.mean(f_b[m], axis=0)
            p, r = frames.p4_pitch_roll_from_accel(fm)
        else:
            p, r = 0.0, 0.0
        Cnb = frames.p4_C_n_b(p, r, math.radians(head))
        Cbn[m] = Cnb.T
        if lat is not None:
            E[m] = gyro_model.earth_rate_body(lat, Cnb)
    use = label != ""
    order = np.flatnonzero(use)
    if len(order) < 16:
        raise UnsupportedError(f"{capture.path}: gyro-drift: {len(order)} static samples; diagnosis needs a "
                               "static record (P4 asks for >= 3 min)")
    f_mps2 = None
    if f_b is not None:
        gnorm = float(np.median(np.linalg.norm(f_b[use], axis=1)))
        if not gnorm > 0:
            raise UnsupportedError(f"{capture.path}: the accelerometer reads zero on average (a dead or "
                                   "unconnected sensor?): check the ax ay az columns")
        f_mps2 = f_b[use] * (frames.G_STANDARD_MPS2 / gnorm)
    prob = DP.gyro_problem(t[order], w_b[order], f_mps2, _col(capture, "temp_c")[order]
                           if "temp_c" in capture.columns else None,
                           E[order] if (lat is not None or mode_ref) else None, label[order], C_b_n=Cbn[order])
    prob.unit = unit
    return prob, {"rows": order}, None, "a block far off the others: a knock, the unit moved, or a bias jump"


def _ldv(capture, base: dict):
    from station.procedures import ldv as P5

    warnings: list[str] = []
    v_b, vl, info = P5.aligned_velocities(capture, None, warnings)
    rows = info.get("rows")
    pick = (lambda name: None if name not in capture.columns or rows is None else _col(capture, name)[rows])
    t = pick("t")
    W = None
    if rows is not None and all(c in capture.columns for c in ("wx", "wy", "wz")):
        W = np.column_stack([_col(capture, c)[rows] for c in ("wx", "wy", "wz")])
    X0 = np.array([base["fit"][f"beam{j + 1}"]["X"] for j in range(3)], float)
    prob = DP.ldv_problem(t, v_b, vl, X0, temp_c=pick("temp_c"), omega_body_rad_s=W)
    return prob, {"rows": rows}, None, "a sample far off: a dropout of the LDV or the reference"


def _centrifuge(capture, base: dict):
    from station.procedures import centrifuge as P2

    N, w, labels, sigma_N, lines = P2._rows(capture)
    R = capture.float_meta("radius_m")
    if R is None or R <= 0:
        raise InputError(capture.path, None, "metadata needs 'radius_m'")
    g = capture.float_meta("g_mps2")
    if g is None:
        lat = capture.float_meta("latitude_deg")
        g = frames.normal_gravity_mps2(lat, capture.float_meta("altitude_m", 0.0)) if lat is not None \
            else frames.G_STANDARD_MPS2
    p0 = {k: np.asarray(v, float) for k, v in base["params"].items() if k in ("S", "b", "D")}
    temp = _col(capture, "temp_c") if not capture.is_time_series else None
    el = _col(capture, "elapsed_s") if not capture.is_time_series else None
    prob = DP.centrifuge_problem(N, w, R, g, p0, labels=labels, sigma_N=sigma_N, temp_c=temp, elapsed_s=el)
    prob.row_labels = [f"line {ln} (position {lab}, ω={x:.3g} rad/s)" for ln, lab, x in zip(lines, labels, w)]
    return prob, {"position": labels, "speed_rad_s": w}, None, \
        "a row that disagrees with the norm condition: a transcription error or a mounting that shifted"


def _compass(capture, base: dict):
    from solvers.stillness import detect_static_intervals

    y = np.column_stack([_col(capture, c) for c in ("mx", "my", "mz")])
    good = np.all(np.isfinite(y), axis=1)
    t = _col(capture, "t")
    if t is None:
        raise UnsupportedError(f"{_where(capture)}: compass diagnosis needs a time series ('t' column)")
    W0 = np.asarray(base["params"]["soft_iron"], float)
    h0 = np.asarray(base["params"]["hard_iron"], float)
    F = float(base["field_nT"])
    incl = base["params"]["reference"].get("inclination_deg")
    noise = base.get("noise_raw") or 1.0
    temp = _col(capture, "temp_c")
    static = {}
    if all(c in capture.columns for c in ("ax", "ay", "az")):
        a = np.column_stack([_col(capture, c) for c in ("ax", "ay", "az")])
        gyro = np.column_stack([_col(capture, c) for c in ("gx", "gy", "gz")]) \
            if all(c in capture.columns for c in ("gx", "gy", "gz")) else None
        ok = good & np.all(np.isfinite(a), axis=1)
        try:
            st = detect_static_intervals(t[ok], a[ok], None if gyro is None else gyro[ok], nan_policy="omit")
            idx = np.flatnonzero(ok)
            ivs = [iv for iv in st.intervals if iv.n >= 5]
            if len(ivs) >= 4:
                static = {
                    "static_f": np.array([iv.accel_mean for iv in ivs]),
                    "static_y": np.array([y[idx[iv.start:iv.stop]].mean(axis=0) for iv in ivs]),
                    "static_t": np.array([t[idx[iv.start:iv.stop]].mean() for iv in ivs]),
                    "static_temp": None if temp is None else
                    np.array([np.nanmean(temp[idx[iv.start:iv.stop]]) for iv in ivs]),
                }
        except (SolverError, ValueError):
            static = {}
    prob = DP.compass_problem(t[good], y[good], W0, h0, F, incl, noise_raw=noise,
                              temp_c=None if temp is None else temp[good], **static)
    return prob, {}, None, "a sample far off the field sphere: a magnetic disturbance nearby or a glitch"


BUILDERS = {"accel-tabletop": _tabletop, "gyro-drift": _gyro, "ldv": _ldv, "accel-centrifuge": _centrifuge,
            "compass": _compass}


# ---------------------------------------------------------------- quality

def _quality(capture, diag, explain) -> list[dict]:
    out: list[dict] = []
    if capture.is_time_series and "t" in capture.columns:
        for q in Q.gaps(capture.columns["t"]):
            q["line"] = _line(capture, q.pop("row"))
            out.append(q)
    num = {c: v for c, v in capture.columns.items()
           if c in ("ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "vl1", "vl2", "vl3")}
    if capture.is_time_series:
        for q in Q.saturation(num):
            q["line"] = _line(capture, q.pop("row"))
            out.append(q)
    if capture.procedure == "accel-tabletop" and capture.is_time_series and "position" in capture.columns \
            and any(capture.columns["position"]):
        from solvers.stillness import detect_static_intervals

        a = np.column_stack([_col(capture, c) for c in ("ax", "ay", "az")])
        g = np.column_stack([_col(capture, c) for c in ("gx", "gy", "gz")]) \
            if all(c in capture.columns for c in ("gx", "gy", "gz")) else None
        try:
            st = detect_static_intervals(capture.columns["t"], a, g, nan_policy="omit")
            for q in Q.moved_positions(st.still_mask, capture.columns["position"]):
                q["line"] = _line(capture, q.pop("row"))
                q["line_stop"] = _line(capture, q.pop("row_stop") - 1)
                out.append(q)
        except (SolverError, ValueError):
            pass
    for q in Q.outliers(diag.studentized, diag.problem.row_labels, explain):
        out.append(q)
    if diag.residual_test.get("white") is False:
        rt = diag.residual_test
        out.append({"kind": "residuals_not_white", "test": rt["test"], "p_value": rt.get("p_value"),
                    "explanation": "the extended model's residuals are not noise-like: something remains that no "
                                   "candidate of the library explains (or the noise is correlated)"})
    return out


# ---------------------------------------------------------------- entry point

def analyse(capture) -> tuple[dict, object, dict]:
    """(diagnose.md dict, the engine's Diagnosis, drivers for plots)."""
    from station.calibrate import calibrate_capture, procedure_module

    procedure_module(capture.procedure, capture.path)  # unknown/missing procedure → InputError
    if capture.procedure not in BUILDERS:
        raise UnsupportedError(f"{capture.procedure}: no diagnosis for this procedure")
    base = None if capture.procedure == "gyro-drift" else calibrate_capture(capture)
    try:
        prob, drivers, _, explain = BUILDERS[capture.procedure](capture, base)
        diag = diagnose(prob)
    except SolverError as exc:
        raise UnsupportedError(f"{_where(capture)}: {capture.procedure}: diagnosis failed: {exc}") from None
    bp = diag.baseline
    out = {
        "procedure": capture.procedure,
        "baseline": {"model": diag.model, "params": bp.params, "residual_rms": diag.rms(bp),
                     "cv_rms": diag.baseline_cv_rms},
        "candidates": diag.candidates,
        "effects": diag.effects,
        "extended": {"model": diag.extended_model, "params": diag.extended.params, "residual_rms": diag.rms(diag.extended),
                     "cv_rms": diag.extended_cv_rms},
        "quality": _quality(capture, diag, explain),
        "verdict": diag.verdict,
    }
    return out, diag, drivers


def format_text(result: dict, diag, drivers: dict, plots: bool = True) -> str:
    from station.calibrate import jsonable

    r = jsonable(result)
    unit = diag.problem.unit
    L = [f"procedure   {r['procedure']}",
         f"baseline    {r['baseline']['model']}",
         f"            residual {r['baseline']['residual_rms']:.4g} {unit} RMS, held-out {r['baseline']['cv_rms']:.4g}",
         "candidates  (selected: ΔBIC < k ln n − F·χ²_k(1 − 0.05/m), F = {:g}, and a lower held-out RMS)".format(
             diag.problem.threshold)]
    for c in r["candidates"]:
        if c.get("resolvable") is False:
            L.append(f"  {c['name']:<24} unresolvable: {c['reason']}")
        else:
            mark = "  <- selected" if c["selected"] else ""
            L.append(f"  {c['name']:<24} ΔBIC {c['delta_bic']:+10.1f}   held-out RMS {c['cv_rms']:.4g}{mark}")
    for e in r["effects"]:
        L.append(f"effect      {e['name']}: held-out RMS {e['cv_rms_before']:.4g} → {e['cv_rms_after']:.4g} "
                 f"(gain {100 * e['gain']:.1f} %)")
        for c in e["confused_with"]:
            L.append(f"            cannot be told apart from {c['name']} (correlation {c['correlation']:+.3f})")
        for k, v in e["params"].items():
            L.append(f"            {k} = {np.round(np.asarray(v, dtype=float), 8).tolist()} ± "
                     f"{np.round(np.asarray(e['uncertainty'][k], dtype=float), 8).tolist()}")
    L.append(f"extended    {r['extended']['model']}")
    L.append(f"            residual {r['extended']['residual_rms']:.4g} {unit} RMS, held-out {r['extended']['cv_rms']:.4g}")
    rt = diag.residual_test
    if rt.get("p_value") is not None:
        L.append(f"            residual test {rt['test']}: p = {rt['p_value']:.3g} "
                 f"({'noise-like' if rt['white'] else 'NOT noise-like'})")
    for q in r["quality"]:
        where = q.get("position") or q.get("where") or q.get("column") or ""
        line = f" line {q['line']}" if q.get("line") else ""
        L.append(f"quality     {q['kind']} {where}{line}: {q['explanation']}")
    L.append("verdict     " + (", ".join(r["verdict"]) if r["verdict"] else "none"))
    L += _per_group(diag)
    if plots:
        L.append(_plots(diag, drivers))
    return "\n".join(L)


def _per_group(diag) -> list[str]:
    """Measured − simulated per CV group (position, mounting or time block), baseline and extended."""
    prob = diag.problem
    keep = np.ones(len(prob.sigma), bool) if prob.row_types is None else np.asarray(prob.row_types) == 0
    g = np.asarray(prob.groups)
    base, ext = -diag.baseline.residuals, -diag.extended.residuals
    uniq = list(dict.fromkeys(g[keep].tolist()))
    if not uniq or len(uniq) > 40:
        return []
    kind = {"accel-tabletop": "position", "accel-centrifuge": "mounting"}.get(prob.procedure, "time block")
    out = [f"measured − simulated per {kind} [{prob.unit}]: mean (RMS), baseline → extended"]
    for u in uniq:
        m = keep & (g == u)
        first = int(np.flatnonzero(m)[0])
        name = prob.row_labels[first].split(" |f|")[0] if prob.row_labels else str(u)
        hit = re.search(r"position ([^,) ]+)", name)
        if hit:
            name = f"position {hit.group(1)}"
        if kind == "time block" and "time [s]" in prob.drivers:
            tt = np.asarray(prob.drivers["time [s]"])[m]
            name = f"t {np.nanmin(tt):8.1f}–{np.nanmax(tt):8.1f} s"
        out.append(f"  {name:<28} {np.mean(base[m]):+.3e} ({np.sqrt(np.mean(base[m] ** 2)):.2e})  →  "
                   f"{np.mean(ext[m]):+.3e} ({np.sqrt(np.mean(ext[m] ** 2)):.2e})")
    return out


def _plots(diag, drivers) -> str:
    """Measured − simulated (the fitted baseline, primary rows) against each driver."""
    try:
        import plotext as plt
    except ImportError:  # pragma: no cover - plotext is a dependency
        return ""
    prob = diag.problem
    res = -np.asarray(diag.baseline.residuals, float)  # measured − simulated
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
        plt.plot_size(78, 13)
        plt.scatter(xs.tolist(), ys.tolist(), marker="dot")
        plt.title(f"measured − simulated baseline [{prob.unit}] against {name}")
        out.append(plt.build())
    return "\n".join(out)
