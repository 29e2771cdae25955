"""What the Results screen, ``calibrate --save`` and the report show, computed without a
screen: parameters with their units and change from the previous calibration (in sigma),
the tolerance and limit checks, the fit's own checks, the verdict, P1 residuals.

Tolerances are the device's (``db.store.Store.get_device(...)['tolerances']``): the
largest change of a parameter (or block, e.g. ``B``) from the value in use that is still
acceptable, in the parameter's units; ``residual_rms`` limits the fit's residual.
Limits (``...['limits']``) are absolute: ``{name or block: [low, high]}`` (either end
None), or ``[low, high, unit]`` where the stored unit depends on the capture
(:func:`limit_parts`). The previous calibration is the calibration in use: the last
*accepted* one (``Store.reference``); a rejected calibration is never compared against.

A result FAILS when a parameter leaves its tolerance or limits, the residual exceeds its
tolerance, or the fit fails its own checks (``fit_checks``). A failed result is saved only
by an explicit decision: rejected with a reason, or accepted as an override with a note
(``review_record``).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace

import numpy as np

from solvers.models import accel as accel_model


def flatten(obj, prefix: str = "") -> dict[str, float | None]:
    """Scalars by name (``B[0]``, ``M[1][2]``), the database's naming."""
    out: dict[str, float | None] = {}
    if isinstance(obj, dict):
        for k, v in obj.items():
            out.update(flatten(v, f"{prefix}.{k}" if prefix else str(k)))
    elif isinstance(obj, (list, tuple, np.ndarray)):
        for i, v in enumerate(obj):
            out.update(flatten(v, f"{prefix}[{i}]"))
    elif obj is None:
        out[prefix] = None
    elif isinstance(obj, (bool, str)):
        pass
    elif isinstance(obj, (int, float, np.floating, np.integer)):
        out[prefix] = float(obj)
    return out


def block_of(name: str) -> str:
    """The block a parameter name belongs to (``M[0][1]`` → ``M``): limits and tolerances
    may name a block or one of its elements."""
    return name.split("[", 1)[0]


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and math.isfinite(x)


@dataclass
class ParamRow:
    name: str
    value: float | None
    sigma: float | None
    previous: float | None = None
    change_sigma: float | None = None  # (value - previous) / sqrt(sigma² + sigma_prev²)
    tolerance: float | None = None
    ok: bool | None = None  # None: nothing to check against
    unit: str = ""
    limit: tuple | None = None  # (low, high), either may be None
    in_limits: bool | None = None
    limit_unread: str | None = None  # the stored limit's unit when it cannot be read in this result's


def param_rows(
    result: dict, previous: dict | None = None, tolerances: dict | None = None, limits: dict | None = None
) -> list[ParamRow]:
    """One row per scalar parameter; ``ok`` is False when it changed more than its
    tolerance from ``previous`` or left its absolute ``limits``."""
    limits = limits or {}
    values = flatten(result.get("params", {}))
    sigmas = flatten(result.get("uncertainty", {}))
    prev_v = flatten(previous.get("params", {})) if previous else {}
    prev_s = flatten(previous.get("uncertainty", {})) if previous else {}
    tolerances = tolerances or {}
    rows = []
    for name, v in values.items():
        row = ParamRow(name, v, sigmas.get(name))
        p = prev_v.get(name)
        if _finite(p) and _finite(v):
            row.previous = p
            s2 = sum(x * x for x in (row.sigma, prev_s.get(name)) if _finite(x))
            row.change_sigma = (v - p) / math.sqrt(s2) if s2 > 0 else None
        tol = tolerances.get(name, tolerances.get(block_of(name)))
        if tol is not None and _finite(float(tol)):
            row.tolerance = float(tol)
            if row.previous is not None:
                row.ok = abs(v - row.previous) <= row.tolerance
        row.unit = param_unit(result, name)
        lim = limits.get(name, limits.get(block_of(name)))
        if lim is not None:
            bounds = limit_in(result, name, lim)
            if bounds is None:  # a unit this result's cannot be converted to: not passed unread
                row.limit_unread = limit_parts(lim)[2]
                row.in_limits = row.ok = False
                rows.append(row)
                continue
            low, high = bounds
            row.limit = (low, high)
            if _finite(v):
                row.in_limits = (low is None or v >= low) and (high is None or v <= high)
            else:
                row.in_limits = False
            row.ok = row.in_limits if row.ok is None else (row.ok and row.in_limits)
        rows.append(row)
    return rows


def param_unit(result: dict, name: str) -> str:
    """The unit of one scalar parameter (``B[0]``, ``beam1.alpha_deg``), '' when dimensionless."""
    block = block_of(name)
    leaf = name.rsplit(".", 1)[-1]
    units = result.get("units") if isinstance(result.get("units"), dict) else {}
    if block in units:
        return str(units[block])
    if leaf.endswith("_deg") or leaf in ("pitch_deg", "roll_deg"):
        return "°"
    if leaf.endswith("_nT"):
        return "nT"
    if leaf.endswith("_mps"):
        return "m/s"
    # the procedure module's PARAM_UNITS: by block, or ".<leaf>" for a leaf of any block
    table = getattr(_procedure_module(result), "PARAM_UNITS", {})
    unit = table.get(block, table.get("." + leaf))
    return "" if unit is None else unit.format(mag_unit=_mag_unit(result))


RATIO = "ratio"  # the unit of a soft-iron limit typed before the device's first compass calibration


def limit_parts(lim) -> tuple[float | None, float | None, str | None]:
    """A stored limit as (low, high, unit): ``[low, high]`` is in the parameter's stored unit;
    ``[low, high, unit]`` says the unit its values are in (written where the stored unit
    depends on the capture: the compass's hard and soft iron, per its ``mag_unit``)."""
    low, high, *unit = lim
    return (
        (None if low is None else float(low)),
        (None if high is None else float(high)),
        (str(unit[0]) if unit else None),
    )


def _per_capture_template(result: dict, name: str) -> str | None:
    """The stored-unit template of ``name`` when it depends on the capture (``nT per {mag_unit}``)."""
    template = getattr(_procedure_module(result), "PARAM_UNITS", {}).get(block_of(name))
    return template if template and "{mag_unit}" in template else None


def limit_unit(result: dict, name: str, typed_as_shown: bool) -> str | None:
    """The unit a limit of ``name`` is stored with (:func:`limit_parts`), None where the stored
    unit is the procedure's own. ``result`` tells the capture's unit (a calibration of the
    device); with none, a limit typed in a unit shown the same for every capture (the soft
    iron's ratio: ``typed_as_shown``) is stored as :data:`RATIO`, anything else without a unit."""
    if _per_capture_template(result, name) is None:
        return None
    if result.get("mag_unit"):
        return param_unit(result, name)
    shown_alike = getattr(_procedure_module(result), "DISPLAY_UNITS", {}).get(block_of(name)) is not None
    return RATIO if typed_as_shown and shown_alike else None


def ratio_unit(result: dict, name: str) -> str:
    """How the screens show ``name`` where that is alike for every capture (the soft iron's
    ``{mag_unit}/{mag_unit}``), with the capture's unit, or the words ``mag_unit`` when no
    calibration tells it."""
    spec = getattr(_procedure_module(result), "DISPLAY_UNITS", {}).get(block_of(name))
    return "" if spec is None else spec[0].format(mag_unit=_mag_unit(result))


def limit_in(result: dict, name: str, lim) -> tuple[float | None, float | None] | None:
    """Stored limit ``lim`` of ``name`` as (low, high) in ``result``'s stored unit of it; None when
    the limit's unit cannot be converted to that (a raw unit, or a ratio against a raw unit).
    A limit stored without a unit is read as stored."""
    low, high, unit = limit_parts(lim)
    template = _per_capture_template(result, name)
    if unit is None or template is None or unit == param_unit(result, name):
        return low, high
    if unit == RATIO:
        disp = display_unit(result, name)
        return None if disp is None else tuple(None if x is None else x / disp[0] for x in (low, high))
    from solvers.units import MAG_UNITS, si_factor

    source = next((u for u in MAG_UNITS if template.format(mag_unit=u) == unit), None)
    f_source, f_here = MAG_UNITS.get(source), si_factor("mag", result.get("mag_unit"))
    if f_source is None or f_here is None:
        return None
    k = f_source / f_here if template.startswith("{mag_unit}") else f_here / f_source  # in it, or per it
    return tuple(None if x is None else x * k for x in (low, high))


def shown_limit(result: dict, name: str, lim) -> tuple[float | None, float | None, str]:
    """Stored limit ``lim`` of ``name`` as the screens show it: (low, high, unit) in the unit
    ``result`` (the calibration that tells the units, or a bare procedure) shows ``name`` in;
    a limit that cannot be read in that unit as stored, with its own unit."""
    low, high, unit = limit_parts(lim)
    bounds = limit_in(result, name, lim) if result.get("params") or unit is None else None
    if bounds is not None:
        low, high = (None if x is None else shown_value(result, name, x) for x in bounds)
        return low, high, shown_unit(result, name) if result else ""
    return low, high, ratio_unit(result, name) if unit == RATIO else (unit or "")


def _mag_unit(result: dict) -> str:
    """The magnetometer unit of ``result``'s capture; for a bare procedure (no calibration
    to tell it: a limit stored before the device's first compass calibration) the words
    ``mag_unit``, not a guess ("nT per raw" was shown for such a soft iron limit)."""
    if result.get("mag_unit"):
        return str(result["mag_unit"])
    return "raw" if result.get("params") else "mag_unit"


def display_unit(result: dict, name: str) -> tuple[float, str] | None:
    """How the screens show parameter (or ``residual_rms``) ``name`` when not in its stored
    unit: (factor, unit), shown = stored * factor; None: as stored. From the procedure
    module's ``DISPLAY_UNITS`` ({block: (unit, factor or factor(result))}), e.g. P4's drift
    in °/h; the stored result, exports and the database keep the stored unit."""
    table = getattr(_procedure_module(result), "DISPLAY_UNITS", {})
    spec = table.get(block_of(name))
    if spec is None:
        return None
    unit, factor = spec
    f = factor(result) if callable(factor) else factor
    if not (_finite(f) and f > 0):
        return None
    return float(f), unit.format(mag_unit=_mag_unit(result))


def shown_value(result: dict, name: str, x):
    """Stored value ``x`` of ``name`` in the unit the screens show (:func:`display_unit`)."""
    disp = display_unit(result, name)
    return x if disp is None else _scaled(x, disp[0])


def stored_value(result: dict, name: str, x):
    """A value of ``name`` typed in the unit the screens show, in its stored unit (the inverse
    of :func:`shown_value`: what a limit or tolerance entered on a screen is stored as)."""
    disp = display_unit(result, name)
    return x if disp is None or not _finite(x) else x / disp[0]


def shown_unit(result: dict, name: str) -> str:
    """The unit the screens show ``name`` in: its display unit, else its stored unit."""
    disp = display_unit(result, name)
    return disp[1] if disp is not None else param_unit(result, name)


def record_result(record: dict) -> dict:
    """A stored calibration (``Store.history`` or ``Store.reference`` row) as the result
    the unit functions read: its procedure, parameters and extra fields (``mag_unit``)."""
    return dict(
        record.get("extra") or {},
        procedure=record.get("procedure"),
        params=record.get("params") or {},
        uncertainty=record.get("uncertainty") or {},
        residual_rms=record.get("residual_rms"),
    )


def unit_context(name: str, results) -> dict:
    """The result that tells the unit of parameter ``name`` (``drift``, ``soft_iron[0][0]``):
    the first of ``results`` whose parameters hold it; else a bare result of the one
    procedure whose module names its block in ``PARAM_UNITS`` (a display factor that needs
    the result, e.g. the compass's per ``mag_unit``, then falls back to the stored unit);
    else {} (no unit known: as stored)."""
    block = block_of(name)
    for result in results:
        if result and (block in (result.get("params") or {}) or name in flatten(result.get("params") or {})):
            return result
    from station.procedures import registry

    owners = [p.name for p in registry.PROCEDURES if block in getattr(p.load(), "PARAM_UNITS", {})]
    return {"procedure": owners[0]} if len(owners) == 1 else {}


def typed_context(name: str, results) -> tuple[dict, str]:
    """The result whose units a person types a limit or tolerance of ``name`` in (as the
    screens show it), and that unit ('' when dimensionless or unknown): :func:`unit_context`;
    for ``residual_rms`` the one procedure of ``results`` (the device's calibrations).
    ValueError, one line, when that unit cannot be known: a residual with no calibration to
    tell its procedure or with procedures whose residual units differ; a display unit that
    needs the result (the compass's soft iron, per the capture's mag_unit) with none."""
    if name == "residual_rms":
        by_unit: dict[str, dict] = {}
        for result in results:
            if result and result.get("procedure"):
                by_unit.setdefault(shown_residual(result)[1], result)
        if not by_unit:
            raise ValueError(
                "residual_rms is in the unit of a procedure's residual (P4 °/h, P1 m/s^2, ...) "
                "and the device has no calibration yet to tell which"
            )
        if len(by_unit) > 1:
            raise ValueError(
                f"residual_rms has a different unit in each of the device's procedures ({', '.join(by_unit)})"
            )
        ((unit, ctx),) = by_unit.items()
        return ctx, unit
    ctx = unit_context(name, results)
    if not ctx:
        return {}, ""
    if not ctx.get("params"):  # a bare procedure: no result to tell a per-capture display factor
        spec = getattr(_procedure_module(ctx), "DISPLAY_UNITS", {}).get(block_of(name))
        if spec is not None and callable(spec[1]):
            unit = spec[0].format(mag_unit="mag_unit")
            raise ValueError(
                f"{block_of(name)} is shown as {unit}, stored per the capture's unit, "
                "and the device has no calibration yet to tell it"
            )
    return ctx, shown_unit(ctx, name)


def shown_rows(result: dict, rows: list[ParamRow]) -> list[ParamRow]:
    """``rows`` in the units the screens show (:func:`display_unit`); value, σ, the value in
    use and the tolerance scaled alike (Δ/σ and the checks are unchanged)."""
    out = []
    for row in rows:
        disp = display_unit(result, row.name)
        if disp is None:
            out.append(row)
            continue
        f, unit = disp
        lim = None if row.limit is None else tuple(None if x is None else x * f for x in row.limit)
        out.append(
            replace(
                row,
                value=_scaled(row.value, f),
                sigma=_scaled(row.sigma, f),
                previous=_scaled(row.previous, f),
                tolerance=_scaled(row.tolerance, f),
                unit=unit,
                limit=lim,
            )
        )
    return out


def _scaled(x, f: float):
    return x * f if _finite(x) else x


def shown_residual(result: dict) -> tuple[float | None, str]:
    """The residual RMS and its unit as the screens show them."""
    res = result.get("residual_rms")
    disp = display_unit(result, "residual_rms")
    if disp is None:
        return res, result_unit(result)
    return (res * disp[0] if _finite(res) else res), disp[1]


def residual_of(result: dict) -> str:
    """What the result's residual RMS is taken over, where its procedure says (P4: "per sample";
    its diagnosis fits block means and says so beside its own), else ""."""
    return getattr(_procedure_module(result), "RESIDUAL_OF", "")


def residual_table(capture, result: dict) -> tuple[tuple[str, ...], list[tuple[str, str, str]]]:
    """The Results screen's per-position (per-row) table: its headers and rows as text, in
    the unit and with the decimals of the summary's residual RMS (``shown_residual``), so the
    table and the summary read alike (P1: both m/s^2). ``((), [])`` for a procedure without
    one (its module's ``position_residuals`` and ``RESIDUAL_COLUMNS``)."""
    module = _procedure_module(result)
    rows = getattr(module, "position_residuals", lambda _c, _r: [])(capture, result)
    if not rows:
        return (), []
    name, norm, residual = getattr(module, "RESIDUAL_COLUMNS", ("position", "norm", "residual"))
    rms, unit = shown_residual(result)
    k = 1.0
    disp = display_unit(result, "residual_rms")
    if disp is not None:
        k = disp[0]
    # the RMS's three significant digits (as the summary shows it); at least 3 decimals for the norm
    scale = rms if _finite(rms) and rms > 0 else max((abs(r) for _n, _a, r in rows if _finite(r)), default=1.0)
    decimals = min(9, max(0, 2 - math.floor(math.log10(scale)))) if scale > 0 else 3
    out = [(str(n), _fixed(a * k, max(decimals, 3), ""), _fixed(r * k, decimals, "+")) for n, a, r in rows]
    return (name, f"{norm} {unit}", f"{residual} {unit}"), out


def _fixed(x, decimals: int, sign: str) -> str:
    return format(x, f"{sign}.{decimals}f") if _finite(x) else "—"


def _procedure_module(result: dict):
    """The result's procedure module (registry), None for a procedure the station lacks."""
    from station.procedures import registry

    entry = registry.get(result.get("procedure"))
    return entry.load() if entry is not None else None


def result_unit(result: dict) -> str:
    """The unit of the result's residual_rms."""
    units = result.get("units") if isinstance(result.get("units"), dict) else {}
    if units.get("residual_rms"):
        return str(units["residual_rms"]).split(" (")[0]
    from station.procedures import registry

    entry = registry.get(result.get("procedure"))
    return entry.result_unit if entry is not None else ""


def fit_checks(result: dict, chi2_limit: float = 100.0) -> list[str]:
    """The fit's own checks, failed ones as one line each ([] when it passes them).

    - non-finite parameters (of the procedure's ``CORE_PARAMS`` where it names them: the
      compass's IGRF reference is null without a place, which is a documented result, not a
      failed fit) or residual: the fit did not converge;
    - every parameter's σ at least its |value| (two or more): the data determined none;
    - a reduced χ² above ``chi2_limit`` (residual RMS more than √100 = 10 times the
      measured noise), only when the noise was measured rather than taken from the
      residuals themselves.
    """
    out = []
    values = flatten(result.get("params", {}))
    sigmas = flatten(result.get("uncertainty", {}))
    module = _procedure_module(result)
    core = getattr(module, "CORE_PARAMS", None)
    judged = [v for k, v in values.items() if core is None or re.split(r"[.\[]", k, maxsplit=1)[0] in core]
    if any(v is None for v in judged) or not (
        result.get("residual_rms") is None or _finite(result.get("residual_rms"))
    ):
        out.append("the fit returned non-finite values")
    pairs = [(v, sigmas[k]) for k, v in values.items() if _finite(v) and _finite(sigmas.get(k))]
    # A gyro drift indistinguishable from zero is a good gyro, not a failed fit.
    zero_is_a_result = getattr(module, "ZERO_IS_A_RESULT", False)
    if not zero_is_a_result and len(pairs) >= 2 and all(s >= abs(v) for v, s in pairs):
        out.append(
            f"every parameter's σ is larger than its value ({len(pairs)} of {len(pairs)}): "
            "the data determine none of them"
        )
    # Where the noise is taken from the residuals, χ² cannot see a misfit: a residual of
    # 5 % of g on an accelerometer means the model does not describe the data at all (a
    # working triad on a bench leaves milli-g; e.g. a centrifuge that never turned).
    res = result.get("residual_rms")
    bound = getattr(module, "RESIDUAL_LIMIT", None)
    if bound is not None and _finite(res) and res > bound:
        unit = result_unit({"procedure": result.get("procedure")})
        out.append(
            f"residual {res:.3g} {unit} RMS is above 5 % of g ({bound:.3g} {unit}): "
            "the model does not describe these data"
        )
    chi2 = result.get("reduced_chi2")
    noise = str(result.get("noise") or "")
    if _finite(chi2) and chi2 > chi2_limit and not noise.startswith("estimated"):
        out.append(
            f"residual {math.sqrt(chi2):.3g} times the measured noise (reduced χ² {chi2:.3g}): "
            "the model does not describe these data"
        )
    return out


@dataclass
class Assessment:
    """How a result fares: ``verdict`` pass | fail | no tolerance, and why."""

    verdict: str
    reasons: list[str]
    rows: list[ParamRow]
    checks: list[str]  # the fit's own failed checks (also in reasons)

    @property
    def failed(self) -> bool:
        return self.verdict == "fail"


def assess(result: dict, previous: dict | None = None, device: dict | None = None) -> Assessment:
    """Judge ``result`` against the device's tolerances and limits, the calibration in use
    (``previous``, an accepted calibration or None) and the fit's own checks."""
    device = device or {}
    tolerances = device.get("tolerances") or {}
    limits = device.get("limits") or {}
    rows = param_rows(result, previous, tolerances, limits)
    word, reasons = verdict(rows, result, tolerances)
    checks = fit_checks(result)
    if checks:
        word = "fail"
        reasons = reasons + checks
    return Assessment(word, reasons, rows, checks)


def review_record(assessment: Assessment, decision: str, note: str = "") -> dict:
    """What the database stores with the calibration (``calibrations.review``).

    decision: ``accepted`` (a result that did not fail), ``rejected`` (needs a reason
    when it failed: the note), or ``override`` (a failed result accepted; needs a note).
    """
    note = (note or "").strip()
    if decision == "accepted" and assessment.failed:
        raise ValueError("a failed result is accepted only as an override with a note")
    if decision in ("rejected", "override") and assessment.failed and not note:
        raise ValueError(f"{'rejecting' if decision == 'rejected' else 'overriding'} a failed result needs a note")
    return {"verdict": assessment.verdict, "reasons": list(assessment.reasons), "decision": decision, "note": note}


def verdict(rows: list[ParamRow], result: dict, tolerances: dict | None = None) -> tuple[str, list[str]]:
    """("pass" | "fail" | "no tolerance", reasons)."""
    tolerances = tolerances or {}
    reasons = []
    # judged on the stored values, said in the units the screens show (shown_rows)
    for r, s in zip(rows, shown_rows(result, rows)):
        u = f" {s.unit}" if s.unit and s.unit != "1" else ""
        if r.tolerance is not None and r.previous is not None and abs(r.value - r.previous) > r.tolerance:
            reasons.append(f"{s.name} changed {s.value - s.previous:+.3g}{u} (tolerance {s.tolerance:g}{u})")
        if r.limit_unread is not None:
            reasons.append(
                f"{s.name}: its limit is in {r.limit_unread}, which does not convert to this result's {r.unit or 'unit'}: "
                "set the limit again"
            )
        elif r.in_limits is False:
            lo, hi = s.limit
            span = f"{'-∞' if lo is None else format(lo, 'g')} … {'∞' if hi is None else format(hi, 'g')}"
            reasons.append(f"{s.name} = {_fmt(s.value)}{u} outside its limits {span}{u}")
    checked = any(r.ok is not None for r in rows)
    tol_res = tolerances.get("residual_rms")
    res = result.get("residual_rms")
    if tol_res is not None and _finite(res):
        checked = True
        if res > float(tol_res):
            shown, unit = shown_residual(result)
            u = f" {unit}" if unit else ""
            reasons.append(
                f"residual {shown:.3g}{u} above tolerance {shown_value(result, 'residual_rms', float(tol_res)):g}{u}"
            )
    if not checked:
        return "no tolerance", []
    return ("fail" if reasons else "pass"), reasons


def _fmt(x) -> str:
    return format(x, ".6g") if _finite(x) else "—"


def p1_residuals(capture, result: dict) -> list[tuple[str, float, float]]:
    """Per position: (name, |B + M V| [m/s²], |B + M V| - g [m/s²])."""
    try:
        B = np.asarray(result["params"]["B"], dtype=float)
        M = np.asarray(result["params"]["M"], dtype=float)
    except (KeyError, TypeError, ValueError):
        return []
    g = result.get("g_mps2")
    if not _finite(g):
        try:
            g = float(capture.meta.get("g_mps2"))
        except (TypeError, ValueError):
            g = math.nan
    rows = result.get("positions")
    if isinstance(rows, list) and rows and all(isinstance(p, dict) and "mean_raw" in p for p in rows):
        # the positions the fit used (a time series has one row per sample, not per position)
        names = [p.get("label") for p in rows]
        r = [p.get("residual_mps2") for p in rows]
        if _finite(g) and all(_finite(x) for x in r):
            # the fit's own residuals, which residual_rms and calibrate's per-position lines give
            # (the returned B, M carry the rotation's second-order debiasing, ~1e-5 of g)
            return [(str(n), float(g + x), float(x)) for n, x in zip(names, r)]
        V = np.array([p["mean_raw"] for p in rows], dtype=float)
    else:
        V = np.column_stack([capture.columns[c] for c in ("ax", "ay", "az")])
        names = capture.columns.get("position", np.array([str(i + 1) for i in range(len(V))], dtype=object))
    norms = np.linalg.norm(accel_model.p1_apply(V, B, M), axis=1)
    return [(str(n), float(a), float(a - g)) for n, a in zip(names, norms)]
