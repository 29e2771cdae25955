"""Errors that reach the operator as one line and exit status 2."""

from __future__ import annotations

import math
import os


class StationError(Exception):
    """Base of every error the CLI turns into one line and exit status 2."""

    exit_status = 2


class InputError(StationError):
    """A file (or argument) that breaks the rules: `file:line: message`."""

    def __init__(self, path: str | os.PathLike | None, line: int | None, message: str):
        self.path = None if path is None else os.fspath(path)
        self.line = line
        self.message = message
        super().__init__(str(self))

    def __str__(self) -> str:
        where = [p for p in (self.path, None if self.line is None else str(self.line)) if p]
        return ":".join(where + [" " + self.message]) if where else self.message


class OutputError(StationError):
    """Standard output cannot take the result (a full disk behind ``> file``, a closed stream):
    not the input's fault, so the line names standard output."""


class UnsupportedError(StationError):
    """A valid capture that cannot support the procedure (too few positions, ...).
    ``alternative``: a method of the procedure the capture does allow (the TUI offers it)."""

    def __init__(self, *args, alternative: str | None = None) -> None:
        super().__init__(*args)
        self.alternative = alternative


# Warnings met while reading the input (an importer's "the raw topics hold 6 samples"), held until
# the command ends: printed after a result, folded into the one error line of a refusal (an
# error is one line on stderr, whatever was noticed before it).
_deferred: list[tuple[str, str]] = []


def defer_warning(where: str, text: str) -> None:
    """Hold warning ``text`` about ``where`` (the file) until the command ends (station.cli.main)."""
    _deferred.append((str(where), text))


def take_deferred_warnings() -> list[tuple[str, str]]:
    """The held (where, text) warnings, oldest first; the list is emptied."""
    out = list(_deferred)
    _deferred.clear()
    return out


def require_positive(option: str, value: float | None, unit: str = "") -> None:
    """Refuse a numeric command-line option that is not a finite positive number (0, negative,
    nan, inf) as one line; None (the option not given) passes."""
    if value is not None and not (value > 0 and math.isfinite(value)):
        raise InputError(
            None, None, f"{option} must be a positive number{' of ' + unit if unit else ''}, got {value:g}"
        )
