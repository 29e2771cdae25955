"""`calibrate_capture`: a capture in, the calibrate.md result dict out.

Each procedure's logic lives in its module (``station/procedures/<stem>.py``, listed in
``station.procedures.registry``; its shape is ``station.procedures.contract.ProcedureModule``).
This module only dispatches.
"""

from __future__ import annotations

import json

import numpy as np

from solvers.errors import SolverError
from solvers.jsonable import jsonable
from station.errors import InputError, UnsupportedError
from station.formatting import MISSING, device_text, num, param_lines
from station.guard import check_extremes, check_result, printed_warnings, quiet_stdout
from station.procedures import registry


def procedure_module(procedure: str | None, path=None):
    """The module of ``procedure`` (InputError naming ``path`` when there is none)."""
    if not procedure:
        raise InputError(
            path,
            None,
            "metadata has no 'procedure': say which procedure this capture is for, a line "
            f"'# procedure: P' with P one of {', '.join(registry.names())} "
            "(station record --procedure P writes it)",
        )
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
        raise UnsupportedError(
            f"{where}: the fit failed numerically ({exc}); check the data: constant, all zero or absurdly large values?"
        ) from None
    except SolverError as exc:
        raise UnsupportedError(f"{where}: {exc}", alternative=exc.alternative) from None
    except (OverflowError, FloatingPointError) as exc:
        raise UnsupportedError(
            f"{where}: a number overflowed in the fit ({exc}): the data hold values far beyond the sensor's range"
        ) from None


def to_json(result: dict) -> str:
    return json.dumps(jsonable(result), indent=2)


def format_text(result: dict) -> str:
    """A plain report: procedure, device, each parameter ± 1σ, residual, warnings."""
    module = None
    try:
        module = procedure_module(result.get("procedure"))
    except Exception:
        module = None
    if module is not None and hasattr(module, "format_text"):
        return module.format_text(result)
    lines = [
        f"procedure  {result.get('procedure')}",
        f"device     {device_text(result)}",
        f"model      {result.get('model')}",
    ]
    params, unc = result.get("params", {}), result.get("uncertainty", {})
    for name, value in params.items():
        sig = unc.get(name) if isinstance(unc, dict) else None
        lines += param_lines(name, jsonable(value), jsonable(sig))
    rms = num(result.get("residual_rms"), ".4g")
    lines.append(f"residual   {rms} RMS" if rms != MISSING else f"residual   {MISSING}")
    if "n_positions" in result:
        lines.append(f"positions  {result['n_positions']}")
    for w in result.get("warnings", []):
        lines.append(f"warning    {w}")
    return "\n".join(lines)
