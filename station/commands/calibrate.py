"""`station calibrate FILE [--json] [--method M] [--device ID] [--save]` (calibrate.md)."""
from __future__ import annotations

import argparse



def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="calibrate a capture file (the procedure named in its metadata)",
                       description="Compute the calibration the capture's procedure asks for and print it.")
    p.add_argument("file", help="capture file (station-capture CSV)")
    p.add_argument("--json", action="store_true", help="print one JSON object (calibrate.md)")
    p.add_argument("--method", default=None, help="estimator, where a procedure offers several "
                   "(accel-tabletop: norm | upper-triangular | six-position; accel-centrifuge: exact | "
                   "exact-gamma | paper | paper-3rd, each also -all)")
    p.add_argument("--device", default=None, help="device id (default: the capture's 'device')")
    p.add_argument("--save", action="store_true", help="store capture and result in the station database")
    p.add_argument("--operator", default=None, help="operator's name, stored with --save")
    p.add_argument("--accuracy", type=float, default=None, metavar="DEG_H",
                   help="gyro-drift: the 1-sigma drift accuracy asked, °/h (sets metadata accuracy_deg_h)")
    p.add_argument("--reference", default=None, metavar="FILE",
                   help="ldv: the reference velocity stream as a separate capture (sets reference_file)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from station.calibrate import calibrate_capture, format_text, to_json
    from station.capture import read_capture

    capture = read_capture(args.file)
    if getattr(args, "accuracy", None) is not None:
        capture.meta["accuracy_deg_h"] = repr(float(args.accuracy))
    if getattr(args, "reference", None):
        import os

        capture.meta["reference_file"] = os.path.abspath(args.reference)
    result = calibrate_capture(capture, method=args.method)
    if args.device:
        result["device"] = args.device
    if args.save:
        from station.cli import db_path
        from station.store import save_result

        result["calibration_id"] = save_result(db_path(args), capture, result, device_id=args.device,
                                               operator=args.operator)
    print(to_json(result) if args.json else format_text(result))
    return 0
