"""Results as plain JSON values, once (the calibrate and diagnose dicts, simulation truth,
what the database stores).

Pure Python on purpose (no numpy import): ``station due`` and ``station history`` start
without numpy; numpy's arrays and scalars are converted through their ``tolist()``.
"""

from __future__ import annotations

import math


def jsonable(obj, *, strict: bool = False):
    """Plain JSON values: dict keys → str, tuples → lists, numpy arrays and scalars → Python
    numbers and lists, NaN and ±inf → None (JSON has no NaN, and SQLite's JSON functions
    reject it). Any other object is returned as it is, or refused (``ValueError``) when
    ``strict``."""
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, float):
        f = float(obj)
        return f if math.isfinite(f) else None
    if isinstance(obj, int):
        return int(obj)
    if isinstance(obj, dict):
        return {str(k): jsonable(v, strict=strict) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v, strict=strict) for v in obj]
    tolist = getattr(obj, "tolist", None)  # numpy arrays and scalars (np.bool_ → bool)
    if tolist is not None:
        return jsonable(tolist(), strict=strict)
    if strict:
        raise ValueError(f"cannot store {type(obj).__name__} value {obj!r} as JSON")
    return obj
