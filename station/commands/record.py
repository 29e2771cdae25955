"""`station record --port PORT --out FILE`: record a device into a capture, headless."""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time

from station.errors import InputError, OutputError, require_positive
from station.fileio import check_output
from station.procedures import registry
from station.textsafe import safe

# The baud rates --baud takes. termios's standard rates run from 50 (B50) to 4000000 (Linux's
# B4000000); pyserial sets others through the driver (BOTHER), which high-speed USB adapters
# (FTDI's FT232H, FT2232H) take up to 12 Mbaud. Beyond that no serial device runs: 1e14 reached
# the driver's call and failed there ("signed integer is greater than maximum").
BAUD_MIN, BAUD_MAX = 50, 12_000_000


class SignalFlag:
    """A stop flag that a signal handler may set. ``threading.Event.set()`` takes the lock that
    ``Event.wait()`` holds on entering and leaving its wait; a handler run in the main thread at
    that moment waited for that lock for good (CI, under load: `record` sent SIGHUP, then
    SIGTERM, asleep with its partial open 20 minutes later). Setting a bool takes no lock;
    ``wait`` sleeps (a signal interrupts the sleep and the handler runs) and then looks."""

    def __init__(self) -> None:
        self._set = False

    def set(self) -> None:
        self._set = True

    def is_set(self) -> bool:
        return self._set

    def wait(self, timeout: float) -> bool:
        if not self._set:
            time.sleep(timeout)
        return self._set


def baud_arg(text: str) -> int:
    """argparse type of --baud: a whole number from BAUD_MIN to BAUD_MAX."""
    span = (
        f"a baud rate is a whole number from {BAUD_MIN} (the lowest standard rate) to {BAUD_MAX} "
        "(high-speed USB adapters; the standard rates end at 4000000)"
    )
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: {span}") from None
    if not BAUD_MIN <= value <= BAUD_MAX:
        raise argparse.ArgumentTypeError(f"{value} is out of range: {span}")
    return value


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "record",
        help="record a device (serial port or pyserial URL) into a capture file",
        description="Record samples from a device into a capture file until --seconds pass or "
        "SIGINT/SIGTERM/SIGHUP (a hang-up, e.g. an SSH session dropped, ends it as Ctrl-C does; under nohup it "
        "goes on). Rows are written as they arrive to FILE.partial; the finished capture "
        "replaces FILE atomically. --port takes a device path (/dev/ttyUSB0, /dev/pts/3) or a "
        "pyserial URL (socket://host:port, rfc2217://host:port, loop://); with --protocol mavlink also a network "
        "endpoint through pymavlink: udp:127.0.0.1:14550 (listen), udpout:HOST:PORT, tcp:HOST:5760, tcpin:HOST:PORT.",
    )
    p.add_argument("--port", help="device path or pyserial URL")
    p.add_argument(
        "--baud",
        type=baud_arg,
        default=115200,
        help=f"baud rate, {BAUD_MIN} to {BAUD_MAX} (default 115200; ignored by ptys and sockets)",
    )
    p.add_argument("--protocol", default="station", choices=("station", "mavlink"))
    p.add_argument(
        "--seconds", type=float, default=None, metavar="S", help="stop after S seconds (default: until interrupted)"
    )
    p.add_argument("--out", help="capture file to write")
    p.add_argument(
        "--procedure",
        choices=registry.names(),
        metavar="P",
        help=f"the procedure this capture is for (metadata): {registry.one_of(registry.names())}",
    )
    p.add_argument("--meta", action="append", metavar="KEY=VALUE", help="extra metadata, e.g. latitude_deg=39.98")
    p.add_argument(
        "--mavlink-message",
        metavar="MSG[:ID]",
        help="MAVLink stream to record, e.g. HIGHRES_IMU, SCALED_IMU2, RAW_IMU:1 (default: first IMU message seen)",
    )
    p.add_argument(
        "--mavlink-rate",
        type=float,
        default=200.0,
        metavar="HZ",
        help="ask the flight controller to stream at HZ (REQUEST_DATA_STREAM and MAV_CMD_SET_MESSAGE_INTERVAL; "
        "also reads AUTOPILOT_VERSION and the calibration parameters); 0: ask nothing (default 200)",
    )
    p.add_argument(
        "--recover",
        metavar="FILE.partial",
        help="finish the .partial file a killed recording left and exit: every whole row is kept, a cut "
        "last line dropped (said on stderr); a file with a bad row before its last line is refused, nothing written",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="with --recover: replace an existing --out (without it such a file is refused, nothing written)",
    )
    p.set_defaults(func=run)


def _meta(items: list[str] | None) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise InputError(None, None, f"--meta {item!r}: expected KEY=VALUE")
        out[key.strip()] = value.strip()
    return out


def _to_null(fd: int) -> None:
    """What is written to ``fd`` from now on (and what its buffer still holds, at exit) goes to
    the null device: a terminal that hung up answers every write with EIO, and the interpreter's
    flush at exit would turn the recording's exit status into 120."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, fd)
        os.close(null)
    except OSError:
        pass


def _warn(msg: str) -> None:
    """A line on stderr, if it can still be written: a terminal that hung up (SIGHUP) answers
    with EIO, and a warning raised there would leave the recording unfinished."""
    try:
        print(f"station record: {msg}", file=sys.stderr)
        sys.stderr.flush()
    except OSError:
        _to_null(2)


def run(args: argparse.Namespace) -> int:
    from station.device.mavlink import parse_source
    from station.device.record import record, recover_partial, refuse_unrecovered

    if args.recover:
        res = recover_partial(
            args.recover,
            args.out,
            warn=lambda msg: print(f"station record: {safe(msg)}", file=sys.stderr),
            force=args.force,
        )
        print(f"recovered {safe(args.recover)} -> {safe(res.path)}: {res.rows} rows")
        return 0
    if args.force:
        raise InputError(None, None, "--force applies to --recover only (a recording replaces its --out)")
    if not args.port:
        raise InputError(None, None, "--port is required (a device path or a pyserial URL)")
    if not args.out:
        raise InputError(None, None, "--out is required")
    if os.path.isdir(args.out):
        raise InputError(args.out, None, "is a folder: give --out a file name for the capture")
    check_output(args.out)  # a named pipe or a device: found out before, not after, the recording
    refuse_unrecovered(args.out)
    folder = os.path.dirname(os.path.abspath(args.out))
    if not os.path.isdir(folder):
        raise InputError(args.out, None, f"cannot write: no folder {folder}")
    require_positive("--seconds", args.seconds, "seconds")
    if args.mavlink_rate != 0:  # 0: ask the flight controller for nothing
        require_positive("--mavlink-rate", args.mavlink_rate, "Hz")
    try:
        parse_source(args.mavlink_message)
    except ValueError as exc:
        raise InputError(None, None, f"--mavlink-message: {exc}") from None
    stop, hung_up = SignalFlag(), SignalFlag()

    def _stop(signum, frame):  # noqa: ARG001
        if signum == signal.SIGHUP:
            hung_up.set()
        stop.set()

    # A hang-up (the terminal closed, an SSH session dropped without tmux) ends the recording as
    # Ctrl-C does: it killed the process where it stood, the rows left in FILE.partial. Under
    # `nohup` (SIGHUP ignored) it stays ignored: the recording goes on.
    signals = [signal.SIGINT, signal.SIGTERM]
    if signal.getsignal(signal.SIGHUP) is not signal.SIG_IGN:
        signals.append(signal.SIGHUP)
    old = {s: signal.signal(s, _stop) for s in signals}
    try:
        res = record(
            args.port,
            args.out,
            baud=args.baud,
            protocol=args.protocol,
            seconds=args.seconds,
            procedure=args.procedure,
            extra_meta=_meta(args.meta),
            mavlink_source=args.mavlink_message,
            mavlink_rate_hz=args.mavlink_rate or None,
            stop=stop,
            warn=_warn,
        )
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    if hung_up.is_set():
        ended = "complete: false (interrupted)" if res.incomplete else "complete"
        _warn(
            "hang-up (SIGHUP: the terminal or SSH session closed): the recording ended as on Ctrl-C; "
            f"{res.path} is {ended}"
        )
    m = res.meta
    summary = (
        f"recorded {res.samples} samples ({m.get('duration_s', '?')} s, {m.get('sample_rate_hz', '?')} Hz) "
        f"from {args.port} into {res.path}: gaps {m['gaps']}, parse errors {m['parse_errors']}, "
        f"reconnects {m['reconnects']}, dropped {m['dropped']}"
        + (f"; INCOMPLETE: {res.incomplete}" if res.incomplete else "")
    )
    if not hung_up.is_set():
        print(summary)
    else:  # the terminal may be gone: the capture is written, a summary nobody can read is no error
        try:
            print(summary)
            sys.stdout.flush()
        except (OSError, OutputError):
            _to_null(1)
    return 1 if res.incomplete else 0  # every sample is kept; the exit status says the data stop early
