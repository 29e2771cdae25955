"""`station export CALIBRATION_ID --format json|ardupilot|px4|c-header`."""

from __future__ import annotations

import argparse
import re
import sys

from station.commands._dbutil import open_store, record_id, refuse_database_as_output
from station.errors import InputError
from station.fileio import atomic_write_text, cannot_write

FORMATS = (
    "json",
    "ardupilot",
    "px4",
    "qgc",
    "c-header",
)  # = station.firmware_export.FORMATS (not imported: start-up time)


def device_id_arg(text: str) -> int:
    """argparse type of --device-id: a whole number, decimal (``2424842``, as QGroundControl and
    Mission Planner list CAL_ACC0_ID / INS_ACC_ID) or hexadecimal with ``0x`` (``0x250002``, as
    PX4's ``listener`` and drivers print a device id). Its range is the format's to judge
    (station.firmware_export), so a value out of it is refused there, naming the parameter."""
    cell = text.strip()
    if re.fullmatch(r"[+-]?[0-9]+", cell):
        return int(cell, 10)
    if re.fullmatch(r"[+-]?0[xX][0-9a-fA-F]+", cell):
        return int(cell, 16)
    raise argparse.ArgumentTypeError(
        f"{text!r} is no device id: give a whole number, decimal (2424842) or hexadecimal with 0x (0x250002)"
    )


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "export",
        help="a stored calibration as JSON, ArduPilot or PX4 parameters, or a C header",
        description="ardupilot: a .param file (Mission Planner, MAVProxy); px4: 'param set' lines; qgc: a "
        "QGroundControl .params file (PX4); c-header: float constants. When the capture's data were already "
        "corrected by the board, the new absolute parameters are composed with the parameters in use (read from "
        "the capture's param.<NAME> metadata); see station/firmware_export.py.",
    )
    p.add_argument("calibration_id", metavar="CALIBRATION_ID", type=record_id("calibration"))
    p.add_argument("--format", required=True, choices=FORMATS)
    p.add_argument(
        "--instance",
        type=int,
        help="firmware sensor slot (ArduPilot IMUs 1-5, compasses 1-3, default: the capture's sensor's, else 1; PX4 0-3, default: the slot of the capture's sensor, the only one in use, or 0)",
    )
    p.add_argument(
        "--device-id",
        type=device_id_arg,
        metavar="ID",
        help="PX4: the sensor's device id for CAL_*n_ID when the capture does not hold it, decimal (2424842) "
        "or hexadecimal (0x250002)",
    )
    p.add_argument(
        "--vehicle",
        default=None,
        metavar="SYSID,COMPID",
        help="qgc: the vehicle and component id columns (default 1,1)",
    )
    p.add_argument("-o", "--output", metavar="FILE", help="write to FILE (atomically) instead of stdout (- for stdout)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from station.firmware_export import export

    refuse_database_as_output(args, args.output, "-o")
    # an option the format has no use for was ignored without a word (--device-id with ardupilot)
    for option, value, formats in (
        ("--instance", args.instance, ("ardupilot", "px4", "qgc")),
        ("--device-id", args.device_id, ("px4", "qgc")),
        ("--vehicle", args.vehicle, ("qgc",)),
    ):
        if value is not None and args.format not in formats:
            raise InputError(None, None, f"{option} applies to --format {' or '.join(formats)} only")
    if args.vehicle is None:
        args.vehicle = "1,1"
    with open_store(args) as store:
        cal = store.calibration(args.calibration_id)
        meta = store.capture_info(cal["capture_id"])["meta"] if cal["capture_id"] is not None else {}
    try:
        sysid, compid = (int(x) for x in args.vehicle.split(","))
    except ValueError:
        raise InputError(None, None, f"--vehicle {args.vehicle!r}: expected SYSID,COMPID, e.g. 1,1") from None
    if not (1 <= sysid <= 255 and 0 <= compid <= 255):  # MAVLink: one byte each, system 0 is broadcast
        raise InputError(
            None, None, f"--vehicle {args.vehicle!r}: MAVLink ids are a system 1-255 and a component 0-255"
        )
    text = export(cal, meta, args.format, args.instance, device_id=args.device_id, vehicle=(sysid, compid))
    for line in text.splitlines():  # a value the firmware takes beyond its documented range: said here too
        if line.startswith("# warning: "):
            print(f"station: warning: {line[len('# warning: ') :]}", file=sys.stderr)
    if args.output is not None and args.output != "-":
        with cannot_write(args.output):
            atomic_write_text(args.output, text)
    else:
        sys.stdout.write(text)
    return 0
