"""Numbers as text, once: the reports, the CLI tables and the TUI's readouts use these.

A value that is not a finite real number (None, NaN, ±inf, text) prints as ``missing``
(an em dash unless the caller's table uses another mark). Kept free of numpy: numpy's
scalars are ``numbers.Real`` and are formatted like floats.
"""

from __future__ import annotations

import math
import numbers

MISSING = "—"


def device_text(result: dict) -> str:
    """A result's device for its text report: ``(none)`` when the capture names none (as
    ``station inspect`` says), not Python's ``None``."""
    device = result.get("device")
    return "(none)" if device is None or device == "" else str(device)


def num(x, fmt: str = ".6g", missing: str = MISSING) -> str:
    """``format(x, fmt)`` when ``x`` is a finite real number (not a bool), else ``missing``."""
    if isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isfinite(x):
        return format(x, fmt)
    return missing


def sigma(x, fmt: str = ".2g", missing: str = MISSING) -> str:
    """A 1σ (or an expanded uncertainty U = k·σ) as text: ``missing`` for exactly 0 as well as
    for a non-finite one. A σ of 0 is a figure the fit did not estimate (an entry the gauge
    fixes, such as P1's M[1][0]; P5's condition number), which "± 0" would read as exact."""
    if isinstance(x, numbers.Real) and not isinstance(x, bool) and x == 0:
        return missing
    return num(x, fmt, missing)


def value_sigma(value, s) -> str:
    """``value ± s`` (6 and 2 significant digits); ``(not identifiable)`` for a non-finite σ,
    ``± —`` for a σ of 0 (not estimated: :func:`sigma`)."""
    if value is None:
        return MISSING
    if s is None or (isinstance(s, float) and not math.isfinite(s)):
        return f"{value:.6g} (not identifiable)" if isinstance(s, float) else f"{value:.6g}"
    return f"{value:.6g} ± {sigma(s)}"


def param_lines(name: str, value, sig, indent: str = "  ") -> list[str]:
    """A parameter (number, vector, matrix or named block) ± its 1σ as report lines; ``value``
    and its 1σ ``sig`` are plain JSON values (lists, dicts, floats, None)."""
    if isinstance(value, dict):
        out = [f"{indent}{name}:"]
        for k, v in value.items():
            out += param_lines(k, v, sig.get(k) if isinstance(sig, dict) else None, indent + "  ")
        return out
    if isinstance(value, list) and value and isinstance(value[0], list):
        out = [f"{indent}{name}:"]
        for i, row in enumerate(value):
            srow = sig[i] if isinstance(sig, list) else [None] * len(row)
            out.append(indent + "  [" + ", ".join(value_sigma(v, s) for v, s in zip(row, srow)) + "]")
        return out
    if isinstance(value, list):
        srow = sig if isinstance(sig, list) else [None] * len(value)
        return [f"{indent}{name}: [" + ", ".join(value_sigma(v, s) for v, s in zip(value, srow)) + "]"]
    if isinstance(value, (int, float)):
        return [f"{indent}{name}: {value_sigma(value, sig if isinstance(sig, (int, float)) else None)}"]
    return [f"{indent}{name}: {value}"]


def due_when(entry: dict) -> str:
    """When a ``Store.due`` entry falls due, as ``station due`` says it: ``never calibrated``,
    ``overdue by N d (due DATE)`` or ``due in N d (DATE)`` (the TUI says a date ahead alike)."""
    days = entry.get("days_left")
    if days is None:
        return "never calibrated"
    if days < 0:
        return f"overdue by {-days:.0f} d (due {entry['due'][:10]})"
    return f"due in {days:.0f} d ({entry['due'][:10]})"


def due_status(entry: dict) -> str:
    """The word for a devices table's status column (7 characters): ``overdue``, ``due`` (now),
    ``in N d`` (a date within the window asked for, not yet due), ``no cal``."""
    days = entry.get("days_left")
    if days is None:
        return "no cal"
    if days < 0:
        return "overdue"
    return "due" if round(days) == 0 else f"in {days:.0f} d"
