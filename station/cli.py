"""`station` command line: a thin layer that parses, then calls library code.

Subcommands live one per module in `station/commands/`; each module defines
`register(subparsers)` and sets `func=handler(args) -> int` on its parser.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import pkgutil
import sys
import warnings

from station import __version__
from station.errors import InputError, OutputError, StationError, take_deferred_warnings


def _common(parser: argparse.ArgumentParser) -> None:
    from db.store import default_db_path

    parser.add_argument(
        "--db",
        default=argparse.SUPPRESS,
        help="station database file (default: $STATION_DB, else ${XDG_DATA_HOME:-~/.local/share}/station/station.db;"
        f" here {default_db_path()})",
    )


class _Parser(argparse.ArgumentParser):
    """argparse with a usage error on one line (what is wrong and where the help is), not the
    whole usage block before it; subcommand parsers are made of the same class."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="station",
        description="Calibration station for inertial and magnetic sensors. "
        "With no command, starts the operator TUI on the built-in simulated device.",
    )
    parser.add_argument("--version", action="version", version=f"station {__version__}")
    _common(parser)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    import station.commands as commands

    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"station.commands.{info.name}")
        register = getattr(module, "register", None)
        if register is None:
            continue
        before = set(sub.choices)
        register(sub)
        for name in set(sub.choices) - before:
            _common(sub.choices[name])
    return parser


# arguments that are text the station stores or writes (ids, names, notes, limits), not paths:
# a path may hold any bytes the system allows, these must be characters
TEXT_ARGS = ("id", "device", "model", "notes", "operator", "reject", "override", "limit", "tolerance", "meta")


def _check_text_args(args: argparse.Namespace) -> None:
    """Refuse a text argument holding bytes that are not UTF-8 (kept by Python as lone
    surrogates): SQLite's encoder failed on them deep inside and the line blamed the
    database ("cannot read the station database: 'utf-8' codec can't encode ...")."""
    for name in TEXT_ARGS:
        value = getattr(args, name, None)
        for text in value if isinstance(value, list) else [value]:
            if not isinstance(text, str):
                continue
            if name in ("id", "device") and not text.strip():
                # was: `calibrate --device ''` fell back to the capture's device without a word
                raise InputError(
                    None, None, f"{'ID' if name == 'id' else '--device'} '{text}': a device id must be non-empty text"
                )
            bad = [ch for ch in text if 0xDC80 <= ord(ch) <= 0xDCFF]
            if bad:
                from station.textsafe import safe

                shown = text.encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
                option = name if name == "id" else "--" + name
                raise InputError(
                    None,
                    None,
                    f"{option} '{safe(shown)}': not UTF-8 text (byte 0x{ord(bad[0]) - 0xDC00:02x}); give it in UTF-8",
                )


def db_path(args: argparse.Namespace) -> str:
    """The database path: --db, else ``db.store.default_db_path()`` ($STATION_DB, then XDG).

    A path given (--db, $STATION_DB) in a folder that does not exist is refused (InputError):
    a mistyped one made that folder and a new empty database in it. Only the built-in default
    (XDG) gets its folder made, when a command creates the database."""
    explicit, source = _given_db(args)
    if explicit:
        _require_folder(explicit, source)
        return explicit
    from db.store import default_db_path  # loaded only when the default is needed

    return default_db_path()


def db_source(args: argparse.Namespace) -> str | None:
    """Where ``db_path(args)`` came from: "--db", "$STATION_DB", or None for the built-in default."""
    return _given_db(args)[1]


def _given_db(args: argparse.Namespace) -> tuple[str, str] | tuple[None, None]:
    """The database path given and where: --db, else $STATION_DB (an empty one is not given);
    (None, None) for the built-in default. The one place of that precedence."""
    if getattr(args, "db", None):
        return args.db, "--db"
    if os.environ.get("STATION_DB"):
        return os.environ["STATION_DB"], "$STATION_DB"
    return None, None


def _require_folder(path: str, source: str) -> None:
    """InputError when the folder of a database path that was given does not exist (or is no folder)."""
    if path == ":memory:" or path.startswith("file:"):
        return
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(folder):
        return
    what = "is not a folder" if os.path.exists(folder) else "does not exist"
    raise InputError(
        path, None, f"no station database here: the folder {folder} {what} (mistyped {source}?); nothing created"
    )


# Commands that own the terminal (Textual draws it); everything else writes through SafeStream.
_TERMINAL_APPS = ("tui", "demo")


@contextlib.contextmanager
def _safe_streams(args: argparse.Namespace):
    """stdout/stderr escape terminal-active characters (station.textsafe) while a command runs."""
    from station.textsafe import SafeStream

    if getattr(args, "command", None) in _TERMINAL_APPS:
        yield
        return
    as_json = bool(getattr(args, "json", False)) or getattr(args, "format", None) == "json"
    out, err = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = SafeStream(out, json=as_json, name="standard output"), SafeStream(err)
    try:
        yield
    finally:
        sys.stdout, sys.stderr = out, err


def _one_line(text: str) -> str:
    """An error or warning line with any newline or control character in it (a file name
    holding one, a library's multi-line message) shown escaped: it stays one line."""
    from station.textsafe import safe

    return safe(text)


def _tui_options_first(parser: argparse.ArgumentParser, argv: list[str]) -> list[str]:
    """``station --port PORT`` (README: the TUI "unless --port is given") as ``station tui
    --port PORT``: options with no command are the TUI's. Argparse took the port for a command
    name ("invalid choice: '/dev/ttyUSB0'"). A line naming a command, or only the station's
    own options (-h, --version), is left as it is."""
    commands = parser._subparsers._group_actions[0].choices if parser._subparsers else {}
    if "tui" not in commands or not argv or not argv[0].startswith("-") or argv[0] in ("-h", "--help", "--version"):
        return argv
    if any(a in commands for a in argv):
        return argv
    return ["tui", *argv]


class _Terminated(BaseException):
    """SIGTERM (kill, timeout, systemd stop) raised where the command is, so that what it was
    writing unwinds as on Ctrl-C: the atomic write's temporary removed, a transaction rolled back."""


@contextlib.contextmanager
def _sigterm_unwinds(args: argparse.Namespace):
    """While a command runs (not the TUI, which owns its signals), SIGTERM raises _Terminated.
    Only in the main thread and only where SIGTERM has its default action (an ignored one stays
    ignored); the old handler is put back after."""
    import signal
    import threading

    def _raise(signum, frame):  # noqa: ARG001
        raise _Terminated()

    if (
        getattr(args, "command", None) in _TERMINAL_APPS
        or threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL
    ):
        yield
        return
    signal.signal(signal.SIGTERM, _raise)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, signal.SIG_DFL)


def _quiet_stdout() -> None:
    """After standard output failed: what is left in its buffer goes to the null device, so
    the interpreter's flush at exit adds no 'Exception ignored' lines to the one error line."""
    try:
        fd = os.open(os.devnull, os.O_WRONLY)
        os.dup2(fd, 1)
        os.close(fd)
    except OSError:
        pass


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    argv = _tui_options_first(parser, list(sys.argv[1:] if argv is None else argv))
    args = parser.parse_args(argv)
    func = getattr(args, "func", None)
    if func is None:
        # No subcommand: the TUI on the simulated device when it exists, else the demo.
        tui = parser._subparsers._group_actions[0].choices.get("tui") if parser._subparsers else None
        if tui is not None:
            args = parser.parse_args(["tui", *argv])  # keep --db
        else:
            args = parser.parse_args(["walkthrough"])
        func = args.func
    debug = bool(os.environ.get("STATION_DEBUG"))
    with warnings.catch_warnings(), _safe_streams(args), _sigterm_unwinds(args):
        if not debug:  # numerics' RuntimeWarnings are not the operator's business: results carry warnings
            warnings.simplefilter("ignore", RuntimeWarning)
        take_deferred_warnings()  # none from an earlier main() in this process
        try:
            _check_text_args(args)
            status = int(func(args) or 0)
            sys.stdout.flush()  # a full disk behind '> file' is found here, not at exit
            for where, w in take_deferred_warnings():
                print(_one_line(f"station: {where}: warning: {w}"), file=sys.stderr)
            return status
        except OutputError as exc:
            _quiet_stdout()
            take_deferred_warnings()
            print(_one_line(f"station: {exc}"), file=sys.stderr)
            return exc.exit_status
        except StationError as exc:
            held = take_deferred_warnings()
            also = "".join(f"; warning: {w}" for _, w in held)
            print(_one_line(f"station: {exc}{also}"), file=sys.stderr)
            return exc.exit_status
        except KeyboardInterrupt:
            print("station: interrupted", file=sys.stderr)
            return 130
        except _Terminated:
            print("station: terminated", file=sys.stderr)
            return 143
        except BrokenPipeError:
            return 0
        except Exception as exc:  # noqa: BLE001 - the last line of defence: one line, never a traceback
            if debug:
                raise
            where = getattr(args, "file", None) or getattr(args, "command", None) or "station"
            also = "".join(f"; warning: {w}" for _, w in take_deferred_warnings())
            print(
                _one_line(
                    f"station: {where}: cannot process this input ({type(exc).__name__}: {exc}); "
                    f"STATION_DEBUG=1 shows the traceback{also}"
                ),
                file=sys.stderr,
            )
            return 2
