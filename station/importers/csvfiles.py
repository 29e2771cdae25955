"""CSV files from elsewhere: EuRoC / Kalibr IMU files, and any CSV through a column map.

EuRoC MAV (``mav0/imu0/data.csv``): one header line
``#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],a_RS_S_x [m s^-2],…``;
Kalibr (``imu0.csv`` for ``kalibr_bagcreater``): ``timestamp,omega_x,omega_y,omega_z,alpha_x,alpha_y,alpha_z``
with the same units (ns, rad/s, m/s²). The units in brackets are read, not assumed.

Plain CSV: ``--map`` names which source column holds each capture column (``t=time_s,ax=acc_x``;
a number is a 1-based column position), ``--unit`` gives the units (``accel=m/s^2,gyro=deg/s,
mag=uT,t=ms``); without a time column ``--rate HZ`` numbers the rows. Lines starting with
``#`` are skipped; the delimiter (``,`` ``;`` tab or space) is detected from the header line.
"""

from __future__ import annotations

import codecs
import csv
import itertools
import math
import re
from collections.abc import Iterator

import numpy as np

from station.capture import (
    CUT_SHORT,
    MAX_ABS,
    UNIT_ALIASES,
    UNIT_KEYS,
    nearest_column,
    no_line_end_note,
    plausible_limit,
)
from station.errors import InputError
from station.fileio import open_input
from station.importers._common import COLUMNS, NAME, Imported, Stream, set_date
from station.importers.options import TARGETS
from station.textencoding import (
    LINE_ENDS,
    MAX_LINE_BYTES,
    UTF16_BOMS,
    bom_encoding,
    check_text,
    read_chunks,
)

KIND_OF = {c: k for k, cols in COLUMNS.items() for c in cols}
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
# --unit t= spelled as people write it: read as the unit it names
TIME_ALIASES = {"sec": "s", "msec": "ms", "µs": "us", "μs": "us", "usec": "us", "nsec": "ns"}
MAX_RATE_HZ = 1e9  # the capture format's largest sample_rate_hz
SHOWN_COLUMNS = 12  # header names a refusal lists
EUROC_COLUMNS = {
    "w_RS_S_x": "gx",
    "w_RS_S_y": "gy",
    "w_RS_S_z": "gz",
    "a_RS_S_x": "ax",
    "a_RS_S_y": "ay",
    "a_RS_S_z": "az",
    "omega_x": "gx",
    "omega_y": "gy",
    "omega_z": "gz",
    "alpha_x": "ax",
    "alpha_y": "ay",
    "alpha_z": "az",
    "timestamp": "t",
}
EUROC_UNITS = {"ns": "ns", "rad s^-1": "rad/s", "m s^-2": "m/s^2"}
KALIBR_UNITS = {
    "t": "ns",
    "accel": "m/s^2",
    "gyro": "rad/s",
}  # kalibr_bagcreater's documented units
_NUMBER = re.compile(r"\s*[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?\s*")
# a decimal comma ('0,01'), as a decimal-comma locale writes numbers where ',' is not the separator
_DECIMAL_COMMA = re.compile(r"\s*[+-]?[0-9]+,[0-9]+(?:[eE][+-]?[0-9]+)?\s*")


# a number written with thousands separators: '15,032', '-1,234,567.5', '15.032,5'
_THOUSANDS = re.compile(r"\s*[+-]?[0-9]{1,3}(?:(?:,[0-9]{3})+(?:\.[0-9]*)?|(?:\.[0-9]{3})+(?:,[0-9]*)?)\s*")


_FLUSH_ROWS = 1 << 16  # parsed rows kept as Python floats before they become an array chunk


def _tail(path, n_bytes: int) -> str | None:
    """The file's last ``n_bytes`` (about) as text, enough to see how it ends: UTF-16 by its
    byte-order mark, else byte for character (its line ends and ``#`` are ASCII); None when unreadable."""
    utf16 = bom_encoding(path) == "utf-16"
    try:
        with open_input(path, "a CSV file") as f:
            head = f.read(2)
            size = f.seek(0, 2)
            start = max(0, size - n_bytes)
            f.seek(max(2, start - start % 2) if utf16 else start)
            raw = f.read()
    except (InputError, OSError):
        return None
    if utf16:  # from an even offset: whole code units
        return raw.decode("utf-16-le" if head == codecs.BOM_UTF16_LE else "utf-16-be", "replace")
    return raw.decode("latin-1")


def _ends_without_line_end(path) -> bool:
    tail = _tail(path, 1)
    return bool(tail) and tail[-1] not in ("\n", "\r")


def _cut_last_row(path, linenos: np.ndarray, warnings: list[str]) -> None:
    """Warn, as the capture reader does, when the file's last line is a data row with no line end:
    a file cut short (a copy of a log still being written, a logger killed) ends so, and its
    last value may be cut ('9.8123' read as '9.8')."""
    tail = _tail(path, MAX_LINE_BYTES + 2)
    if not tail or tail.endswith(("\n", "\r")):
        return
    last = tail[tail.rfind("\n") + 1 :].strip()
    if last and not last.startswith("#") and len(linenos):
        warnings.append(no_line_end_note(int(linenos[-1])))


def _strip_end(line: str) -> str:
    if line.endswith("\r\n"):
        return line[:-2]
    return line[:-1] if line and line[-1] in LINE_ENDS else line


def _lines(path, encoding: str = "utf-8") -> Iterator[str]:
    """The lines of a file :func:`check_text` passed, in the ``encoding`` it found, without
    their ends, as ``text.splitlines()`` of the whole decoded file gives them, read a chunk at a time."""
    decoder = codecs.getincrementaldecoder(encoding)()
    carry = ""  # an unfinished line (or one ending in "\r", whose "\n" may come next)
    start = True  # a byte order mark at the start is no text
    try:
        with open_input(path, "a CSV file") as f:
            for chunk in read_chunks(f, path, utf16=encoding == "utf-16"):
                text = decoder.decode(chunk)
                if start and text:
                    text, start = text.removeprefix("\ufeff"), False
                pieces = (carry + text).splitlines(keepends=True)
                carry = ""
                if pieces and (pieces[-1][-1] not in LINE_ENDS or pieces[-1][-1] == "\r"):
                    carry = pieces.pop()
                for piece in pieces:
                    yield _strip_end(piece)
            yield from (carry + decoder.decode(b"", final=True)).splitlines()
    except OSError as exc:
        raise InputError(path, None, f"cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise InputError(path, None, f"changed while it was read: not {encoding} text any more") from None


def _cells(path, lineno: int, text: str, delimiter: str) -> list[str]:
    """One line's fields; the csv module's own refusals (a field over its size limit, a stray
    quote in strict mode) as one line naming the line."""
    try:
        return next(csv.reader([text], delimiter=delimiter, skipinitialspace=delimiter == " "))
    except csv.Error as exc:
        raise InputError(path, lineno, f"not a CSV row: {exc}") from None


def _open_text(path) -> tuple[Iterator[tuple[int, str]], list[str]]:
    """The file's lines (no line ends) with their numbers, streamed: the whole file is never
    held; and the warnings so far (a file read as Windows-1252). InputError for what is not
    text, raised here, before any line is given."""
    encoding, note = check_text(path)
    return enumerate(_lines(path, encoding), 1), [note] if note else []


def first_line(path) -> str:
    try:
        with open_input(path) as f:
            raw = f.read(4096) if bom_encoding(path) == "utf-16" else f.readline(4096)
    except (InputError, OSError):  # the reader that follows says why
        return ""
    if raw.startswith(UTF16_BOMS):
        text = raw[: len(raw) // 2 * 2].decode("utf-16", "replace")
        return (text.splitlines() or [""])[0].strip()
    return raw.lstrip(b"\xef\xbb\xbf").decode("utf-8", "replace").strip()


def is_euroc(path) -> bool:
    """An EuRoC (``#timestamp [ns],w_RS_S_x …``) or Kalibr (``timestamp,omega_x,…``) IMU file."""
    head = [c.strip() for c in first_line(path).lstrip("#").split(",")]
    names = {re.sub(r"\s*\[.*\]$", "", c) for c in head}
    return (
        bool(head)
        and re.sub(r"\s*\[.*\]$", "", head[0]) == "timestamp"
        and ({"w_RS_S_x", "a_RS_S_x"} <= names or {"omega_x", "alpha_x"} <= names)
    )


# a missing value as other tools write it: numpy.savetxt 'nan', pandas na_rep 'NaN', R 'NA', a
# spreadsheet '#N/A', null/None; read as the empty cell it stands for
_MISSING = {"", "nan", "na", "n/a", "#n/a", "null", "none"}


def _number(path, lineno: int, name: str, cell: str) -> float:
    if not _NUMBER.fullmatch(cell):
        if cell.strip().lower() in _MISSING:
            return math.nan
        hint = ""
        if _THOUSANDS.fullmatch(cell):  # '15,032' (a spreadsheet's 1000 separator), '15.032,5'
            hint = ": a thousands separator? save the file with plain numbers (no 1000 separator)"
        raise InputError(path, lineno, f"column '{name}': {cell.strip()[:40]!r} is not a number{hint}")
    x = float(cell)
    if not math.isfinite(x):
        raise InputError(path, lineno, f"column '{name}': {cell.strip()!r} is out of range")
    return x


def _one_decimal_mark(path, lineno: int, name: str, cell: str, marks: dict[str, int]) -> str:
    """``cell`` with a decimal comma as a decimal point; a file that writes both marks is refused
    ('1.234' beside '1,5' may be a thousands separator: no way to tell)."""
    if _DECIMAL_COMMA.fullmatch(cell):
        mark, number = ",", cell.replace(",", ".")
    elif "." in cell and _NUMBER.fullmatch(cell):
        mark, number = ".", cell
    else:
        return cell
    marks.setdefault(mark, lineno)
    if len(marks) > 1:
        other = "," if mark == "." else "."
        raise InputError(
            path,
            lineno,
            f"column '{name}': {cell.strip()!r} has a decimal {'point' if mark == '.' else 'comma'} where line "
            f"{marks[other]} has a decimal {'comma' if other == ',' else 'point'}: one decimal mark per file",
        )
    return number


def _join(chunks: list[np.ndarray], dtype) -> np.ndarray:
    """``np.concatenate(chunks)`` emptying ``chunks`` as it copies: each chunk is freed once
    copied, so the column is held about once, not twice (chunks and result) at the end."""
    out = np.empty(sum(len(c) for c in chunks), dtype=dtype)
    at = 0
    chunks.reverse()  # pop from the end, first chunk first
    while chunks:
        c = chunks.pop()
        out[at : at + len(c)] = c
        at += len(c)
        del c
    return out


def _rows(
    path,
    lines: Iterator[tuple[int, str]],
    first_lineno: int,
    delimiter: str,
    ncols: int,
    cols: dict[str, int],
    int_time: str | None = None,
    iso_time: bool = False,
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Parse the data lines ``lines`` ((number, text), the first numbered ``first_lineno``):
    ``{target: values}`` and each row's line number. Rows become float64 array chunks as they
    come (``_FLUSH_ROWS`` at a time), so a large file is held once, as numbers. ``int_time``'s
    cells are whole ns, or with ``iso_time`` dates and times (:func:`_iso_ns`)."""
    done: dict[str, list] = {t: [] for t in cols if t != int_time}  # array chunks
    out: dict[str, list] = {t: [] for t in cols}
    ints: list[int] = out[int_time] if int_time else []
    line_chunks: list[np.ndarray] = []
    linenos: list[int] = []
    marks: dict[str, int] = {}  # decimal mark ('.' or ',') → the first line that uses it
    commas = delimiter != ","  # decimal commas are possible

    def flush() -> None:
        for t in done:
            done[t].append(np.asarray(out[t], dtype=np.float64))
            out[t] = []
        line_chunks.append(np.asarray(linenos, dtype=np.int64))
        linenos.clear()

    for lineno, text in lines:
        if not text.strip() or text.lstrip().startswith("#"):
            continue
        cells = _cells(path, lineno, text, delimiter)
        if len(cells) != ncols:
            message = f"{len(cells)} fields where the header has {ncols}"
            if len(cells) < ncols and next(lines, None) is None and _ends_without_line_end(path):
                message += f", on the last line, which has no line end: {CUT_SHORT}"
            raise InputError(path, lineno, message)
        for target, j in cols.items():
            if target == int_time and iso_time:  # '2024-03-01 12:00:00.010': ns since 1970, UTC
                ints.append(_iso_ns(path, lineno, target, cells[j].strip()))
            elif target == int_time:  # nanosecond integers: keep every digit (float64 would round them)
                cell = cells[j].strip()
                if not re.fullmatch(r"[+-]?[0-9]+", cell):
                    raise InputError(
                        path,
                        lineno,
                        f"column '{target}': {cell[:40]!r} is not a whole number of ns",
                    )
                ints.append(int(cell))
            else:
                cell = cells[j]
                if commas:
                    cell = _one_decimal_mark(path, lineno, target, cell, marks)
                out[target].append(_number(path, lineno, target, cell))
        linenos.append(lineno)
        if len(linenos) >= _FLUSH_ROWS:
            flush()
    flush()
    numbers = _join(line_chunks, np.int64)
    if not numbers.size:
        raise InputError(path, first_lineno, "no data rows after the header")
    values = {t: _join(chunks, np.float64) for t, chunks in done.items()}
    if int_time:
        values[int_time] = np.asarray(ints, dtype=object)
    return {t: values[t] for t in cols}, numbers


def _check_limits(path, values: dict[str, np.ndarray], linenos: np.ndarray, units: dict[str, str]) -> None:
    """Refuse a cell beyond what any sensor of its kind reports (station.capture.plausible_limit,
    in the unit the file declares), naming its line, as the capture reader would."""
    meta = {f"{kind}_unit": unit for kind, unit in units.items()}
    for target, col in values.items():
        if target not in KIND_OF:
            continue
        limit = plausible_limit(target, meta)
        if limit is None:  # raw units: any finite number (the fits' guard bounds them)
            continue
        bound, reason = limit
        with np.errstate(invalid="ignore"):
            over = np.abs(np.asarray(col, dtype=np.float64)) > bound
        if over.any():
            i = int(np.argmax(over))
            raise InputError(path, int(linenos[i]), f"column '{target}': {float(col[i]):g} is beyond {reason}")


def _unwrapped(t: np.ndarray, linenos: np.ndarray, warnings: list[str]) -> np.ndarray:
    """A logger's time stamp from a 16- or 32-bit counter (an Arduino's micros() wraps after
    71.6 min) made monotonic: each fall from near the top of the counter's range to near its
    start adds 2**bits, said in a warning. Anything else is returned as it is (and a fall is
    then refused as time going backwards)."""
    steps = np.diff(t)
    falls = np.flatnonzero(steps < 0)
    if not falls.size or not (np.all(t >= 0) and np.all(t == np.round(t))):
        return t
    for bits in (16, 32):
        wrap = 2.0**bits
        if t.max() < wrap and np.all((steps[falls] + wrap >= 0) & (steps[falls] + wrap < wrap / 2)):
            lines = ", ".join(str(int(linenos[i + 1])) for i in falls[:3]) + (" ..." if falls.size > 3 else "")
            warnings.append(
                f"the time column wraps at 2^{bits} (a {bits}-bit counter) {falls.size} time(s), "
                f"first on line {lines}: unwrapped"
            )
            return t + wrap * np.cumsum(np.r_[0, steps < 0])
    return t


# a time column's name that says its unit (time_ms, t_us, timestamp_ns, millis …)
_NAMED_TIME_UNIT = re.compile(r"(?:^|[^a-z])(ms|msec|millis|us|usec|micros|ns|nsec|nanos)(?:$|[^a-z])", re.IGNORECASE)


def _seconds_said(column: str, t_s: np.ndarray, warnings: list[str]) -> None:
    """A warning where a time column read in seconds (no ``--unit t=``) looks like another unit:
    its name says one (``time_ms``), or its median step is over a second (a bench logger in ms at
    100 Hz read as 0.1 Hz, which a calibration would take as a 3-hour record)."""
    step = float(np.median(np.diff(t_s))) if len(t_s) > 1 else 0.0
    named = _NAMED_TIME_UNIT.search(column)
    if not named and not (len(t_s) >= 20 and step > 1.0):
        return
    why = f"its name says {named.group(1)}" if named else f"a median step of {step:g} s ({1 / step:.3g} Hz)"
    warnings.append(
        f"the time column {column!r} is read in seconds, but {why}: if it is in ms, us or ns, "
        "give --unit t=ms (or t=us, t=ns)"
    )


def _time_seconds(path, t, linenos: np.ndarray, factor: float, integer: bool, warnings: list[str]) -> np.ndarray:
    """Seconds from the first row; t must not go backwards (the line that does is named); a
    wrapping counter (plain CSV) is unwrapped, with a warning (:func:`_unwrapped`)."""
    if integer:
        t0 = t[0]
        ts = np.array([(v - t0) for v in t], dtype=np.float64) * factor
    else:
        if np.isnan(t).any():
            i = int(np.flatnonzero(np.isnan(t))[0])
            raise InputError(path, int(linenos[i]), "the time column is empty (every row needs its time)")
        t = _unwrapped(t, linenos, warnings)
        ts = (t - t[0]) * factor
    if len(ts) > 1 and ts[-1] == ts[0] and not np.diff(ts).any():  # as the capture reader says it
        raise InputError(path, int(linenos[0]), f"the time axis does not advance ({len(ts)} rows, all at t = {t[0]:g})")
    back = np.flatnonzero(np.diff(ts) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise InputError(path, int(linenos[i]), "time goes backwards")
    return ts


def _streams(
    path,
    values: dict[str, np.ndarray],
    t_s: np.ndarray,
    units: dict[str, str],
    source: str,
) -> dict:
    streams = {}
    for kind, cols in COLUMNS.items():
        present = [c for c in cols if c in values]
        if not present:
            continue
        if len(present) != 3:
            raise InputError(
                None,
                None,
                f"{kind}: map all three of {', '.join(cols)} (got {', '.join(present)})",
            )
        xyz = np.empty((len(t_s), 3), dtype=np.float64)
        for j, c in enumerate(cols):  # each column freed once stacked: the samples held once
            xyz[:, j] = values.pop(c)
        streams[kind] = Stream(
            kind,
            t_s,
            xyz,
            units[kind],
            source,
            temp_c=values.get("temp_c") if kind == "accel" else None,
        )
    if not streams:
        raise InputError(path, None, "no accelerometer, gyro or magnetometer columns")
    if "temp_c" in values and "accel" not in streams:
        first = next(iter(streams.values()))
        first.temp_c = values["temp_c"]
    return streams


# ---------------------------------------------------------------------------------- EuRoC / Kalibr


def read_euroc(path, *, kinds=None) -> Imported:
    lines, warnings = _open_text(path)
    first = next(lines, None)
    if first is None:
        raise InputError(path, 1, "empty file")
    header = [c.strip() for c in first[1].lstrip("#").split(",")]
    cols: dict[str, int] = {}
    units: dict[str, str] = {}
    for j, cell in enumerate(header):
        m = re.fullmatch(r"(.*?)\s*(?:\[(.*)\])?", cell)
        name, unit = m.group(1), m.group(2)
        target = EUROC_COLUMNS.get(name)
        if target is None:
            continue
        if target in cols:
            raise InputError(
                path,
                1,
                f"two columns for {target} ('{header[cols[target]]}' and '{cell}')",
            )
        cols[target] = j
        kind = "t" if target == "t" else KIND_OF[target]
        if unit is not None:
            u = EUROC_UNITS.get(unit.strip())
            if u is None or (kind == "t") != (u == "ns"):
                raise InputError(
                    path,
                    1,
                    f"column '{cell}': unit [{unit}] is not one the station reads here "
                    f"(EuRoC writes [ns], [rad s^-1], [m s^-2])",
                )
            if units.setdefault(kind, u) != u:
                raise InputError(
                    path,
                    1,
                    f"column '{cell}': [{unit}] differs from the other {kind} columns",
                )
        else:
            units.setdefault(kind, KALIBR_UNITS[kind])
    missing = [c for c in ("t",) + COLUMNS["gyro"] + COLUMNS["accel"] if c not in cols]
    if missing:
        raise InputError(
            path,
            1,
            f"not an EuRoC/Kalibr IMU header: no column for {', '.join(missing)}",
        )
    values, linenos = _rows(path, lines, 2, ",", len(header), cols, int_time="t")
    _check_limits(path, values, linenos, units)
    _cut_last_row(path, linenos, warnings)
    first_s = int(values["t"][0]) * 1e-9
    t_s = _time_seconds(path, values.pop("t"), linenos, 1e-9, integer=True, warnings=warnings)
    meta: dict[str, str] = {}
    _epoch_date(first_s, header[cols["t"]], meta, warnings)  # EuRoC's stamps are Unix ns
    streams = _streams(path, values, t_s, units, "EuRoC/Kalibr CSV")
    if kinds is not None:
        streams = {k: s for k, s in streams.items() if k in kinds}
    return Imported(streams, meta, warnings)


# ------------------------------------------------------------------------------------- plain CSV


# Excel's first line naming the file's delimiter ('sep=;', 'sep=,', 'sep=\t' as a tab): Excel
# writes it (and reads it) where the locale's list separator would leave the file ambiguous
_SEP_LINE = re.compile(r'"?sep=([;,\t|: ])"?\1*')


def _sniff_delimiter(header: str, sep: str | None = None) -> str:
    """The line's delimiter: ``sep`` when the file's first line named one (Excel's ``sep=;``),
    else ``;`` or tab where one stands outside quotes (a decimal-comma
    locale's file: ``0,00;0,1;9,8`` is four fields, not ``0`` and ``00;0``), else ``,``, else a
    space (numpy.savetxt's default)."""
    if sep is not None:
        return sep
    bare = re.sub(r'"[^"]*"', "", header)  # a quoted field's delimiters are its text
    for d in (";", "\t", ","):
        if d in bare:
            return d
    return " "


PREAMBLE_MAX_LINES = 50  # how far below the first line a header under a logger's preamble is looked for


def _names_columns(header: list[str], mapping: dict[str, str]) -> bool:
    """Whether ``header`` is the header row for ``mapping``: it holds every source column given
    by name (a number names no header), or, with no --map, a capture column's name."""
    if not mapping:
        return any(c in TARGETS for c in header)
    named = [src for src in mapping.values() if not src.isdigit()]
    return not named or all(src in header for src in named)


def _later_header(
    path,
    lines: Iterator[tuple[int, str]],
    mapping: dict[str, str],
    skipped: list[tuple[int, str]],
    sep: str | None = None,
) -> tuple[int, str] | None:
    """(line number, text) of the first of the next PREAMBLE_MAX_LINES lines that is the header
    for ``mapping`` (lines read from ``lines``, which then goes on after it), None when none is.
    Every line read and passed over is appended to ``skipped`` (so the caller can read them
    again as data when no header is found)."""
    for lineno, text in lines:
        if lineno > PREAMBLE_MAX_LINES + 1 or not text.strip() or text.lstrip().startswith("#"):
            skipped.append((lineno, text))
            if lineno > PREAMBLE_MAX_LINES + 1:
                return None
            continue
        cells = [c.strip() for c in _cells(path, lineno, text, _sniff_delimiter(text, sep))]
        if _names_columns(cells, mapping) and _is_header(cells):
            return lineno, text
        skipped.append((lineno, text))
    return None


def _commented_header(
    path, above: tuple[int, str] | None, n_fields: int, mapping: dict[str, str], sep: str | None = None
) -> list[str] | None:
    """The column names of a ``#`` comment line directly above the first data row, as
    numpy.savetxt writes its ``header=`` (``# t ax ay az``) and numpy.genfromtxt(names=True) reads
    it: as many names as the row has fields, naming what ``--map`` asks for (without ``--map``: a
    capture column). None when the line above is none such (a comment of other words)."""
    if above is None or not above[1].lstrip().startswith("#"):
        return None
    text = above[1].lstrip()[1:].strip()
    cells = [c.strip() for c in _cells(path, above[0], text, _sniff_delimiter(text, sep))]
    if len(cells) != n_fields or not _is_header(cells) or not _names_columns(cells, mapping):
        return None
    return cells


def unknown_series_note(unknown: list[str], header_line: int) -> str:
    """The one warning line for a header's columns that are no capture column (``tmperature_C``,
    ``pressure``): not imported, with the capture name a misspelt one is closest to."""
    named = []
    for c in unknown[:SHOWN_COLUMNS]:
        near = nearest_column(c, TARGETS)
        named.append(repr(c) + (f" (did you mean {near!r}?)" if near else ""))
    more = f" (+{len(unknown) - SHOWN_COLUMNS} more)" if len(unknown) > SHOWN_COLUMNS else ""
    return (
        f"line {header_line}: column{'s' if len(unknown) > 1 else ''} {', '.join(named)}{more}: no capture column "
        f"({', '.join(TARGETS)}), not imported; --map COL=NAME takes one in"
    )


def _units_row(
    path,
    lineno: int,
    row: list[str],
    cols: dict[str, int],
    units: dict[str, str],
    row_said: dict[str, str],
    warnings: list[str],
) -> None:
    """Read a units row (``s,m/s^2,m/s^2,m/s^2`` under ``t,ax,ay,az``; ``[m/s^2]`` too) into
    ``units`` for each sensor (and ``t``) that ``--unit`` leaves unsaid; a ``--unit`` that
    differs is used, and said. A sensor's columns in different units are refused."""
    for kind in ("t", "accel", "gyro", "mag"):
        names = ["t"] if kind == "t" else [c for c in COLUMNS[kind] if c in cols]
        cells = [re.sub(r"^[\[(](.*)[\])]$", r"\1", row[cols[c]]).strip() for c in names if c in cols]
        if not cells or not any(cells):
            continue
        aliases = TIME_ALIASES if kind == "t" else UNIT_ALIASES.get(f"{kind}_unit", {})
        known = TIME_UNITS if kind == "t" else UNIT_KEYS[f"{kind}_unit"]
        said = {aliases.get(c, c) for c in cells}
        if len(said) > 1:
            raise InputError(
                path,
                lineno,
                f"units row: the {NAME.get(kind, 'time')} columns {', '.join(names)} are in different units "
                f"({', '.join(repr(c) for c in cells)}): one unit per sensor",
            )
        (unit,) = said
        if unit not in known:
            row_said[kind] = cells[0]
            continue
        given = units.get(kind)
        if given is None:
            units[kind] = unit
        elif given != unit:
            warnings.append(
                f"--unit {kind}={given} differs from the units row (line {lineno}: {unit!r} for "
                f"{', '.join(names)}): --unit used"
            )


# a date and time as pandas writes a DatetimeIndex ('2024-03-01 00:00:00.010000000'), ISO 8601
# with 'T', a zone 'Z' or '+01:00' (to the minute) or none
_ISO_TIME = re.compile(
    r"([0-9]{4}-[0-9]{2}-[0-9]{2})[T ]([0-9]{2}:[0-9]{2}:[0-9]{2}(?:\.[0-9]{1,9})?)(Z|[+-][0-9]{2}:?[0-9]{2})?"
)


def _iso_ns(path, lineno: int, name: str, cell: str) -> int:
    """ns since 1970 (UTC) of a date and time cell (:data:`_ISO_TIME`; no zone: read as UTC)."""
    m = _ISO_TIME.fullmatch(cell)
    try:
        if m is None:
            raise ValueError
        ns = int(np.datetime64(f"{m[1]}T{m[2]}", "ns").astype(np.int64))
    except ValueError:
        raise InputError(path, lineno, f"column '{name}': {cell[:40]!r} is not a date and time") from None
    zone = m[3]
    if zone and zone != "Z":  # local time at an offset: back to UTC
        sign = 1 if zone[0] == "+" else -1
        digits = zone[1:].replace(":", "")
        ns -= sign * (int(digits[:2]) * 3600 + int(digits[2:]) * 60) * 1_000_000_000
    return ns


def _is_number(cell: str) -> bool:
    return bool(_NUMBER.fullmatch(cell) or _DECIMAL_COMMA.fullmatch(cell))


def _is_header(cells: list[str]) -> bool:
    """Whether a line's (stripped) fields are column names: (almost) all of them text, at most
    one field in ten a number (a header may name a column '2'), or channels numbered as pandas
    names an array's columns (:func:`_numbered_channels`). A line of numbers with some text
    among them (``1.0,2.0,abc``: a data row with a corrupt field) is a data row, not a header."""
    filled = [c for c in cells if c and c.lower() not in _MISSING]
    numbers = sum(1 for c in filled if _is_number(c))
    return bool(filled) and (numbers * 10 <= len(filled) or _numbered_channels(cells))


# the name pandas (or a logger) gives the index column before numbered channels: a word, maybe
# with digits, dots or a unit ('time', 'time (s)', 'Unnamed: 0', 'imu1_time', 'header.stamp');
# a corrupt number ('x1.5', '9.81e') is none: it holds a decimal number, or starts with a digit
_INDEX_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_ :.\-]*(?:\s*[\[(][^\])]*[\])])?")
_DECIMAL_INSIDE = re.compile(r"[0-9]\.[0-9]|[0-9][eE][+-]?[0-9]")


def _numbered_channels(cells: list[str]) -> bool:
    """Whether a line is pandas' header of an array's numbered columns: ``,0,1,2`` (its index
    unnamed), ``time,0,1,2`` (named), ``0,1,2`` (``index=False``): the numbers 0 to n-1 in order,
    at least two of them, after one field that is empty or a name (:data:`_INDEX_NAME`), or
    none. A corrupt data row that ends in small whole numbers (``abc,1,2,3``, ``1.5x,0,1,2``,
    ``a,b,0,1``) is none: its bad field is refused on its line."""
    k = len(cells)
    while k and re.fullmatch(r"[0-9]+", cells[k - 1]):
        k -= 1
    run = [int(c) for c in cells[k:]]
    return (
        len(run) >= 2
        and run == list(range(len(run)))
        and k <= 1
        and (k == 0 or not cells[0] or (bool(_INDEX_NAME.fullmatch(cells[0])) and not _DECIMAL_INSIDE.search(cells[0])))
    )


def _data_row_refusal(path, lineno: int, cells: list[str]) -> InputError:
    """The refusal of a first line that is a data row (mostly numbers) with a field that is no
    number, where the columns are asked for by name: the field, said as a data row's would be."""
    numbers = sum(1 for c in cells if _is_number(c))
    j, bad = next((j, c) for j, c in enumerate(cells) if c and not _is_number(c) and c.lower() not in _MISSING)
    return InputError(
        path,
        lineno,
        f"field {j + 1}: {bad[:40]!r} is not a number, in a data row ({numbers} of its {len(cells)} fields are "
        "numbers, so it is no header): correct the field, or add a first line that names the columns",
    )


# a logger's preamble line that declares the sample rate ('Fs,100': the MPU-6050 logger of
# shared/data/mpu6050_unc; 'Sample rate (Hz),200', 'sampling_frequency,50')
_RATE_KEY = re.compile(
    r"(?:fs|sample[ _-]?rate|sampling[ _-]?(?:rate|frequency|freq))\s*(?:[(\[]\s*hz\s*[)\]]|_hz|hz)?", re.IGNORECASE
)


def _declared_rate(path, skipped: list[tuple[int, str]], sep: str | None = None) -> tuple[float, int, str] | None:
    """(Hz, line number, line) of the first preamble line that declares the sample rate, None
    when none does (or its value is no positive number of Hz)."""
    for lineno, text in skipped:
        cells = [c.strip() for c in _cells(path, lineno, text, _sniff_delimiter(text, sep))]
        if len(cells) >= 2 and _RATE_KEY.fullmatch(cells[0]) and _NUMBER.fullmatch(cells[1]):
            hz = float(cells[1])
            if 0 < hz <= MAX_RATE_HZ:
                return hz, lineno, text.strip()
    return None


# Unix times a time column may start at to be read as a calendar date: 1e9 s (2001-09-09) to
# 4.1e9 s (2099-12-03). A bench logger's time since power-up stays far below 1e9 s (31 years).
EPOCH_RANGE_S = (1e9, 4.1e9)


def _epoch_date(first_s: float, column: str, meta: dict[str, str], warnings: list[str]) -> None:
    """The capture's ``date`` (UTC) when the time column's first value, in seconds, is clearly a
    Unix time (:data:`EPOCH_RANGE_S`); the time axis stays relative to the first sample."""
    if EPOCH_RANGE_S[0] <= first_s <= EPOCH_RANGE_S[1]:
        set_date(meta, warnings, first_s, f"{column!r} column's Unix")


def read_plain(
    path,
    *,
    mapping: dict[str, str],
    units: dict[str, str],
    rate_hz: float | None = None,
    kinds=None,
) -> Imported:
    """A CSV with a header row, read through ``mapping`` (capture column → source column)."""
    for target in mapping:
        if target not in TARGETS:
            raise InputError(
                None,
                None,
                f"--map {target}=…: {target!r} is not a capture column (choose from {', '.join(TARGETS)})",
            )
    for key in units:
        if key not in ("t", "accel", "gyro", "mag"):
            raise InputError(None, None, f"--unit {key}=…: expected t, accel, gyro or mag")
    # the spellings a capture's own unit keys take (dps, m/s2, µT ...) name the same units here
    units = {k: (TIME_ALIASES if k == "t" else UNIT_ALIASES.get(f"{k}_unit", {})).get(v, v) for k, v in units.items()}
    t_given = "t" in units  # --unit t= (a units row may add one below)
    lines, warnings = _open_text(path)
    hi, head, above = None, "", None  # the first line that is no comment, and the line above it
    sep = None  # the delimiter a first line 'sep=;' names (Excel writes it and reads it so)
    for hi, head in lines:
        if hi == 1 and sep is None and (m := _SEP_LINE.fullmatch(head)):
            sep = m[1]
            continue
        # a row of empty cells (',,,', a spreadsheet's blank row padded to the table's width) is blank
        if head.strip(" \t,;") and not head.lstrip().startswith("#"):
            break
        above = (hi, head)
    else:
        hi = None
    if hi is None:
        raise InputError(path, 1, "empty file: no header row" + (f" under its 'sep={sep}' line" if sep else ""))
    delimiter = _sniff_delimiter(head, sep)
    header = [c.strip() for c in _cells(path, hi, head, delimiter)]
    first_data = hi + 1
    by_number = bool(mapping) and all(src.isdigit() for src in mapping.values())
    meta: dict[str, str] = {}
    declared = None  # (Hz, line, text): the sample rate a preamble line declares ('Fs,100')
    skipped: list[tuple[int, str]] = [(hi, head)]
    found = None
    numbers_only = all(_is_number(c) or c.lower() in _MISSING for c in header)
    commented = _commented_header(path, above, len(header), mapping, sep) if numbers_only else None
    # a line that holds every column --map names by name is the header, whatever its numbers
    # ('time,1,2,3' under --map t=time,ax=1,...: a logger's channels numbered from 1)
    named = [src for src in mapping.values() if not src.isdigit()]
    is_header = _is_header(header) or (bool(named) and all(src in header for src in named))
    if is_header and numbers_only and all(header):
        # '0,1,2' alone: pandas' numbered columns over its rows of floats, or a data row of whole
        # numbers ('0,1,2,3' then '1,1,2,3'): the line under it tells
        peek = next(lines, None)
        if peek is not None:
            lines = itertools.chain([peek], lines)
            under = [c.strip() for c in _cells(path, peek[0], peek[1], delimiter)]
            # '--map ax=0': a 0 is no column's position, so the numbers are names: a header
            is_header = "0" in mapping.values() or not all(re.fullmatch(r"[+-]?[0-9]+", c) for c in under)
            if not is_header:
                warnings.append(
                    f"line {hi} ({head.strip()[:40]!r}) is read as data, though its numbers run as pandas' to_csv "
                    "numbers an array's columns; if it is that header, map the columns by those numbers "
                    "(--map ax=0,...)"
                )
    if is_header and by_number and "0" not in mapping.values() and header[0] and _numbered_channels(header):
        # 'abc,0,1,2,3' under --map ax=1,ay=2,az=3: a data row with a bad first field, or pandas'
        # header of numbered columns with its index named 'abc'. --map's numbers count the file's
        # columns from 1 and none is 0 (pandas' first column), so they are no names of this line:
        # read as names they would take other columns than the ones asked for
        raise InputError(
            path,
            hi,
            f"field 1: {header[0][:40]!r} is not a number, so the line is no data row; nor is it read as pandas' "
            f"header of numbered columns (index {header[0][:40]!r}, columns 0-{len(header) - 2}), as --map's "
            "numbers have no 0: correct the field, or map by the header's names (--map ax=0,...)",
        )
    if commented is not None:
        # numpy.savetxt's header= ('# t ax ay az' above the numbers), read as numpy.genfromtxt(names=True)
        # reads it: the names of the data under it; that first data line is data
        lines = itertools.chain([(hi, head)], lines)
        header, first_data = commented, hi
        hi = above[0]
    elif not is_header:  # a data row (numbers, maybe with a bad field), not column names
        if numbers_only and not by_number:
            raise InputError(
                path,
                hi,
                f"no header row: this line holds {len(header)} numbers; name the columns by their number "
                f"(--map t=1,ax=2,... of 1-{len(header)}) or add a first line that names them",
            )
        if not numbers_only:
            # a logger's preamble ('Fs,100') above the header, or a data row with a bad field
            found = _later_header(path, lines, mapping, skipped, sep)
        if found is None and by_number:
            # no header: the columns named by their number, every line data (the first one too,
            # and those a search for a header under a preamble read)
            lines = itertools.chain(skipped, lines)
            header = [str(j + 1) for j in range(len(header))]
            first_data = hi
        elif found is None and not mapping:
            raise _data_row_refusal(path, hi, header)
        elif found is None:  # --map names a column no line of the first ones names
            numbers = sum(1 for c in header if _is_number(c))
            missing = next(((t, c) for t, c in mapping.items() if not c.isdigit() and c not in header), None)
            if missing is None:  # every name is on this line, among numbers: no header all the same
                raise _data_row_refusal(path, hi, header)
            target, source = missing
            raise InputError(
                path,
                hi,
                f"--map {target}={source}: no column {source!r}: none of the first {PREAMBLE_MAX_LINES + 1} "
                f"lines names it, and this one is no header ({numbers} of its {len(header)} fields are numbers)",
            )
    elif not _names_columns(header, mapping):
        found = _later_header(path, lines, mapping, skipped, sep)
    if found is not None:
        # a logger's preamble above the header ('Fs,100', 'Logging Type,1', ...): the header is
        # the first line that names the columns asked for; the lines above it are said, not read
        first, first_text = hi, head
        hi, head = found
        delimiter = _sniff_delimiter(head, sep)
        header = [c.strip() for c in _cells(path, hi, head, delimiter)]
        first_data = hi + 1
        warnings.append(
            f"lines {first}-{hi - 1} above the header (line {hi}) are not data: skipped "
            f"(line {first}: {first_text.strip()[:40]!r})"
        )
        declared = _declared_rate(path, skipped, sep)
    if commented is None and found is None and header != [str(j + 1) for j in range(len(header))] and numbers_only:
        warnings.append(
            f"line {hi} ({head.strip()[:40]!r}) is read as a header of numbered columns, as pandas' to_csv "
            "names an array's columns, not as data"
        )
    given = bool(mapping)
    if not mapping:  # a header that already uses the capture's names
        mapping = {c: c for c in header if c in TARGETS}
        unknown = [c for c in header if c and c not in TARGETS and not c.isdigit()]
        if mapping and unknown:  # columns the capture has no place for: said, not dropped without a word
            warnings.append(unknown_series_note(unknown, hi))
        if not mapping:
            guess: dict[str, str] = {}  # the capture column each name most likely means (acc_x: ax)
            for c in header:
                near = nearest_column(c, TARGETS) if c and "," not in c and "=" not in c else None
                if near is not None and near not in guess:
                    guess[near] = c
            example = ",".join(f"{t}={guess[t]}" for t in TARGETS if t in guess) or "t=time,ax=acc_x,ay=acc_y,az=acc_z"
            raise InputError(
                path,
                hi,
                f"no column is named like a capture column ({', '.join(TARGETS)}); its columns: "
                + ", ".join(repr(c) for c in header[:SHOWN_COLUMNS])
                + (f" (+{len(header) - SHOWN_COLUMNS} more)" if len(header) > SHOWN_COLUMNS else "")
                + f": say which is which with --map, e.g. --map {example}",
            )
    cols: dict[str, int] = {}
    for target, source in mapping.items():
        if source in header:
            same = [j + 1 for j, name in enumerate(header) if name == source]
            if len(same) > 1:
                where = f"--map {target}={source}: " if given else ""
                raise InputError(
                    path,
                    hi,
                    f"{where}{len(same)} columns are named {source!r} (columns {', '.join(map(str, same[:-1]))} "
                    f"and {same[-1]}): say which by its number, e.g. --map {target}={same[0]}",
                )
            cols[target] = header.index(source)
        elif source.isdigit() and 1 <= int(source) <= len(header):
            cols[target] = int(source) - 1
        else:
            raise InputError(
                path,
                hi,
                f"--map {target}={source}: no column {source!r} in the header ({', '.join(header)})",
            )
    # a number that is also a column's name (pandas' ',0,1,2'): the name, as the header shows it
    renamed = [
        f"{t}={src} (column {cols[t] + 1})"
        for t, src in mapping.items()
        if src.isdigit() and src in header and cols[t] != int(src) - 1
    ]
    taken: dict[int, str] = {}
    for target, j in cols.items():  # one column's samples as two quantities (gx=a,gy=a; gx=2,temp_c=a)
        if j in taken:
            raise InputError(
                path,
                hi,
                f"--map: column {header[j]!r} ({j + 1}) is given for both {taken[j]} and {target}"
                + (
                    f" (a number in --map is the column so named where the header names one: {', '.join(renamed)})"
                    if renamed
                    else ""
                ),
            )
        taken[j] = target
    if renamed:
        warnings.append(
            f"--map {', '.join(renamed)}: the header's column names, not column numbers (line {hi} names "
            "its columns by numbers)"
        )
    # a units row under the header ('t,ax,ay,az' then 's,m/s^2,m/s^2,m/s^2'): no data; its units
    # are the file's where --unit does not give them
    row_said: dict[str, str] = {}  # kind → what the units row writes for its columns, when no unit we know
    peek = next(lines, None)
    if peek is not None:
        lines = itertools.chain([peek], lines)
        row = [c.strip() for c in _cells(path, peek[0], peek[1], delimiter)] if peek[1].strip() else []
        if len(row) == len(header) and any(row) and not any(_is_number(c) for c in row):
            next(lines)
            first_data = peek[0] + 1
            _units_row(path, peek[0], row, cols, units, row_said, warnings)
    if rate_hz is not None and "t" in cols:
        raise InputError(None, None, "--rate is for a file without a time column; t is mapped (leave out one of them)")
    if declared is not None and "t" not in cols:
        hz, at, text = declared
        if rate_hz is None:  # the rate the logger declares numbers the rows
            rate_hz = hz
            warnings.append(
                f"no time column: the rows are numbered at the {hz:g} Hz line {at} declares ({text[:40]!r})"
            )
        elif not math.isclose(rate_hz, hz, rel_tol=1e-9):
            warnings.append(
                f"--rate {rate_hz:g} differs from the {hz:g} Hz line {at} declares ({text[:40]!r}): --rate used"
            )
    kinds_present = {KIND_OF[c] for c in cols if c in KIND_OF}
    # what the file leaves unsaid, all of it in one line at its header: the units of the columns
    # it has, and the time when it has no time column and no --rate
    unsaid = [kind for kind in sorted(kinds_present) if units.get(kind) is None]
    no_time = "t" not in cols and rate_hz is None
    if unsaid:
        give = ",".join(f"{kind}=UNIT" for kind in unsaid)
        allowed = "; ".join(f"{kind}: {', '.join(UNIT_KEYS[f'{kind}_unit'])}" for kind in unsaid)
        raise InputError(
            path,
            hi,
            f"the file does not say the unit of its {' and '.join(NAME[k] for k in unsaid)} columns"
            + "".join(f" (its units row: {row_said[k]!r})" for k in unsaid if k in row_said)
            + f": give --unit {give} ({allowed})"
            + ("; it has no time column either: --map t=COLUMN or the sample rate, --rate HZ" if no_time else ""),
        )
    for kind in sorted(kinds_present):
        unit = units.get(kind)
        allowed = UNIT_KEYS[f"{kind}_unit"]
        if unit not in allowed:
            raise InputError(
                None,
                None,
                f"--unit {kind}={unit}: not {'an' if kind == 'accel' else 'a'} {kind} "
                f"unit (one of {', '.join(allowed)})",
            )
    t_unit = units.get("t", "s")
    if t_unit not in TIME_UNITS:
        raise InputError(None, None, f"--unit t={t_unit}: expected one of {', '.join(TIME_UNITS)}")
    if no_time:
        raise InputError(
            path,
            hi,
            "no time column: map one (--map t=COLUMN) or give the sample rate (--rate HZ)",
        )
    if rate_hz is not None and not (0 < rate_hz <= MAX_RATE_HZ):  # the capture's sample_rate_hz takes no more
        raise InputError(
            None, None, f"--rate must be a positive number of Hz, at most {MAX_RATE_HZ:g}, got {rate_hz:g}"
        )
    iso_time = False  # the time column holds dates and times (pandas' DatetimeIndex): ns since 1970
    if "t" in cols:
        first = next(((n, x) for n, x in lines if x.strip() and not x.lstrip().startswith("#")), None)
        if first is not None:
            lines = itertools.chain([first], lines)
            row = _cells(path, first[0], first[1], delimiter)
            m = _ISO_TIME.fullmatch(row[cols["t"]].strip()) if len(row) > cols["t"] else None
            if m is not None:
                iso_time = True
                if t_given:
                    raise InputError(
                        None,
                        None,
                        f"--unit t={units['t']}: the time column holds dates and times ({m[0]!r}, line "
                        f"{first[0]}), not numbers in a unit: leave --unit t out",
                    )
                if not m[3]:
                    warnings.append(
                        f"the time column's dates and times have no time zone ({m[0]!r}, line {first[0]}): "
                        "read as UTC for the capture's date"
                    )
    values, linenos = _rows(
        path, lines, first_data, delimiter, len(header), cols, int_time="t" if iso_time else None, iso_time=iso_time
    )
    _check_limits(path, values, linenos, units)
    _cut_last_row(path, linenos, warnings)
    if iso_time:
        t_column = str(mapping.get("t", "t"))
        first_s = int(values["t"][0]) * 1e-9
        t_s = _time_seconds(path, values.pop("t"), linenos, 1e-9, integer=True, warnings=warnings)
        set_date(meta, warnings, first_s, f"{t_column!r} column's")
    elif "t" in values:
        t_column = str(mapping.get("t", "t"))
        first_s = float(values["t"][0]) * TIME_UNITS[t_unit]
        t_s = _time_seconds(path, values.pop("t"), linenos, TIME_UNITS[t_unit], integer=False, warnings=warnings)
        if "t" not in units:
            _seconds_said(t_column, t_s, warnings)
        _epoch_date(first_s, t_column, meta, warnings)
        if declared is not None and len(t_s) > 1:
            hz, at, text = declared
            step = float(np.median(np.diff(t_s)))
            if step > 0 and not math.isclose(1.0 / step, hz, rel_tol=0.05):
                warnings.append(
                    f"the time column's median step, {step:g} s ({1 / step:.4g} Hz), disagrees with the {hz:g} Hz "
                    f"line {at} declares ({text[:40]!r}): the time column is used"
                )
    else:
        t_s = np.arange(len(linenos), dtype=np.float64) / rate_hz
        if len(t_s) and not t_s[-1] <= MAX_ABS:  # the time a capture can hold (station.capture.MAX_ABS)
            raise InputError(
                None, None, f"--rate {rate_hz:g}: {len(t_s)} rows would span {t_s[-1]:g} s, beyond {MAX_ABS:g} s"
            )
    streams = _streams(
        path,
        values,
        t_s,
        units,
        "CSV " + ", ".join(f"{k}={v}" for k, v in mapping.items()),
    )
    if kinds is not None:
        streams = {k: s for k, s in streams.items() if k in kinds}
    return Imported(streams, meta, warnings)
