"""`station import FILE [--format F] --procedure P --out CAPTURE`: a flight-controller log, ROS bag,
EuRoC/Kalibr or plain CSV as a station capture (README: Import; docs/import.md)."""

from __future__ import annotations

import argparse

from station.textsafe import safe


def register(sub: argparse._SubParsersAction) -> None:
    from station.importers.options import add_arguments

    p = sub.add_parser(
        "import",
        help="turn a PX4/ArduPilot/MAVLink log, ROS bag/MCAP, EuRoC/Kalibr or plain CSV into a capture",
        description="Read the data a flight controller, robot or bench logger already wrote and write a station "
        "capture for one procedure: units as the log declares them, the board's calibration "
        "parameters in use as param.* metadata, 'corrected: true' when the board had already "
        "applied them. Bad input: one line 'file:line: what is wrong', exit 2, nothing written.",
    )
    p.add_argument("file", help="the log or CSV file (a ROS 2 bag may be its folder)")
    p.add_argument(
        "--out",
        "-o",
        required=True,
        metavar="CAPTURE",
        help="the capture file to write (atomically)",
    )
    p.add_argument(
        "--device",
        default=None,
        help="the capture's device id (default: from the log where it names the board and sensor)",
    )
    add_arguments(p, for_import=True)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import os

    from station.capture import write_capture
    from station.errors import InputError, defer_warning
    from station.fileio import check_output
    from station.importers.load import import_file
    from station.importers.options import options_from_args

    check_output(args.out)
    if os.path.exists(args.out) and os.path.exists(args.file) and os.path.samefile(args.out, args.file):
        raise InputError(args.out, None, "--out is the input file: choose another name")
    capture, warnings = import_file(args.file, options_from_args(args))
    write_capture(args.out, capture)
    for w in warnings:  # printed when the command ends, one line each (station.cli)
        defer_warning(args.file, w)
    t = capture.columns["t"]
    cols = [c for c in capture.columns if c != "t"]
    params = sum(1 for k in capture.meta if k.startswith("param."))
    units = ", ".join(f"{k[:-5]} {v}" for k, v in capture.meta.items() if k.endswith("_unit"))
    corrected = capture.meta.get("corrected")
    print(
        f"{safe(args.out)}: {capture.procedure}, {capture.n_rows} rows, {float(t[-1]):.6g} s, "
        f"{capture.meta.get('sample_rate_hz')} Hz; columns {', '.join(cols)} ({units}); "
        f"{params} firmware parameters{'' if corrected is None else f'; corrected: {corrected}'}"
    )
    return 0
