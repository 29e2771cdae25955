"""The command-line options that say how to read a log or a foreign CSV (import, calibrate,
diagnose). Light on purpose: building the parser must not load numpy."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field

from station.errors import InputError
from station.procedures import registry

FORMATS = ("px4", "ardupilot", "tlog", "ros", "euroc", "csv")
FORMAT_HELP = (
    "px4 (.ulg), ardupilot (.bin DataFlash), tlog (.tlog MAVLink), ros (.bag, .db3, .mcap, "
    "rosbag2 folder), euroc (EuRoC/Kalibr imu CSV), csv (any CSV with --map/--unit)"
)
TARGETS = ("t", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp_c")


@dataclass(frozen=True)
class Source:
    """One ``--source`` of a log format: its value, the import screen's words for it (short:
    the choice is 16 columns wide at 80x24) and what it reads."""

    value: str
    label: str
    reads: str


# The one registry of the sources a log format can be read from: `station import --source`
# (its choices and help) and the import screen's source choice both come from it.
SOURCES: dict[str, tuple[Source, ...]] = {
    "px4": (
        Source("auto", "PX4: auto", "the raw sensor_* topics where logged, else sensor_combined"),
        Source("raw", "raw topics", "sensor_accel/gyro/mag, before the board's calibration"),
        Source("combined", "combined", "sensor_combined, after the board's calibration"),
    ),
    "ardupilot": (
        Source("auto", "AP: auto", "IMU where logged, else ACC/GYR, else ISBH/ISBD"),
        Source("raw", "ACC/GYR", "ACC/GYR, every sample at the sensor's rate"),
        Source("combined", "IMU", "IMU, the filtered samples at the main loop's rate"),
        Source("batch", "ISB batch", "ISBH/ISBD, the batch sampler's blocks, INS_LOG_BAT_MASK"),
    ),
}
SOURCE_NAMES = {"px4": "PX4 logs", "ardupilot": "ArduPilot DataFlash logs"}


def source_values(fmt: str | None = None) -> tuple[str, ...]:
    """The ``--source`` values of ``fmt`` (None: of every format, in the registry's order)."""
    formats = [fmt] if fmt is not None else list(SOURCES)
    return tuple(dict.fromkeys(s.value for f in formats for s in SOURCES.get(f, ())))


def check_source(fmt: str, source: str) -> None:
    """Refuse a ``--source`` that ``fmt`` has no such source for, in one line."""
    if source == "auto":
        return
    if fmt not in SOURCES:
        raise InputError(None, None, f"--source applies to {' and '.join(SOURCE_NAMES[f] for f in SOURCES)} only")
    if source not in source_values(fmt):
        raise InputError(
            None,
            None,
            f"--source {source}: {SOURCE_NAMES[fmt]} are read from {', '.join(source_values(fmt))}",
        )


def _source_help() -> str:
    return "; ".join(
        f"{SOURCE_NAMES[fmt]}: " + ", ".join(f"{s.value} ({s.reads})" for s in sources)
        for fmt, sources in SOURCES.items()
    )


def primary(procedure: str | None) -> str | None:
    """The sensor kind whose samples are the rows of ``procedure``'s capture made from a log;
    None when a log cannot feed it (registry: ``from_logs``)."""
    p = registry.get(procedure)
    return p.sensor_kind if p is not None and p.from_logs else None


@dataclass
class ImportOptions:
    """What the command line says about reading a foreign file (all optional)."""

    fmt: str | None = None
    procedure: str | None = None
    instance: int | None = None
    source: str = "auto"
    topics: dict[str, str] = field(default_factory=dict)
    mapping: dict[str, str] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    rate_hz: float | None = None
    device: str | None = None


def parse_pairs(items: list[str] | None, what: str) -> dict[str, str]:
    """``["t=time_s,ax=acc_x", "ay=acc_y"]`` → ``{"t": "time_s", "ax": "acc_x", "ay": "acc_y"}``."""
    out: dict[str, str] = {}
    for item in items or []:
        if not item.replace(",", "").strip():  # "" from an unset shell variable: not the same as leaving it out
            raise InputError(None, None, f"{what} {item!r} is empty: expected NAME=VALUE")
        for part in item.split(","):
            if not part.strip():
                continue
            key, sep, value = part.partition("=")
            key, value = key.strip(), value.strip()
            if not sep or not key or not value:
                raise InputError(None, None, f"{what} {part.strip()!r}: expected NAME=VALUE")
            if key in out:
                raise InputError(None, None, f"{what}: {key} given twice")
            out[key] = value
    return out


def add_arguments(parser: argparse.ArgumentParser, *, for_import: bool = False) -> None:
    """Add the import options to ``parser`` (``--procedure`` required for ``station import``)."""
    g = parser.add_argument_group("reading logs and other files (README: Import)")
    g.add_argument(
        "--format",
        dest="import_format",
        choices=FORMATS,
        default=None,
        help=f"the file's format (default: from its name or header): {FORMAT_HELP}",
    )
    g.add_argument(
        "--procedure",
        dest="import_procedure",
        choices=registry.importable(),
        default=None,
        required=for_import,
        help="the procedure the data are for (sets the capture's rows: "
        + ", ".join(f"{primary(p)} samples for {p}" for p in registry.importable())
        + ")"
        + ("" if for_import else "; needed for a log unless it holds only magnetometer data"),
    )
    g.add_argument(
        "--instance",
        type=int,
        default=None,
        metavar="N",
        help="PX4: uORB instance of sensor_accel/gyro/mag; ArduPilot/MAVLink: IMU and compass "
        "instance (0 = first; default: the first the log has, a warning naming the others)",
    )
    g.add_argument(
        "--source",
        choices=source_values(),
        default="auto",
        help="where in the log the accelerometer and gyro samples are read from: " + _source_help(),
    )
    g.add_argument(
        "--topic",
        action="append",
        default=None,
        metavar="KIND=TOPIC",
        help="ROS: which topic to read when there are several (imu=/imu0, mag=/mag, temp=/temp)",
    )
    g.add_argument(
        "--map",
        action="append",
        default=None,
        metavar="COL=SOURCE,...",
        help=f"CSV: capture column = source column name or 1-based number ({', '.join(TARGETS)})",
    )
    g.add_argument(
        "--unit",
        action="append",
        default=None,
        metavar="KIND=UNIT,...",
        help="CSV: units: accel=g|m/s^2|mg|counts|V, gyro=deg/s|rad/s|…, mag=uT|nT|gauss|…, t=s|ms|us|ns",
    )
    g.add_argument(
        "--rate",
        type=float,
        default=None,
        metavar="HZ",
        help="CSV without a time column: the sample rate",
    )


def options_from_args(args: argparse.Namespace) -> ImportOptions:
    topics = parse_pairs(getattr(args, "topic", None), "--topic")
    for key in topics:
        if key not in ("imu", "mag", "temp"):
            raise InputError(None, None, f"--topic {key}=…: expected imu, mag or temp")
    return ImportOptions(
        fmt=getattr(args, "import_format", None),
        procedure=getattr(args, "import_procedure", None),
        instance=getattr(args, "instance", None),
        source=getattr(args, "source", "auto") or "auto",
        topics=topics,
        mapping=parse_pairs(getattr(args, "map", None), "--map"),
        units=parse_pairs(getattr(args, "unit", None), "--unit"),
        rate_hz=getattr(args, "rate", None),
        device=getattr(args, "device", None),
    )
