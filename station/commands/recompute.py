"""`station recompute CALIBRATION_ID`: re-run a stored capture with today's code, show what moved."""

from __future__ import annotations

import argparse
import json
import sys

from station.commands._dbutil import aligned, fmt_num, open_store, print_json, record_id
from station.errors import UnsupportedError
from station.formatting import sigma
from station.textsafe import safe


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "recompute", help="re-run a stored calibration's capture with today's models and show the difference"
    )
    p.add_argument("calibration_id", metavar="CALIBRATION_ID", type=record_id("calibration"))
    p.add_argument("--json", action="store_true", help="a JSON object: stored, recomputed, per-parameter differences")
    p.set_defaults(func=run)


def _calibrator():
    try:
        from station import calibrate
    except ImportError as exc:
        raise UnsupportedError(f"recompute: the calibrators are not available in this build ({exc})") from None
    fn = getattr(calibrate, "calibrate_capture", None)
    if fn is None:
        raise UnsupportedError("recompute: station.calibrate.calibrate_capture is not available in this build")
    return fn


def _capture(Capture, meta: dict, columns: dict, path: str):
    """A Capture from stored meta/columns, with line numbers as `write_capture` would lay the file out
    (one metadata line per key, then the header), so messages that cite lines match the export."""
    import dataclasses

    names = {f.name for f in dataclasses.fields(Capture)}
    extra = {}
    if "meta_lines" in names:
        extra["meta_lines"] = {key: i + 1 for i, key in enumerate(meta)}
    if "header_line" in names:
        extra["header_line"] = len(meta) + 1
    return Capture(meta=meta, columns=columns, path=path, **extra)


def differences(stored: dict, new: dict) -> list[dict]:
    """Per scalar parameter: stored value and sigma, recomputed value and sigma, delta, delta/stored sigma."""
    from db.params import clean_json, flatten

    old_v, old_s = flatten(stored["params"]), flatten(stored["uncertainty"])
    new_v, new_s = flatten(clean_json(new.get("params") or {})), flatten(clean_json(new.get("uncertainty") or {}))
    rows = []
    for name in list(old_v) + [n for n in new_v if n not in old_v]:
        a, b = old_v.get(name), new_v.get(name)
        delta = None if a is None or b is None else b - a
        sigma = old_s.get(name)
        z = None
        if delta is not None and sigma is not None and sigma > 0:
            z = delta / sigma
        rows.append(
            {
                "param": name,
                "stored": a,
                "stored_sigma": sigma,
                "recomputed": b,
                "recomputed_sigma": new_s.get(name),
                "delta": delta,
                "delta_in_sigma": z,
            }
        )
    return rows


def run(args: argparse.Namespace) -> int:
    calibrate_capture = _calibrator()
    from station.capture import Capture
    from station.cli import db_path

    with open_store(args) as store:
        cal = store.calibration(args.calibration_id)
        if cal["capture_id"] is None:
            raise UnsupportedError(f"calibration {cal['id']} was stored without its capture: nothing to recompute")
        meta, columns = store.load_capture(cal["capture_id"])
    capture = _capture(Capture, meta, columns, f"{db_path(args)}#capture={cal['capture_id']}")
    from solvers.errors import SolverError

    try:
        new = calibrate_capture(capture)
    except SolverError as exc:
        raise UnsupportedError(f"recompute of calibration {cal['id']}: {exc}") from None
    rows = differences(cal, new)
    if args.json:
        from db.params import clean_json

        print_json(
            {"calibration_id": cal["id"], "stored": cal["result"], "recomputed": clean_json(new), "differences": rows}
        )
        return 0
    worst = max((abs(r["delta_in_sigma"]) for r in rows if r["delta_in_sigma"] is not None), default=None)
    out = [
        f"calibration #{cal['id']} of device {safe(cal['device_id'])} ({cal['procedure']}, {cal['time']}), "
        f"stored by software {cal['software_version'] or '-'}, recomputed now",
    ]
    header = ("PARAM", "STORED", "±SIGMA", "RECOMPUTED", "DELTA", "DELTA/SIGMA")
    table = [header] + [
        (
            r["param"],
            fmt_num(r["stored"]),
            sigma(r["stored_sigma"], ".2g", "-"),
            fmt_num(r["recomputed"]),
            fmt_num(r["delta"], 3),
            "-" if r["delta_in_sigma"] is None else f"{r['delta_in_sigma']:+.2f}",
        )
        for r in rows
    ]
    out += aligned(table)
    if worst is not None:
        out.append(f"largest change: {worst:.2f} sigma" + (" (within 1 sigma)" if worst <= 1 else ""))
    old_w, new_w = list(cal["warnings"]), [str(w) for w in new.get("warnings") or []]
    if old_w != new_w:
        out.append("warnings then: " + (json.dumps(old_w, ensure_ascii=False) if old_w else "none"))
        out.append("warnings now:  " + (json.dumps(new_w, ensure_ascii=False) if new_w else "none"))
    sys.stdout.write("\n".join(out) + "\n")
    return 0
