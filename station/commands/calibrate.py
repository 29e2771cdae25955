"""`station calibrate FILE [--json] [--method M] [--device ID] [--save]` (calibrate.md)."""
from __future__ import annotations

import argparse



def register(sub: argparse._SubParsersAction) -> None:
    from station.importers.options import add_arguments

    p = sub.add_parser("calibrate", help="calibrate a capture file (the procedure named in its metadata)",
                       description="Compute the calibration the capture's procedure asks for and print it.")
    p.add_argument("file", help="capture file (station-capture CSV), or a log: .ulg, .bin, .tlog, ROS bag/MCAP, EuRoC/Kalibr CSV")
    p.add_argument("--json", action="store_true", help="print one JSON object (calibrate.md)")
    p.add_argument("--method", default=None, help="estimator, where a procedure offers several "
                   "(accel-tabletop: norm | upper-triangular | six-position | step8; accel-centrifuge: exact | "
                   "exact-gamma | paper | paper-3rd, each also -all; compass: rls | batch | ellipsoid; "
                   "gyro-drift: reference | static (mode A | B); ldv: force)")
    p.add_argument("--device", default=None, help="device id (default: the capture's 'device')")
    p.add_argument("--save", action="store_true", help="store capture and result in the station database")
    p.add_argument("--operator", default=None, help="operator's name, stored with --save")
    p.add_argument("--accuracy", type=float, default=None, metavar="DEG_H",
                   help="gyro-drift: the 1-sigma drift accuracy asked, °/h (sets metadata accuracy_deg_h)")
    p.add_argument("--reference", default=None, metavar="FILE",
                   help="ldv: the reference velocity stream as a separate capture (sets reference_file)")
    add_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import warnings

    from station.calibrate import calibrate_capture, format_text, to_json
    from station.importers.load import load_for_command

    if getattr(args, "accuracy", None) is not None and not 0 < args.accuracy < float("inf"):
        from station.errors import InputError

        raise InputError(None, None, f"--accuracy must be a positive number of °/h, got {args.accuracy:g}")
    capture = load_for_command(args)  # a capture, or a log / EuRoC file read through the importer
    if getattr(args, "accuracy", None) is not None:
        capture.meta["accuracy_deg_h"] = repr(float(args.accuracy))
    if getattr(args, "reference", None):
        import os

        capture.meta["reference_file"] = os.path.abspath(args.reference)
    with warnings.catch_warnings():  # numpy's RuntimeWarnings are not for the operator: one line or a result
        warnings.simplefilter("ignore", RuntimeWarning)
        result = calibrate_capture(capture, method=args.method)
    if args.device:
        result["device"] = args.device
    if args.save:
        result["calibration_id"] = _save(args, capture, result)
    if args.json:
        print(to_json(result))
    else:
        from station.textsafe import safe

        shown = dict(result, device=safe(result["device"]) if result.get("device") is not None else None)
        print(format_text(shown))
    return 0


def _save(args: argparse.Namespace, capture, result: dict) -> int:
    """save_result with the database's errors as one line and exit 2 (as the db commands do)."""
    import sqlite3

    from station.cli import db_path
    from station.errors import InputError
    from station.store import save_result

    path = db_path(args)
    try:
        return save_result(path, capture, result, device_id=args.device, operator=args.operator)
    except (sqlite3.Error, OSError) as exc:
        raise InputError(path, None, f"cannot save to the station database: {exc}") from None
    except ValueError as exc:  # the store's refusals (e.g. an empty device id)
        raise InputError(None, None, str(exc)) from None
