"""`station verify`: exit 1, naming the record, when a stored calibration, capture, device setting
or schedule was changed or removed after it was written (`db.store.Store.verify`)."""

from __future__ import annotations

import argparse
import json
import sqlite3
import sys

from station.commands._dbutil import open_store
from station.errors import InputError
from station.textsafe import safe


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "verify", help="check that no stored calibration was changed after it was written (exit 1 if one was)"
    )
    p.add_argument("--json", action="store_true", help="a JSON list of problems")
    p.add_argument(
        "--anchor",
        action="append",
        default=[],
        metavar="HASH",
        help="an anchor hash from an export or report: a problem unless the record still holds it",
    )
    p.set_defaults(func=run)


def _anchor(text: str) -> str:
    """An anchor as typed or pasted: a sha256 hex digest (spaces around it and letter case do
    not matter); anything else is a usage error, not the tamper alarm of a missing anchor."""
    anchor = text.strip().lower()
    if len(anchor) != 64 or any(c not in "0123456789abcdef" for c in anchor):
        raise InputError(
            None,
            None,
            f"--anchor {safe(repr(text))}: not an anchor hash (64 hex digits, as an export's "
            "'# station anchor' line or JSON 'anchor' gives it)",
        )
    return anchor


def run(args: argparse.Namespace) -> int:
    anchors = [_anchor(a) for a in args.anchor]
    with open_store(args) as store:
        sound = store.integrity_check()
        problems = store.verify()
        for anchor in anchors:
            try:
                held = store.has_anchor(anchor)
            except sqlite3.Error:  # no anchors table: reported by verify as a damaged schema
                held = False
            if not held:
                problems.append(
                    {
                        "kind": "anchor missing",
                        "calibration_id": None,
                        "capture_id": None,
                        "device_id": None,
                        "detail": f"anchor {anchor} (from an export or report) is not in "
                        "the record: anchors written after it was shown were removed or rewritten",
                    }
                )
        counts = store.counts()
    if sound != "ok":
        problems.insert(0, {"kind": "corrupt file", "detail": f"PRAGMA integrity_check: {sound}"})
    if args.json:
        sys.stdout.write(json.dumps(problems, indent=2, ensure_ascii=False) + "\n")
        return 1 if problems else 0
    for p in problems:
        what = []
        if p.get("calibration_id") is not None:
            what.append(f"calibration {p['calibration_id']}")
        if p.get("capture_id") is not None:
            what.append(f"capture {p['capture_id']}")
        device = f" (device {safe(p['device_id'])})" if p.get("device_id") is not None else ""
        sys.stdout.write(f"{p['kind']}: {' / '.join(what) or 'database'}{device}: {safe(p['detail'])}\n")
    if problems:
        sys.stderr.write(f"station: verify found {len(problems)} problem{'s' if len(problems) != 1 else ''}\n")
        return 1

    def n(count: int, word: str) -> str:
        return f"{count} {word}{'' if count == 1 else 's'}"

    sys.stdout.write(
        f"ok: {n(counts['calibrations'], 'calibration')} and {n(counts['captures'], 'capture')} of "
        f"{n(counts['devices'], 'device')} unchanged since they were written\n"
    )
    return 0
