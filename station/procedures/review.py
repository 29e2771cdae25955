"""What the Results screen shows, computed without a screen: parameters with their
change from the previous calibration (in sigma), tolerance checks, P1 residuals.

Tolerances are the device's (``db.store.Store.get_device(...)['tolerances']``): the
largest change of a parameter (or block, e.g. ``B``) from the value in use that is still
acceptable, in the parameter's units; ``residual_rms`` limits the fit's residual.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

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


def _block(name: str) -> str:
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


def param_rows(result: dict, previous: dict | None = None, tolerances: dict | None = None) -> list[ParamRow]:
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
        tol = tolerances.get(name, tolerances.get(_block(name)))
        if tol is not None and _finite(float(tol)):
            row.tolerance = float(tol)
            if row.previous is not None:
                row.ok = abs(v - row.previous) <= row.tolerance
        rows.append(row)
    return rows


def verdict(rows: list[ParamRow], result: dict, tolerances: dict | None = None) -> tuple[str, list[str]]:
    """("pass" | "fail" | "no tolerance", reasons)."""
    tolerances = tolerances or {}
    reasons = [f"{r.name} changed {r.value - r.previous:+.3g} (tolerance {r.tolerance:g})" for r in rows if r.ok is False]
    checked = any(r.ok is not None for r in rows)
    tol_res = tolerances.get("residual_rms")
    res = result.get("residual_rms")
    if tol_res is not None and _finite(res):
        checked = True
        if res > float(tol_res):
            reasons.append(f"residual {res:.3g} above tolerance {float(tol_res):g}")
    if not checked:
        return "no tolerance", []
    return ("fail" if reasons else "pass"), reasons


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
        V = np.array([p["mean_raw"] for p in rows], dtype=float)
        names = [p.get("label") for p in rows]
    else:
        V = np.column_stack([capture.columns[c] for c in ("ax", "ay", "az")])
        names = capture.columns.get("position", np.array([str(i + 1) for i in range(len(V))], dtype=object))
    norms = np.linalg.norm(accel_model.p1_apply(V, B, M), axis=1)
    return [(str(n), float(a), float(a - g)) for n, a in zip(names, norms)]
