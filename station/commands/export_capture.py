"""`station export-capture CAPTURE_ID [-o FILE]` (or `--calibration ID`): a stored capture as a capture file."""

from __future__ import annotations

import argparse
import sys

from station.commands._dbutil import open_store, record_id, refuse_database_as_output
from station.errors import InputError


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "export-capture",
        help="a stored capture back as a capture file (the station's CSV format)",
        description="Write a capture stored in the database as a capture file, exactly as it was saved "
        "(same metadata, columns and values). Give the capture's id, or --calibration ID for the capture a "
        "calibration was computed from.",
    )
    p.add_argument("capture_id", metavar="CAPTURE_ID", type=record_id("capture"), nargs="?", help="capture id")
    p.add_argument(
        "--calibration", metavar="ID", type=record_id("calibration"), help="export the capture of this calibration"
    )
    p.add_argument("-o", "--output", metavar="FILE", help="write FILE (atomically) instead of stdout (- for stdout)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from station.capture import Capture, format_capture, write_capture

    if (args.capture_id is None) == (args.calibration is None):
        raise InputError(None, None, "export-capture: give a CAPTURE_ID or --calibration ID (one of them)")
    refuse_database_as_output(args, args.output, "-o")
    with open_store(args) as store:
        capture_id = args.capture_id
        if capture_id is None:
            capture_id = store.calibration(args.calibration)["capture_id"]
            if capture_id is None:
                raise InputError(None, None, f"calibration {args.calibration} was stored without its capture")
        meta, columns = store.load_capture(capture_id)
    to_file = args.output not in (None, "-")
    capture = Capture(meta=dict(meta), columns=columns, path=args.output if to_file else None)
    if to_file:
        write_capture(args.output, capture)
    else:
        format_capture(capture, sys.stdout)
    return 0
