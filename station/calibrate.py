"""`calibrate_capture`: a capture in, the calibrate.md result dict out.

Each procedure's logic lives in its module (``station/procedures/<stem>.py``, listed in
``station.procedures.registry``; its shape is ``station.procedures.contract.ProcedureModule``).
This module only dispatches.
"""
from __future__ import annotations

import json
import math

import numpy as np

from solvers.errors import SolverError
from station.errors import InputError, UnsupportedError
from station.procedures import registry
from station.guard import check_extremes, check_result, printed_warnings, quiet_stdout


def procedure_module(procedure: str | None, path=None):
    """The module of ``procedure`` (InputError naming ``path`` when there is none)."""
    if not procedure:
        raise InputError(path, None, "metadata has no 'procedure': say which procedure this capture is for")
    entry = registry.get(procedure)
    if entry is None:
        raise InputError(path, None, f"unknown procedure {procedure!r}")
    try:
        return entry.load()
    except ModuleNotFoundError as exc:
        if exc.name == entry.module:
            raise UnsupportedError(f"{procedure}: this station cannot calibrate it yet") from None
        raise


def calibrate_capture(capture, method: str | None = None, *, prepared=None) -> dict:
    """The calibrate.md result for ``capture`` (a :class:`station.capture.Capture`);
    ``prepared``: the module's ``prepare(capture)``, when the caller has it already.

    Guarded (``station.guard``): numbers no instrument produces and a time axis that does
    not advance are refused before the fit; anything a dependency prints meanwhile becomes
    a warning of the result (never stdout); a core parameter the data cannot determine
    (non-finite) is a refusal, not a null.
    """
    module = procedure_module(capture.procedure, capture.path)
    check_extremes(capture)
    kwargs = {} if prepared is None else {"prepared": prepared}
    with quiet_stdout() as printed:
        result = guarded(capture, module.calibrate, capture, method=method, **kwargs)
    if printed:
        result.setdefault("warnings", []).extend(printed_warnings(printed))
    check_result(capture, result)
    return result


def guarded(capture, fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` with numerical breakdowns as one-line refusals naming the capture."""
    where = f"{capture.path or 'capture'}: {capture.procedure}"
    try:
        with np.errstate(all="ignore"):
            return fn(*args, **kwargs)
    except np.linalg.LinAlgError as exc:  # NaN/inf reached a decomposition: degenerate or absurd data
        raise UnsupportedError(f"{where}: the fit failed numerically ({exc}); "
                               "check the data: constant, all zero or absurdly large values?") from None
    except SolverError as exc:
        raise UnsupportedError(f"{where}: {exc}") from None
    except (OverflowError, FloatingPointError) as exc:
        raise UnsupportedError(f"{where}: a number overflowed in the fit ({exc}): the data hold values "
                               "far beyond the sensor's range") from None


def jsonable(obj):
    """Arrays → lists, numpy scalars → floats, NaN/inf → None (JSON has no NaN)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        f = float(obj)
        return f if math.isfinite(f) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def to_json(result: dict) -> str:
    return json.dumps(jsonable(result), indent=2)


def format_value(v, s) -> str:
    if v is None:
        return "—"
    if s is None or (isinstance(s, float) and not math.isfinite(s)):
        return f"{v:.6g} (not identifiable)" if isinstance(s, float) else f"{v:.6g}"
    return f"{v:.6g} ± {s:.2g}"


def format_text(result: dict) -> str:
    """A plain report: procedure, device, each parameter ± 1σ, residual, warnings."""
    module = None
    try:
        module = procedure_module(result.get("procedure"))
    except Exception:
        module = None
    if module is not None and hasattr(module, "format_text"):
        return module.format_text(result)
    lines = [f"procedure  {result.get('procedure')}", f"device     {result.get('device')}",
             f"model      {result.get('model')}"]
    params, unc = result.get("params", {}), result.get("uncertainty", {})
    for name, value in params.items():
        sig = unc.get(name) if isinstance(unc, dict) else None
        lines += _format_param(name, value, sig)
    lines.append(f"residual   {result.get('residual_rms'):.4g} RMS" if isinstance(result.get("residual_rms"), (int, float)) else "residual   —")
    if "n_positions" in result:
        lines.append(f"positions  {result['n_positions']}")
    for w in result.get("warnings", []):
        lines.append(f"warning    {w}")
    return "\n".join(lines)


def _format_param(name, value, sig, indent="  ") -> list[str]:
    value = jsonable(value)
    sig = jsonable(sig)
    if isinstance(value, dict):
        out = [f"{indent}{name}:"]
        for k, v in value.items():
            out += _format_param(k, v, sig.get(k) if isinstance(sig, dict) else None, indent + "  ")
        return out
    if isinstance(value, list) and value and isinstance(value[0], list):
        out = [f"{indent}{name}:"]
        for i, row in enumerate(value):
            srow = sig[i] if isinstance(sig, list) else [None] * len(row)
            out.append(indent + "  [" + ", ".join(format_value(v, s) for v, s in zip(row, srow)) + "]")
        return out
    if isinstance(value, list):
        srow = sig if isinstance(sig, list) else [None] * len(value)
        return [f"{indent}{name}: [" + ", ".join(format_value(v, s) for v, s in zip(value, srow)) + "]"]
    if isinstance(value, (int, float)):
        return [f"{indent}{name}: {format_value(value, sig if isinstance(sig, (int, float)) else None)}"]
    return [f"{indent}{name}: {value}"]
