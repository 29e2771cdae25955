"""`station diagnose FILE [--json]` (../shared/spec/diagnose.md)."""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    from station.importers.options import add_arguments

    p = sub.add_parser(
        "diagnose",
        help="show what the model gets wrong on a capture, name the cause, measure the gain",
        description="Fit the procedure's baseline, test the effect library, report the extended "
        "model and data-quality findings (diagnose.md).",
    )
    p.add_argument(
        "file", help="capture file (station-capture CSV), or a log: .ulg, .bin, .tlog, ROS bag/MCAP, EuRoC/Kalibr CSV"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object (diagnose.md)")
    p.add_argument("--no-plots", action="store_true", help="text report without terminal plots")
    add_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from station.calibrate import to_json
    from station.importers.load import load_for_command
    from station.procedures.diagnose import analyse, format_text

    capture = load_for_command(args)  # a capture, or a log / EuRoC file read through the importer
    result, diag, inp = analyse(capture)
    print(to_json(result) if args.json else format_text(result, diag, inp, plots=not args.no_plots))
    return 0
