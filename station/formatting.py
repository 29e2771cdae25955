"""Numbers as text, once: the reports, the CLI tables and the TUI's readouts use these.

A value that is not a finite real number (None, NaN, ±inf, text) prints as ``missing``
(an em dash unless the caller's table uses another mark). Kept free of numpy: numpy's
scalars are ``numbers.Real`` and are formatted like floats.
"""

from __future__ import annotations

import math
import numbers

MISSING = "—"


def num(x, fmt: str = ".6g", missing: str = MISSING) -> str:
    """``format(x, fmt)`` when ``x`` is a finite real number (not a bool), else ``missing``."""
    if isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isfinite(x):
        return format(x, fmt)
    return missing


def value_sigma(value, sigma) -> str:
    """``value ± sigma`` (6 and 2 significant digits); ``(not identifiable)`` for a non-finite σ."""
    if value is None:
        return MISSING
    if sigma is None or (isinstance(sigma, float) and not math.isfinite(sigma)):
        return f"{value:.6g} (not identifiable)" if isinstance(sigma, float) else f"{value:.6g}"
    return f"{value:.6g} ± {sigma:.2g}"


def param_lines(name: str, value, sigma, indent: str = "  ") -> list[str]:
    """A parameter (number, vector, matrix or named block) ± its 1σ as report lines; ``value``
    and ``sigma`` are plain JSON values (lists, dicts, floats, None)."""
    if isinstance(value, dict):
        out = [f"{indent}{name}:"]
        for k, v in value.items():
            out += param_lines(k, v, sigma.get(k) if isinstance(sigma, dict) else None, indent + "  ")
        return out
    if isinstance(value, list) and value and isinstance(value[0], list):
        out = [f"{indent}{name}:"]
        for i, row in enumerate(value):
            srow = sigma[i] if isinstance(sigma, list) else [None] * len(row)
            out.append(indent + "  [" + ", ".join(value_sigma(v, s) for v, s in zip(row, srow)) + "]")
        return out
    if isinstance(value, list):
        srow = sigma if isinstance(sigma, list) else [None] * len(value)
        return [f"{indent}{name}: [" + ", ".join(value_sigma(v, s) for v, s in zip(value, srow)) + "]"]
    if isinstance(value, (int, float)):
        return [f"{indent}{name}: {value_sigma(value, sigma if isinstance(sigma, (int, float)) else None)}"]
    return [f"{indent}{name}: {value}"]
