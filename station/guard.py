"""Guards between hostile or extreme input and the numerics.

- :func:`check_extremes`: a capture whose numbers no instrument can produce (beyond the
  column's bound, ``station.capture.column_limit``: a plausibility bound per sensor kind and
  unit, else ``MAX_ABS``, where squares and sums of squares start to overflow float64) or
  whose time axis does not advance is refused before any fit sees it, naming the
  file, the line and the column.
- :func:`quiet_stdout`: text that a dependency prints while the numerics run (LAPACK's
  ``** On entry to DLASCL ...`` from C, a Python ``print`` in a library) is caught at the
  file-descriptor level and handed back as lines, so ``--json`` stdout holds nothing but
  the JSON document and the lines can become the result's ``warnings``.
- :func:`check_result`: a result whose parameters came out non-finite is refused with the
  parameter's name instead of being returned with nulls.
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import math
import os
import sys
import tempfile
import threading

import numpy as np

from station.capture import MAX_ABS, column_limit  # noqa: F401 - MAX_ABS: the generic bound, here as before
from station.errors import InputError, UnsupportedError

_MAX_CAPTURED_BYTES = 1 << 16
_LOCK = threading.RLock()  # process-wide fd 1; nested blocks (same thread) are fine


def _data_line(capture, row: int) -> int | None:
    """The file line of data row ``row`` (0-based), when the capture came from a file."""
    if capture.header_line is None:
        return None
    return capture.header_line + 1 + int(row)


def check_extremes(capture, columns: bool = True) -> None:
    """Refuse numbers beyond the column's bound (``column_limit``) and a time axis that does not advance.

    InputError ``file:line: column 'ax': 1e+200 is beyond ...``; the first offending row
    in file order is named. ``columns``: also :func:`check_columns` (the procedure's measured
    columns; False for a command that reads whichever sensors are there, such as ``noise``).
    """
    first: tuple[int, str, float, str] | None = None
    for name, col in capture.columns.items():
        arr = np.asarray(col)
        if arr.dtype.kind != "f" or arr.size == 0:
            continue
        bound, reason = column_limit(name, capture.meta)
        with np.errstate(invalid="ignore"):
            bad = np.abs(arr) > bound
        bad |= np.isinf(arr)
        if bad.any():
            k = int(np.argmax(bad))
            if first is None or k < first[0]:
                first = (k, name, float(arr[k]), reason)
    if first is not None:
        k, name, value, reason = first
        raise InputError(capture.path, _data_line(capture, k), f"column '{name}': {value:g} is beyond {reason}")
    t = capture.columns.get("t")
    if t is not None and len(t) > 1:
        t = np.asarray(t, dtype=float)
        if not t[-1] > t[0]:
            raise InputError(
                capture.path,
                _data_line(capture, 0),
                f"column 't': the time axis does not advance ({len(t)} rows, all at t = {t[0]:g} s)",
            )
        steps = np.diff(t)
        positive = steps[steps > 0]
        if positive.size and not np.isfinite(positive.min() / max(abs(t[0]), abs(t[-1]))):
            raise InputError(capture.path, _data_line(capture, 0), "column 't': the time axis cannot be resolved")
    if columns:
        check_columns(capture)


def _procedure_module(capture):
    """The capture's procedure module (registry), None for a procedure the station lacks."""
    from station.procedures import registry

    entry = registry.get(capture.procedure)
    return entry.load() if entry is not None else None


def check_columns(capture) -> None:
    """Refuse a measured column that holds no value at all, and a column that must change but
    never does (an LDV beam).

    An all-empty column (a sensor that gave nothing) and a beam reading one value throughout
    (a dead or saturated beam: its angles and scale factor have nothing to come from) cannot
    support the procedure; the refusal names the column instead of returning nulls. Which
    columns: the procedure module's ``MEASURED`` and ``DEAD_IF_CONSTANT``.
    """
    module = _procedure_module(capture)
    dead_if_constant = getattr(module, "DEAD_IF_CONSTANT", ())
    for name in getattr(module, "MEASURED", ()):
        col = capture.columns.get(name)
        if col is None or len(col) == 0:
            continue
        arr = np.asarray(col, dtype=float)
        finite = arr[np.isfinite(arr)]
        if finite.size == 0:
            raise InputError(
                capture.path,
                capture.header_line,
                f"column '{name}' is empty in every row: the sensor gave no data for it",
            )
        if name in dead_if_constant and len(arr) > 1 and finite.min() == finite.max():
            says = module.DEAD_IF_CONSTANT_SAYS.format(name=name, value=finite[0] + 0.0)
            raise UnsupportedError(f"{capture.path or 'capture'}: {capture.procedure}: {says}")


def check_result(capture, result: dict) -> None:
    """Refuse a result whose core parameters (the procedure module's ``CORE_PARAMS``) are not
    all finite numbers: a fit the data cannot carry is a refusal naming the parameter, not a
    result with nulls. A result whose every uncertainty is null is refused too.
    """
    core = getattr(_procedure_module(capture), "CORE_PARAMS", None)

    def walk(value, name):
        if isinstance(value, dict):
            for k, v in value.items():
                yield from walk(v, f"{name}.{k}" if name else str(k))
        elif isinstance(value, (list, tuple, np.ndarray)):
            for i, v in enumerate(value.tolist() if isinstance(value, np.ndarray) else value):
                yield from walk(v, f"{name}[{i}]")
        else:
            yield name, value

    def missing(value) -> bool:
        return value is None or (isinstance(value, (float, np.floating)) and not math.isfinite(float(value)))

    sigmas = [v for _, v in walk(result.get("uncertainty") or {}, "") if not isinstance(v, (str, bool))]
    if sigmas and all(missing(v) for v in sigmas):
        raise UnsupportedError(
            f"{capture.path or 'capture'}: {capture.procedure}: no parameter's uncertainty can be "
            "computed from these data: refused rather than reported without one"
        )
    for name, value in walk(result.get("params") or {}, ""):
        if core is not None and name.split("[")[0].split(".")[0] not in core:
            continue
        if missing(value):
            raise UnsupportedError(
                f"{capture.path or 'capture'}: {capture.procedure}: the data cannot determine "
                f"'{name}' (the fit gives no finite value): refused rather than reported as null"
            )


def _libc_fflush() -> None:
    try:
        ctypes.CDLL(None).fflush(None)
    except Exception:  # noqa: BLE001 - no libc (exotic platform): Python's own flush is all we can do
        pass


@contextlib.contextmanager
def quiet_stdout():
    """Catch whatever is written to stdout (fd 1 and ``sys.stdout``) inside the block.

    Yields a list that, after the block, holds the caught text as stripped, non-empty
    lines (at most 64 KiB kept). One block at a time per process (a lock): the fd is
    process-wide. Where fd 1 cannot be redirected (closed, or no fileno), only
    ``sys.stdout`` is.
    """
    lines: list[str] = []
    with _LOCK:
        try:
            sys.stdout.flush()
        except (OSError, ValueError, AttributeError):
            pass
        _libc_fflush()
        saved = None
        sink = tempfile.TemporaryFile()
        try:
            try:
                saved = os.dup(1)
                os.dup2(sink.fileno(), 1)
            except OSError:
                saved = None
            buffer = io.StringIO()
            with contextlib.redirect_stdout(buffer):
                try:
                    yield lines
                finally:
                    _libc_fflush()
        finally:
            if saved is not None:
                os.dup2(saved, 1)
                os.close(saved)
            sink.seek(0)
            raw = sink.read(_MAX_CAPTURED_BYTES)
            sink.close()
            text = raw.decode("utf-8", "replace") + buffer.getvalue()[:_MAX_CAPTURED_BYTES]
            lines.extend(s.strip() for s in text.splitlines() if s.strip())


def printed_warnings(lines: list[str], limit: int = 5) -> list[str]:
    """Caught dependency output as result warnings (distinct lines, at most ``limit``)."""
    distinct = list(dict.fromkeys(lines))
    out = [f"a library printed: {line[:200]}" for line in distinct[:limit]]
    if len(distinct) > limit:
        out.append(f"a library printed {len(distinct) - limit} more distinct lines")
    return out
