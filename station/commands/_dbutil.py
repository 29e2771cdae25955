"""Shared plumbing of the database commands: open the store, map its errors to exit 2."""

from __future__ import annotations

import argparse
import json
import shutil
import sqlite3
import sys
import textwrap
from contextlib import contextmanager

from station.errors import InputError


def record_id(what: str):
    """An argparse type for a stored record's number (``what``: calibration, capture): a device
    id given by mistake is told apart in the one-line usage error."""

    def parse(text: str) -> int:
        try:
            return int(text)
        except ValueError:
            hint = " (the # that `station history DEVICE` lists)" if what == "calibration" else ""
            raise argparse.ArgumentTypeError(f"{text!r} is not a {what} number{hint}") from None

    parse.__name__ = f"{what} number"
    return parse


def add_db_option(parser: argparse.ArgumentParser) -> None:
    """`--db` on a nested subcommand too (cli.py adds it to top-level commands only)."""
    parser.add_argument("--db", default=argparse.SUPPRESS, help="station database file")


def require_existing(path: str, source: str | None = "--db or $STATION_DB") -> None:
    """A command that reads the database refuses a path with no database (a mistyped --db would
    otherwise create an empty one, folders included, and report "nothing due"). ``source``: what
    named the path ("--db", "$STATION_DB"), None for the built-in default (then no typo to suspect)."""
    import os

    hint = f"mistyped {source}?" if source else "the default database, none made yet"

    if path == ":memory:" or path.startswith("file:"):
        return
    if not os.path.exists(path) and os.path.lexists(path):  # a loop of links (a link to nothing: below)
        try:
            os.stat(path)
        except FileNotFoundError:
            pass
        except OSError as exc:
            raise InputError(path, None, f"cannot open the station database: {exc.strerror or exc}") from None
    if not os.path.exists(path):
        raise InputError(
            path,
            None,
            f"no station database here ({hint}); "
            "`station devices add ID` or `station calibrate FILE --save` creates one",
        )
    if os.path.isdir(path):
        raise InputError(path, None, "is a directory, not a station database")
    if os.path.isfile(path) and os.path.getsize(path) == 0:  # SQLite would make it a database
        raise InputError(path, None, f"empty file, not a station database ({hint})")


def refuse_database_as_output(args, out: str | None, option: str) -> None:
    """Refuse an output ``out`` that is the station database (or its -wal, -shm, -journal
    file): the atomic write would replace the whole database with the export."""
    import os

    from station.cli import db_path

    if not out or out == "-":
        return
    path = db_path(args)
    if path == ":memory:" or path.startswith("file:"):
        return
    for suffix in ("", "-wal", "-shm", "-journal"):
        db_file = path + suffix
        try:
            same = os.path.samefile(out, db_file)
        except (OSError, ValueError):  # one of them does not exist (or cannot be named)
            same = False
        if same:
            what = "the station database" + (f"'s {suffix[1:]} file" if suffix else "")
            raise InputError(out, None, f"{option} is {what}: choose another name (nothing written)")


def db_error_text(exc: Exception) -> str:
    """SQLite's reason, with what 'database is locked' means here: another connection held
    the write lock for the whole busy wait, and this command wrote nothing."""
    from db.store import BUSY_TIMEOUT_S

    text = str(exc)
    if isinstance(exc, sqlite3.OperationalError) and ("locked" in text or "busy" in text):
        text += (
            f": another process held it for the whole {BUSY_TIMEOUT_S:g} s wait (another station saving, "
            "a sqlite3 shell in a transaction); nothing written, try again when it is done"
        )
    return text


@contextmanager
def open_store(args, create: bool = False):
    """The Store at `station.cli.db_path(args)`; db-layer ValueError/NotFound -> InputError.

    ``create``: make the database (and its folder) when it does not exist; otherwise a missing
    database is an InputError (exit 2), see :func:`require_existing`.
    """
    from db.store import NotFound, Store
    from station.cli import db_path, db_source

    path = db_path(args)
    if not create:
        require_existing(path, db_source(args))
    try:
        store = Store(path)
    except Exception as exc:  # sqlite3.DatabaseError, OSError: not a usable database
        raise InputError(path, None, f"cannot open the station database: {exc}") from None
    try:
        yield store
    except NotFound as exc:
        raise InputError(None, None, str(exc)) from None
    except ValueError as exc:
        raise InputError(None, None, str(exc)) from None
    except sqlite3.Error as exc:  # e.g. a read-only file or folder, a full disk
        raise InputError(path, None, f"station database: {db_error_text(exc)}") from None
    finally:
        store.close()


def require_device(store, device_id: str) -> dict:
    device = store.get_device(device_id)
    if device is None:
        raise InputError(None, None, f"no device {json.dumps(device_id, ensure_ascii=False)} in the database")
    return device


def print_json(obj) -> None:
    sys.stdout.write(json.dumps(obj, indent=2, ensure_ascii=False) + "\n")


def terminal_width() -> int:
    """The terminal's width in columns when stdout is one (``COLUMNS`` first), else 0: output
    into a pipe or a file is not wrapped."""
    return shutil.get_terminal_size((0, 0)).columns if sys.stdout.isatty() else 0


def fit_line(line: str, indent: str, width: int) -> str:
    """``indent + line``, wrapped between words at ``width`` columns (0: not wrapped), the
    continuation lines indented four columns further."""
    if width <= 0 or len(indent) + len(line) <= width:
        return indent + line
    return textwrap.fill(line, width, initial_indent=indent, subsequent_indent=indent + "    ", break_long_words=False)


def aligned(rows: list[tuple[str, ...]], indent: str = "") -> list[str]:
    """``rows`` of cells as lines, each column padded to its widest cell, two spaces between
    columns, trailing spaces dropped."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return [(indent + "  ".join(c.ljust(w) for c, w in zip(r, widths))).rstrip() for r in rows]


def fmt_num(value, digits: int = 6) -> str:
    if value is None:
        return "-"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, (int, float)):
        return f"{value:.{digits}g}"
    return str(value)


def require_writable(path: str, what_next: str) -> None:
    """InputError (one line, exit 2) for a database that a command would write only at its end
    (the TUI on Connect and on every save, the demo after its run): one that is no station
    database, or one this user may read but not write. The TUI on a read-only one started, then
    every Connect said "Cannot connect: attempt to write a readonly database" about a device
    that was fine; the demo failed after its whole run. ``what_next``: what the operator can do,
    said after the reason. A path with no database yet is made on the first save."""
    import os

    if path == ":memory:" or path.startswith("file:") or not os.path.exists(path):
        return
    from db.store import Store

    try:
        store = Store(path)
    except Exception as exc:  # noqa: BLE001 - sqlite3.DatabaseError, OSError: not a usable database
        text = f"cannot open the station database: {exc}"
        raise InputError(path, None, f"{text}; {what_next}" if "readonly" in str(exc) else text) from None
    try:
        store.check_writable()
    except sqlite3.Error as exc:
        raise InputError(path, None, f"cannot write the station database: {exc}; {what_next}") from None
    finally:
        store.close()
