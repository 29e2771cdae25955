"""Which reader a file needs, and the capture it gives (for ``import``, ``calibrate``, ``diagnose``)."""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path

from station.capture import DEVICE_TEXT_RULE, Capture, read_capture, write_capture
from station.errors import InputError
from station.fileio import LOG_MAGIC, check_input
from station.importers._common import NAME, Imported, to_capture
from station.importers.options import (
    FORMATS,
    ImportOptions,
    check_source,
    options_from_args,
    primary,
)
from station.procedures import registry

_WHAT = {
    "px4": "a ULog file",
    "ardupilot": "an ArduPilot DataFlash log",
    "tlog": "a MAVLink log",
    "ros": "a ROS bag",
    "euroc": "a CSV file",
    "csv": "a CSV file",
}
_SUFFIX = {".ulg": "px4", ".bin": "ardupilot", ".tlog": "tlog"}


def _by_content(path) -> str | None:
    """The log format ``path``'s first bytes announce, or None (a FIFO or device is never opened here)."""
    from station.fileio import log_kind, open_input

    try:
        with open_input(path) as f:
            kind = log_kind(f.read(8))
    except (InputError, OSError):
        return None
    return kind[0] if kind else None


def detect(path) -> str | None:
    """The format of ``path`` by its first bytes (a ULog or DataFlash log under any name), else
    its name (and, for CSV, its header line); None for a station capture or a file this cannot
    tell (then it is read as a capture, whose reader explains)."""
    from station.importers import csvfiles, ros

    p = Path(path)
    fmt = _by_content(path) or _SUFFIX.get(p.suffix.lower())
    if fmt:
        return fmt
    if ros.is_bag(p):
        return "ros"
    if p.is_file() and csvfiles.is_euroc(p):
        return "euroc"
    return None


def read(path, opts: ImportOptions, fmt: str) -> Imported:
    """The streams and metadata of ``path`` read as ``fmt``."""
    if fmt not in FORMATS:
        raise InputError(None, None, f"--format {fmt!r}: expected one of {', '.join(FORMATS)}")
    check_source(fmt, opts.source)
    if fmt not in ("px4", "ardupilot", "tlog") and opts.instance is not None:
        raise InputError(None, None, "--instance applies to PX4, ArduPilot and MAVLink logs only")
    if fmt != "ros" and opts.topics:
        raise InputError(None, None, "--topic applies to ROS bags and MCAP files only")
    if fmt != "csv" and (opts.mapping or opts.units or opts.rate_hz is not None):
        raise InputError(
            None,
            None,
            f"--map, --unit and --rate apply to plain CSV files (this is read as {fmt}: its units come from the file)",
        )
    p = Path(path)
    # the one check before a reader (ours or a library's) opens the path: no FIFO, no device
    check_input(path, _WHAT[fmt], folder=fmt == "ros")
    if p.is_file() and p.stat().st_size == 0:
        raise InputError(path, None, "empty file")
    if fmt == "px4":
        from station.importers import px4

        return px4.read(
            path,
            instance=opts.instance,
            source=opts.source,
            primary=primary(opts.procedure),
        )
    if fmt in ("ardupilot", "tlog"):
        from station.importers import ardupilot

        if fmt == "ardupilot":
            return ardupilot.read_bin(path, instance=opts.instance, source=opts.source)
        return ardupilot.read_tlog(path, instance=opts.instance)
    if fmt == "ros":
        from station.importers import ros

        return ros.read(path, topics=opts.topics)
    from station.importers import csvfiles

    if fmt == "euroc":
        return csvfiles.read_euroc(path)
    return csvfiles.read_plain(path, mapping=opts.mapping, units=opts.units, rate_hz=opts.rate_hz)


def infer_procedure(path, imported: Imported, fmt: str) -> str:
    """The procedure when the data leave only one (a magnetometer alone: compass)."""
    kinds = set(imported.streams)
    if kinds == {"mag"}:  # a magnetometer alone: the one procedure that calibrates it
        return next(p for p in registry.importable() if primary(p) == "mag")
    have = ", ".join(NAME[k] for k in imported.streams) or "no sensor data"
    fits = [p for p in registry.importable() if primary(p) in kinds] or list(registry.importable())
    raise InputError(
        path,
        None,
        f"{_WHAT[fmt]} with {have} data: say which procedure with --procedure ({', '.join(fits)})",
    )


def is_station_capture(path) -> bool:
    """Whether ``path`` starts with the station capture's first line."""
    from station.importers.csvfiles import first_line

    return first_line(path).replace(" ", "").startswith("#station-capture:")


def import_file(path, opts: ImportOptions) -> tuple[Capture, list[str]]:
    """``path`` as a capture (not yet written) and the reader's warnings."""
    device = opts.device
    if device is not None and (device != device.strip() or not device.isprintable()):  # found before the reading
        raise InputError(None, None, f"--device {device!r}: {DEVICE_TEXT_RULE}")
    fmt = opts.fmt or detect(path)
    if fmt is None:
        if is_station_capture(path):
            # what inspect would say of it: a capture it refuses is refused here in its words
            # (a Windows-1252 one it reads is "already a capture"; one no encoding reads is not)
            read_capture(path)
            raise InputError(
                path,
                1,
                "already a station capture: calibrate, diagnose and inspect read it as it is",
            )
        fmt = "csv"
    capture, warnings = capture_of(path, read(path, opts, fmt), fmt, opts.procedure, opts.device)
    suffix = Path(path).suffix
    if not opts.fmt and _SUFFIX.get(suffix.lower(), fmt) != fmt:  # a .ulg copied as .bin, ...
        what = next(w for _, f, w in LOG_MAGIC if f == fmt)
        warnings.insert(0, f"named {suffix} but {what} by its first bytes: read as one")
    return capture, warnings


def capture_of(
    path, imported: Imported, fmt: str, procedure: str | None, device: str | None = None
) -> tuple[Capture, list[str]]:
    """What :func:`read` found as the capture of ``procedure`` (None: the one the data leave),
    and the reader's warnings. ``imported`` is not changed (the TUI's Import screen builds
    captures of several procedures from one reading)."""
    imported = Imported(dict(imported.streams), dict(imported.meta), list(imported.warnings))
    procedure = procedure or infer_procedure(path, imported, fmt)
    if device is None and fmt == "px4":
        from station.importers import px4

        device = px4.default_device(imported, primary(procedure))
    try:
        capture = to_capture(path, imported, procedure, device=device)
    except InputError as exc:
        # what the reader noticed first (a log cut short, raw topics at 1 Hz) is often why
        # too little is left: the one refusal line carries it, as the CLI folds in warnings
        if not imported.warnings:
            raise
        also = "".join(f"; warning: {w}" for w in imported.warnings)
        raise InputError(exc.path, exc.line, f"{exc.message}{also}") from None
    _escape_text(capture.meta, imported.warnings)
    return capture, list(imported.warnings)


def _escape_text(meta: dict[str, str], warnings: list[str]) -> None:
    """Metadata text from a log (a board name, a firmware string) with a control character or
    spaces at its ends, which no capture can hold, kept with the characters shown escaped and
    a warning: one flipped byte in a name refused the whole log."""
    from station.textsafe import safe

    changed = []
    for key, value in meta.items():
        if isinstance(value, str) and (value != value.strip() or not value.isprintable()):
            meta[key] = safe(value.strip()) or "?"
            changed.append(key)
    if changed:
        warnings.append(
            f"metadata {', '.join(changed)} held a control character (a corrupt log?): kept with it shown escaped"
        )


def checked(path, capture: Capture) -> Capture:
    """``capture`` written and read back by the capture reader (its checks, exactly as
    ``station import`` followed by ``calibrate`` would meet them), named after ``path``."""
    with tempfile.TemporaryDirectory(prefix="station-import-") as tmp:
        tmp_path = os.path.join(tmp, "capture.csv")
        try:
            write_capture(tmp_path, capture)
            out = read_capture(tmp_path)
        except InputError as exc:  # named after the file the operator gave, not the temporary one
            raise InputError(path, None, f"{exc.message} (in the capture made from it)") from None
    out.path = os.fspath(path)
    out.meta_lines = {}
    out.header_line = None
    return out


def load_capture(path, opts: ImportOptions) -> tuple[Capture, list[str]]:
    """What ``calibrate`` and ``diagnose`` read: a station capture as it is, or a file whose
    format is clear (its name or header, or ``--format``) through the importer, then checked
    by the capture reader exactly as ``station import`` followed by ``calibrate`` would be."""
    fmt = opts.fmt or detect(path)
    if fmt is None:
        if opts.mapping or opts.units or opts.rate_hz is not None:
            fmt = "csv"  # --map/--unit say it is a foreign CSV
        else:
            capture = read_capture(path)
            if opts.procedure and capture.procedure and opts.procedure != capture.procedure:
                raise InputError(
                    path,
                    capture.meta_lines.get("procedure"),
                    f"the capture says procedure {capture.procedure}; --procedure "
                    f"{opts.procedure} is for logs and other files read through the importer",
                )
            if opts.procedure and not capture.procedure:
                capture.meta["procedure"] = opts.procedure
            return capture, list(capture.notes)
    capture, warnings = import_file(path, ImportOptions(**{**opts.__dict__, "fmt": fmt}))
    return checked(path, capture), warnings


def load_for_command(args: argparse.Namespace) -> Capture:
    """``calibrate FILE`` / ``diagnose FILE``: the capture; the reader's warnings go to stderr
    when the command ends (after its result, or inside its one error line)."""
    from station.errors import defer_warning

    capture, warnings = load_capture(args.file, options_from_args(args))
    for w in warnings:
        defer_warning(args.file, w)
    return capture
