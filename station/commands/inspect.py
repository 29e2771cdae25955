"""`station inspect FILE [--json]`: validate a capture file and summarise it."""

from __future__ import annotations

import argparse
import json
import math

from station.textsafe import safe


def register(sub: argparse._SubParsersAction) -> None:
    from station.importers.options import add_arguments

    p = sub.add_parser(
        "inspect",
        help="validate a capture file and print a summary",
        description="Read a capture file with every check the station applies and print "
        "its procedure, device, rows, duration, rate, columns (with units) and metadata. "
        "Bad input: one line 'file:line: what is wrong' and exit status 2.",
    )
    p.add_argument("file", help="capture file (station-capture CSV)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    add_arguments(p)  # a log or EuRoC file: the capture `station import` would write
    p.set_defaults(func=run)


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def summary(capture) -> dict:
    """The summary `inspect` prints, as a JSON-ready dict (None where not applicable)."""
    import numpy as np

    out: dict = {
        "file": capture.path,
        "procedure": capture.procedure,
        "device": capture.meta.get("device") or None,
        "kind": "time series" if capture.is_time_series else "table of averages",
        "rows": capture.n_rows,
        "t_start_s": None,
        "t_end_s": None,
        "duration_s": None,
        "rate_hz": None,
        "median_step_s": None,
        "sample_rate_hz": capture.float_meta("sample_rate_hz"),
        "positions": None,
    }
    if capture.is_time_series:
        t = capture.columns["t"]
        out.update(t_start_s=float(t[0]), t_end_s=float(t[-1]), duration_s=float(t[-1] - t[0]))
        if len(t) > 1:  # rate = intervals per second over the whole record (robust to rounded t)
            out["median_step_s"] = float(np.median(np.diff(t)))
            out["rate_hz"] = (len(t) - 1) / out["duration_s"] if out["duration_s"] > 0 else None
    if "position" in capture.columns:
        labels = [p for p in capture.columns["position"].tolist() if p]
        out["positions"] = len(dict.fromkeys(labels))
    columns = []
    for name, arr in capture.columns.items():
        entry = {"name": name, "unit": capture.unit(name)}
        if arr.dtype == object:
            entry["missing"] = int(sum(1 for v in arr.tolist() if not v))
        else:
            good = arr[~np.isnan(arr)]
            entry.update(
                missing=int(len(arr) - len(good)),
                min=_num(good.min()) if len(good) else None,
                max=_num(good.max()) if len(good) else None,
                mean=_num(good.mean()) if len(good) else None,
            )
        columns.append(entry)
    out["columns"] = columns
    out["metadata"] = dict(capture.meta)
    out["warnings"] = rate_warnings(capture)
    return out


def rate_warnings(capture) -> list[str]:
    """A stated ``sample_rate_hz`` that the ``t`` column contradicts: an InputError where the
    capture's own procedure would refuse it (its module names a ``RATE_CONSEQUENCE``: what scales
    with the rate, or answers ``rate_consequence(capture)``), else a warning naming what refuses
    it (P1 with labelled positions and gyro columns: its gyro block)."""
    from station.errors import InputError
    from station.procedures import noise, registry

    entry = registry.get(capture.procedure)
    module = entry.load() if entry is not None else None
    own = getattr(module, "RATE_CONSEQUENCE", None)
    if own is None and hasattr(module, "rate_consequence"):  # P1: only where positions come from t
        own = module.rate_consequence(capture)
    why = f"`station noise` refuses it: {noise.RATE_CONSEQUENCE}"
    note = module.rate_note(capture) if hasattr(module, "rate_note") else None  # P1: its gyro block
    if note:
        why = f"{note}; {why}"
    try:
        capture.series_rate_hz(own or why)
    except InputError as exc:
        if own:
            raise
        return [f"line {exc.line}: {exc.message}" if exc.line else exc.message]
    return []


def _g(x: float | None, digits: int = 6) -> str:
    return "–" if x is None else f"{x:.{digits}g}"


def format_text(s: dict) -> str:
    lines = [
        f"file:       {safe(s['file'])}",
        f"procedure:  {s['procedure'] or '(none: commands that need one will refuse it)'}",
        f"device:     {s['device'] or '(none)'}",
        f"kind:       {s['kind']}",
        f"rows:       {s['rows']}",
    ]
    if s["duration_s"] is not None:
        lines.append(f"duration:   {_g(s['duration_s'])} s (t from {_g(s['t_start_s'])} to {_g(s['t_end_s'])} s)")
        rate = (
            f"{_g(s['rate_hz'])} Hz (rows per second over the duration; median step {_g(s['median_step_s'])} s)"
            if s["rate_hz"]
            else "–"
        )
        if s["sample_rate_hz"] is not None:
            rate += f"; metadata says {_g(s['sample_rate_hz'])} Hz"
        lines.append(f"rate:       {rate}")
    if s["positions"] is not None:
        lines.append(f"positions:  {s['positions']} distinct labels")
    lines.append("columns:")
    width = max(len(c["name"]) for c in s["columns"])
    uwidth = max(len(c["unit"] or "?") for c in s["columns"])
    for c in s["columns"]:
        text = f"  {c['name']:<{width}}  {c['unit'] or '?':<{uwidth}}"
        if "min" in c:
            text += f"  min {_g(c['min']):>11}  max {_g(c['max']):>11}  mean {_g(c['mean']):>11}"
        if c["missing"]:
            text += f"  missing {c['missing']}"
        lines.append(text.rstrip())
    lines.append("metadata:")
    lines.extend(f"  {k}: {v}" for k, v in s["metadata"].items())
    lines.extend(f"warning:    {safe(w)}" for w in s["warnings"])
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from station.guard import check_extremes
    from station.importers.load import load_for_command

    capture = load_for_command(args)
    check_extremes(capture)  # "every check the station applies": what calibrate and diagnose refuse
    s = summary(capture)
    print(json.dumps(s, indent=2, ensure_ascii=False) if args.json else format_text(s))
    return 0
