"""`station report CALIBRATION_ID [-o FILE]`: the calibration's report as one self-contained HTML page."""

from __future__ import annotations

import argparse
import os

from station.commands._dbutil import open_store, record_id, refuse_database_as_output
from station.fileio import atomic_write_text, cannot_write


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "report",
        help="a calibration's report: one self-contained HTML page to file and sign",
        description="Write the calibration's report (device, procedure and source, operator, place, date and "
        "conditions, reference equipment, each parameter with u and U (k = 2) and units, pass/fail, "
        "the previous calibration and drift, figures, hashes and verify status) as HTML.",
    )
    p.add_argument("calibration_id", type=record_id("calibration"), metavar="CALIBRATION_ID")
    p.add_argument(
        "-o",
        "--out",
        default=None,
        metavar="FILE",
        help="where to write it (default: calibration-<ID>.html in the current folder; - for stdout)",
    )
    p.set_defaults(func=run)


def write_report(store, calibration_id: int, out: str | None) -> str:
    """Render and write atomically; returns the path (or '-' after writing to stdout)."""
    import sys

    from station.report import build_report, render_html

    page = render_html(build_report(store, calibration_id))
    if out == "-":
        sys.stdout.write(page)
        return "-"
    path = out or f"calibration-{calibration_id}.html"
    atomic_write_text(path, page)
    return path


def run(args: argparse.Namespace) -> int:
    from station.errors import InputError

    if args.out == "":  # an unset variable: not the default name in the current folder
        raise InputError(None, None, "--out '': an empty file name (leave --out out for calibration-ID.html)")
    if args.out not in (None, "-") and not os.path.isdir(os.path.dirname(os.path.abspath(args.out))):
        raise InputError(args.out, None, "its folder does not exist")
    refuse_database_as_output(args, args.out, "--out")
    with open_store(args) as store:
        with cannot_write(args.out, "the report"):
            path = write_report(store, args.calibration_id, args.out)
    if path != "-":
        print(path)
    return 0
