"""Capture files: read, validate and write the station's CSV format (../shared/spec/capture-format.md).

A capture is ``# key: value`` metadata lines (the first is ``# station-capture: 1``), one header
row of column names, then comma-separated data rows. Numeric columns become float64 arrays
(an empty field is NaN); the text column ``position`` becomes an object array of ``str``
(``''`` where empty).

Every rule the reader enforces is reported as one :class:`~station.errors.InputError`
``file:line: what is wrong``, with ``line`` the 1-based physical line of the file.

Reading streams: the data are parsed in blocks of rows (numpy's C parser on each block, with a
per-cell pass over a block only when it needs one: missing values, non-ASCII text, or an error
whose line must be named), and each column grows block by block, so a large file is never held
as text or as Python objects all at once.

Writing is atomic (a temporary file in the same folder, then ``os.replace``) and refuses any
capture that the reader would refuse or could not give back exactly: ``read_capture(p)`` after
``write_capture(p, c)`` equals ``c`` (floats are written with ``repr``, which round-trips bit
for bit; integer-valued floats are written without the ``.0``).
"""

from __future__ import annotations

import codecs
import datetime as _dt
import io
import math
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from solvers.units import ACCEL_UNITS, GYRO_UNITS, MAG_UNITS, RAW_UNITS
from station.errors import InputError
from station.fileio import atomic_open, cannot_write, log_kind, looks_utf16, open_input
from station.procedures import registry

FORMAT_VERSION = "1"
TEXT_COLUMNS = frozenset({"position"})
GYRO_MODES = ("reference", "static")

# Units each raw-unit key accepts: the raw ones (a calibration supplies the factor) and the
# physical ones solvers/units.py knows.
_RAW_ORDER = ("V", "mV", "counts")
UNIT_KEYS: dict[str, tuple[str, ...]] = {
    "accel_unit": _RAW_ORDER + tuple(ACCEL_UNITS),
    "gyro_unit": _RAW_ORDER + tuple(GYRO_UNITS),
    "mag_unit": _RAW_ORDER + tuple(MAG_UNITS),
}
assert set(_RAW_ORDER) == set(RAW_UNITS)
KNOWN_UNITS = frozenset(u for units in UNIT_KEYS.values() for u in units)
_UNIT_KIND = {"accel_unit": "an acceleration", "gyro_unit": "an angular-rate", "mag_unit": "a magnetic-field"}
# Other spellings of the same units that other tools write (micro sign or Greek mu, m/s2,
# dps, ...): read as the unit they name; a written capture uses the names above.
UNIT_ALIASES: dict[str, dict[str, str]] = {
    "accel_unit": {"m/s2": "m/s^2", "m/s²": "m/s^2", "m/s/s": "m/s^2", "m s^-2": "m/s^2", "ms^-2": "m/s^2"},
    "gyro_unit": {
        "dps": "deg/s",
        "deg/sec": "deg/s",
        "°/s": "deg/s",
        "rad/sec": "rad/s",
        "rad s^-1": "rad/s",
        "deg/hr": "deg/h",
        "°/h": "deg/h",
        "dph": "deg/h",
    },
    "mag_unit": {"µT": "uT", "μT": "uT", "Gauss": "gauss", "Gs": "gauss", "mGauss": "mgauss", "milligauss": "mgauss"},
}

# Metadata keys that must hold a finite number, with an optional validity check.
_NUMERIC_META: dict[str, tuple] = {
    "latitude_deg": (lambda x: -90.0 <= x <= 90.0, "must be between -90 and 90"),
    "longitude_deg": (lambda x: -180.0 <= x <= 360.0, "must be between -180 and 360"),
    "altitude_m": (lambda x: -12000.0 <= x <= 1.0e6, "must be between -12000 and 1000000 (m above the ellipsoid)"),
    "g_mps2": (lambda x: 0.0 < x <= 1000.0, "must be positive and at most 1000 m/s^2"),
    "radius_m": (lambda x: 0.0 < x <= 1.0e4, "must be positive and at most 10000 m"),
    "heading_deg": (lambda x: -360.0 <= x <= 720.0, "must be between -360 and 720"),
    "sample_rate_hz": (lambda x: 0.0 < x <= 1.0e9, "must be positive and at most 1e9"),
}
# A device id is shown by every command, stored in the database and named in the firmware files:
# an ESC sequence or a newline in it is a corrupt or hostile file (station.importers.load says the
# same of `station import --device`).
DEVICE_TEXT_RULE = "a capture's device cannot hold a control character or spaces at its ends"
# The metadata keys capture-format.md defines (those _check_meta checks); one in other letter
# case is read as it.
SPEC_KEYS = frozenset({"procedure", "device", "date", "gyro_mode", *UNIT_KEYS, *_NUMERIC_META})

# Units shown by `station inspect` for the columns the spec names.
COLUMN_UNITS = {
    "t": "s",
    "temp_c": "°C",
    "speed_rad_s": "rad/s",
    "ref_gx": "rad/s",
    "ref_gy": "rad/s",
    "ref_gz": "rad/s",
    "vl1": "m/s",
    "vl2": "m/s",
    "vl3": "m/s",
    "vx": "m/s",
    "vy": "m/s",
    "vz": "m/s",
    "vn": "m/s",
    "ve": "m/s",
    "vd": "m/s",
    "roll_deg": "deg",
    "pitch_deg": "deg",
    "yaw_deg": "deg",
    "wx": "rad/s",
    "wy": "rad/s",
    "wz": "rad/s",
    "heading_deg": "deg",
    "n": "samples",
    "position": "label",
}
_RAW_COLUMN_UNIT_KEY = {
    c: k
    for k, cols in (("accel_unit", "ax ay az"), ("gyro_unit", "gx gy gz"), ("mag_unit", "mx my mz"))
    for c in cols.split()
}
# The columns capture-format.md names, and the station's own: P2's `elapsed_s` (a table's hold
# times, written by `station simulate`, read by P2's diagnosis) and `rate_gyro_rad_s` (the P2
# guide's rate gyro), `station record`'s `segment` (docs/protocol.md); a table of averages may
# also hold `<col>_std` of each.
SPEC_COLUMNS = frozenset({*COLUMN_UNITS, *_RAW_COLUMN_UNIT_KEY, "elapsed_s", "segment", "rate_gyro_rad_s"})


def unknown_table_columns(header: list[str]) -> list[str]:
    """The columns of a capture (a table of averages, or a time series: QA s26d) that
    capture-format.md does not name (nor their `<col>_std`): read and then used by nothing, so
    said (``tmperature_C`` for ``temp_c``), not ignored without a word. The spec keeps unknown metadata keys and ignores
    them; it does not make an unknown column an error, so this is a warning."""
    return [
        c
        for c in header
        if c
        and c not in SPEC_COLUMNS
        and not (c.endswith("_std") and c[:-4] in SPEC_COLUMNS and c[:-4] not in ("position", "n"))
    ]


# The names loggers, spreadsheets and libraries give the capture's columns (imucal's acc_x and
# gyr_x, EuRoC's w_RS_S_x, ROS's angular_velocity.x, a bench's temperature): a column named
# near one of them is taken to mean that capture column by :func:`nearest_column`.
COLUMN_ALIASES = {
    "t": ("time", "timestamp", "times", "stamp", "seconds", "elapsed"),
    "temp_c": ("temp", "temperature", "tmp", "imu_temp", "temp_degc", "temperature_degc", "die_temp"),
    **{
        f"{p}{a}": tuple(f"{w}{sep}{a}" for w in words for sep in ("_", "", ".", " "))
        for p, words in (
            ("a", ("acc", "accel", "acceleration", "accelerometer", "linear_acceleration", "a")),
            ("g", ("gyr", "gyro", "omega", "angular_velocity", "rate", "w", "g")),
            ("m", ("mag", "magn", "magnetometer", "magnetic_field", "m")),
        )
        for a in "xyz"
    },
}
# a unit at a column name's end ('_C', '_degC', ' (m/s^2)', '[uT]', '_mps2', '_dps'): left out
# before names are compared, as the capture's names carry none but temp_c's
_UNIT_SUFFIX = re.compile(
    r"(?:\s*[\[(][^\])]*[\])]|[_ .-]?(?:c|degc|°c|k|s|ms|us|ns|sec|g|mg|mps2|ms2|m_s2|m/s\^?2|m_s|mps|m/s|dps|degps|"
    r"deg_s|rads|rad_s|rad/s|ut|nt|mt|gauss|mgauss|v|mv|counts|raw|lsb))$",
    re.IGNORECASE,
)


def _name_key(name: str) -> str:
    """A column name as :func:`nearest_column` compares it: lower case, its unit left out."""
    key = name.strip().lower()
    for _ in range(2):  # 'acc_x_mps2 (m/s^2)': both
        bare = _UNIT_SUFFIX.sub("", key)
        if not bare:
            break
        key = bare
    return key


def nearest_column(name: str, columns) -> str | None:
    """The capture column (one of ``columns``) that ``name`` most likely means, or None:
    ``tmperature_C`` → ``temp_c``, ``acc_x_mps2`` → ``ax``, ``axx`` → ``ax``. The name, its unit
    suffix left out, is compared (difflib's ratio) with each column and each of its
    :data:`COLUMN_ALIASES`, so a misspelt long name meets the long name it misspells."""
    import difflib

    key = _name_key(name)
    candidates: dict[str, str] = {}
    for c in columns:
        for spelling in (c, _name_key(c), *COLUMN_ALIASES.get(c, ())):
            candidates.setdefault(spelling.lower(), c)
    if key in candidates:
        return candidates[key]
    near = difflib.get_close_matches(key, list(candidates), n=1, cutoff=0.75)
    return candidates[near[0]] if near else None


def unknown_columns_note(unknown: list[str], header_line: int | None = None, *, series: bool = False) -> str:
    """The one warning line for :func:`unknown_table_columns`, with the spec's name a misspelt
    one is closest to (:func:`nearest_column`)."""
    names = sorted(SPEC_COLUMNS | {f"{n}_std" for n in SPEC_COLUMNS - {"position", "n"}})
    named = []
    for c in unknown:
        near = nearest_column(c, names)
        named.append(repr(c) + (f" (did you mean {near!r}?)" if near else ""))
    where = f"line {header_line}: " if header_line is not None else ""
    kind = "time series" if series else "table of averages"
    return (
        f"{where}column{'s' if len(unknown) > 1 else ''} {', '.join(named)} of this {kind}: "
        f"no column of a capture (capture-format.md), ignored"
    )


# Plausibility bounds: magnitudes beyond these no sensor of the kind reports, so a cell beyond
# one is refused on its line (a corrupt or hostile file, not a measurement). Each is a large
# multiple of the widest full-scale range of any part of the kind: accelerations up to
# 1e7 m/s^2 (about 1e6 g; shock accelerometers reach 200 000 g), angular rates up to
# 1e4 rad/s (about 570 000 deg/s; MEMS gyros reach 20 000 deg/s), magnetic fields up to
# 1e10 nT (10 T; 3-D Hall sensors reach 0.3 T), velocities up to 1e5 m/s. In SI; a column in
# another physical unit is bounded by the same quantity in its unit (gyro_unit: deg/s gives
# 5.7e5 deg/s). The reader applies them (a file that breaks one is refused on its line); raw
# units (V, mV, counts), angles, time and unknown columns have none there: any finite number
# reads, and the numerics' guard (station.guard) bounds them by MAX_ABS.
PLAUSIBLE_SI = {"accel": 1e7, "gyro": 1e4, "mag": 1e10, "velocity": 1e5}
# temp_c, °C: no thermometer reads below absolute zero, and none on a sensor above 1e4 °C (hotter
# than the Sun's surface; parts are rated to 125-200 °C, a thermocouple to 1800 °C). A cell beyond
# either is refused on its line, as one beyond PLAUSIBLE_SI.
ABSOLUTE_ZERO_C = -273.15
TEMP_MAX_C = 1e4
# Largest magnitude of any other numeric cell: raw counts (32-bit), Unix time in ns (1.7e18)
# fit; 1e20 squared is 1e40 and the fourth powers some fits form stay far from float64's 1.8e308.
MAX_ABS = 1e20
# A table of averages (capture-format.md: per-position means, ``n`` samples averaged, ``<col>_std``
# their standard deviation) gives the noise every fit weighs its positions by (P1, P2:
# sigma = std / sqrt(n)). Numbers no hold can have are refused on their line, not weighed:
# - n: a whole number, 1 to 1e9 samples (1e9 is 11.6 days of a hold at 1 kHz, 2.8 h at 100 kHz).
# - <col>_std: finite, 0 or more, within the column's plausibility bound (PLAUSIBLE_SI, in its
#   unit), and at most STD_OVER_MEAN times the largest |mean| of its quantity in the table: the
#   column's, or the largest of its triad (ax ay az, ...), since one axis may lie level in every
#   position and average near 0 while its noise is the triad's. A hold is still and its samples
#   lie within the sensor's range, so its spread is of the order of the signal at most (16 times
#   it for a +-16 g part resting at 1 g); 1e3 times it holds for any unit (m/s^2, g, V with its
#   offset, counts) and leaves the rest to the fit. A table whose means are all 0 has no scale, and
#   a _std column without its mean column nothing to compare: only the first two rules apply.
MAX_N_SAMPLES = 1e9
STD_OVER_MEAN = 1e3
_TRIADS = {
    c: tuple(t.split())
    for t in (
        "ax ay az",
        "gx gy gz",
        "mx my mz",
        "ref_gx ref_gy ref_gz",
        "vl1 vl2 vl3",
        "vx vy vz",
        "vn ve vd",
        "wx wy wz",
    )
    for c in t.split()
}
_KIND_WORDS = {"accel": "accelerometer", "gyro": "gyro", "mag": "magnetometer", "velocity": "velocity sensor"}
_FIXED_UNIT_KIND = {"rad/s": ("gyro", 1.0), "m/s": ("velocity", 1.0)}


def plausible_limit(name: str, meta: dict[str, str]) -> tuple[float, str] | None:
    """The largest magnitude a column ``name`` in a physical unit (under metadata ``meta``) can
    hold and why: ``(bound, reason)``, the reason ready for "... is beyond {reason}"
    (PLAUSIBLE_SI); None for a column without a physical unit."""
    from solvers.units import si_factor

    base = name[:-4] if name.endswith("_std") else name
    key = _RAW_COLUMN_UNIT_KEY.get(base)
    kind = factor = unit = None
    if key is not None:
        unit = meta.get(key) or None
        kind = key[: -len("_unit")]
        factor = si_factor(kind, unit) if unit in UNIT_KEYS[key] else None
    elif COLUMN_UNITS.get(base) in _FIXED_UNIT_KIND:
        unit = COLUMN_UNITS[base]
        kind, factor = _FIXED_UNIT_KIND[unit]
    if not factor:
        return None
    bound = PLAUSIBLE_SI[kind] / factor
    return bound, f"what any {_KIND_WORDS[kind]} reports (magnitudes up to {bound:.3g} {unit} are accepted)"


def column_unit(name: str, meta: dict[str, str]) -> str | None:
    """The unit of column ``name`` under metadata ``meta`` (raw columns: its ``*_unit``), or None."""
    base = name[:-4] if name.endswith("_std") else name
    key = _RAW_COLUMN_UNIT_KEY.get(base)
    if key is not None:
        return meta.get(key) or None
    return COLUMN_UNITS.get(base)


class WideStd:
    """The STD_OVER_MEAN rule over a table read in chunks of rows (the streaming reader) or
    whole (the reader's result, the writer's capture): :meth:`add` each chunk in row order,
    then :meth:`first` is what :func:`wide_std` says of the whole table.

    The bound depends on the whole table (the largest |mean| of each triad), so a row is judged
    only at the end. A row can be the first over the final bound only if its std is above every
    std before it in its column and above the bound so far (the bound only grows): only such
    rows are kept, and a growing bound drops them again (a table within the rule keeps none)."""

    def __init__(self, names, meta: dict[str, str]) -> None:
        names = [n for n in names if n not in TEXT_COLUMNS]
        self.meta = meta
        self.rows = 0
        self.groups = {
            n: [c for c in _TRIADS.get(n[:-4], (n[:-4],)) if c in names] for n in names if n.endswith("_std")
        }
        self.scale = dict.fromkeys(self.groups, 0.0)
        self.top = dict.fromkeys(self.groups, -math.inf)  # the largest std so far
        self.kept: dict[str, tuple[np.ndarray, np.ndarray]] = {
            n: (np.empty(0, np.int64), np.empty(0)) for n in self.groups
        }

    def add(self, chunk: dict[str, np.ndarray]) -> None:
        """The next rows of the table (every column of the table, in row order)."""
        size = 0
        for name, group in self.groups.items():
            for c in group:
                m = np.abs(np.asarray(chunk[c], dtype=np.float64))
                m = m[np.isfinite(m)]
                if m.size:
                    self.scale[name] = max(self.scale[name], float(m.max()))
            std = np.asarray(chunk[name], dtype=np.float64)
            size = len(std)
            before = np.fmax.accumulate(np.concatenate(([self.top[name]], std)))
            self.top[name] = float(before[-1])
            with np.errstate(invalid="ignore"):
                new = np.flatnonzero(std > before[:-1])  # above every std before it
            rows, values = self.kept[name]
            rows = np.concatenate((rows, new + self.rows))
            values = np.concatenate((values, std[new]))
            if self.scale[name] > 0:
                keep = values > STD_OVER_MEAN * self.scale[name]
                rows, values = rows[keep], values[keep]
            self.kept[name] = (rows, values)
        self.rows += size

    def first(self) -> tuple[int, str, str] | None:
        """The first row (0-based, in row order; of several columns the leftmost) whose
        ``<col>_std`` is more than STD_OVER_MEAN times the largest |mean| of its quantity in the
        table: ``(row, column, what is wrong)``; None when there is none."""
        first = None
        for name, group in self.groups.items():
            scale = self.scale[name]
            rows, values = self.kept[name]
            if not scale > 0 or not rows.size:
                continue
            over = np.flatnonzero(values > STD_OVER_MEAN * scale)
            if over.size and (first is None or rows[over[0]] < first[0]):
                unit = column_unit(name, self.meta)
                unit = f" {unit}" if unit and unit != "samples" else ""
                first = (
                    int(rows[over[0]]),
                    name,
                    f"{float(values[over[0]]):g}{unit} is more than {STD_OVER_MEAN:g} times the largest magnitude of "
                    f"{', '.join(group)} in the table ({scale:.4g}{unit}): no still hold spreads that wide "
                    "(a standard deviation in another unit?)",
                )
        return first


def wide_std(columns: dict[str, np.ndarray], meta: dict[str, str]) -> tuple[int, str, str] | None:
    """:meth:`WideStd.first` of the whole table ``columns``."""
    check = WideStd(list(columns), meta)
    check.add(columns)
    return check.first()


def column_limit(name: str, meta: dict[str, str]) -> tuple[float, str]:
    """:func:`plausible_limit`, else the generic ``MAX_ABS`` (the numerics' guard)."""
    return plausible_limit(name, meta) or (
        MAX_ABS,
        f"what any instrument reports (magnitudes up to {MAX_ABS:g} are accepted)",
    )


# A number as the format writes it: no nan/inf words, no underscores, no hex.
_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_NONFINITE_WORDS = {"nan", "inf", "infinity"}
# how other tools write a missing value (R's NA, a spreadsheet's #N/A, null/None): refused as 'nan' is
_MISSING_WORDS = {"na", "n/a", "#n/a", "null", "none"}
# Bytes the numpy fast path may see: printable ASCII, tab, LF. Anything else takes the per-cell path.
_FAST_BYTES = bytes(range(0x20, 0x7F)) + b"\t\n"
_LABEL_WIDTH = 32  # fixed width of the text field in the fast path; longer labels take the slow path
_MAX_HEAD_LINE = 1 << 20
# Metadata lines a head may hold: real captures hold tens to a few hundred (the firmware
# parameters in use); a file of millions (40 MB: a minute, 1 GB of memory) is no capture.
MAX_META_LINES = 65536
_MAX_DATA_LINE = 1 << 20  # a data line longer than this is refused (no capture row is 1 MiB)
BLOCK_BYTES = 8 << 20  # the reader's text budget: a block is at most this plus one line
DEFAULT_CHUNK_ROWS = 65536
# t's rate / the stated sample_rate_hz: beyond both ways of reading t, the file contradicts itself
RATE_AGREEMENT = (0.8, 1.25)


# ------------------------------------------------------------------------------------ Capture


@dataclass(eq=False)
class Capture:
    """One capture: metadata (file order) and columns (header order).

    ``meta``: ``dict[str, str]`` with keys and values stripped, ``'station-capture'`` included.
    ``columns``: name -> float64 array (NaN = empty field), or for ``position`` an object array
    of ``str`` (``''`` = empty). ``meta_lines`` / ``header_line`` give the file's line numbers
    (for messages) when the capture was read from a file.
    """

    meta: dict[str, str]
    columns: dict[str, np.ndarray]
    path: str | None = None
    meta_lines: dict[str, int] = field(default_factory=dict, repr=False)
    header_line: int | None = field(default=None, repr=False)
    # what the reader noticed but did not refuse (a last line without its line end): said by
    # the commands as warnings; not part of the capture (equality, writing)
    notes: list[str] = field(default_factory=list, repr=False)

    @property
    def procedure(self) -> str | None:
        return self.meta.get("procedure") or None

    @property
    def is_time_series(self) -> bool:
        return "t" in self.columns

    @property
    def n_rows(self) -> int:
        for arr in self.columns.values():
            return int(len(arr))
        return 0

    def column(self, name: str) -> np.ndarray:
        """The column ``name``; a missing column is an InputError naming the file."""
        try:
            return self.columns[name]
        except KeyError:
            have = ", ".join(self.columns) or "none"
            raise InputError(self.path, self.header_line, f"no column '{name}' (columns: {have})") from None

    def float_meta(self, key: str, default: float | None = None) -> float | None:
        """Metadata ``key`` as a finite float, ``default`` when absent; InputError when not a number."""
        value = self.meta.get(key)
        if value is None:
            return default
        number = _meta_number(value)
        if number is None:
            raise InputError(self.path, self.meta_lines.get(key), f"metadata '{key}': {_show(value)} is not a number")
        return number

    def float_meta_within(self, key: str, default: float | None, high: float, *, zero: bool = False) -> float | None:
        """:meth:`float_meta` that must also be positive (or, with ``zero``, zero too) and at most
        ``high``, else an InputError on its line: a procedure's own key (``heading_sigma_deg``,
        ``accuracy_deg_h``) whose value no bench could mean (a negative 1-sigma, a zero scale)."""
        x = self.float_meta(key)
        if x is None:
            return default
        if not ((x > 0 or (zero and x == 0)) and x <= high):
            sign = "zero or positive" if zero else "positive"
            raise InputError(
                self.path,
                self.meta_lines.get(key),
                f"metadata '{key}': {_show(self.meta[key])} must be {sign} and at most {high:g}",
            )
        return x

    def series_rate_hz(self, consequence: str) -> float | None:
        """The sample rate of a time series (Hz): metadata ``sample_rate_hz`` where the ``t``
        column agrees with it, else ``t``'s median step; None when neither gives a rate.

        A stated rate that ``t`` contradicts is an InputError on its metadata line, ending with
        ``consequence`` (what the rate scales). Both the median step (not fooled by gaps) and
        rows over the duration (not fooled by bursty host time stamps) must disagree beyond
        RATE_AGREEMENT for the file to contradict itself."""
        stated = self.float_meta("sample_rate_hz")
        t = np.asarray(self.columns.get("t", ()), dtype=np.float64)
        t = t[np.isfinite(t)]
        steps = np.diff(t)
        median = float(np.median(steps)) if steps.size else 0.0
        span = float(t[-1] - t[0]) if t.size else 0.0
        if stated is not None and stated > 0:
            if span > 0:
                by_rows = (len(t) - 1) / span
                rates = [by_rows] + ([1.0 / median] if median > 0 else [])
                low, high = RATE_AGREEMENT
                if all(not low <= r / stated <= high for r in rates):
                    raise InputError(
                        self.path,
                        self.meta_lines.get("sample_rate_hz"),
                        f"metadata 'sample_rate_hz': {stated:g} Hz, but the t column holds {by_rows:.6g} rows per "
                        f"second ({len(t)} rows over {span:g} s): correct sample_rate_hz or t ({consequence})",
                    )
            return stated
        return 1.0 / median if median > 0 else None

    def local_gravity_mps2(self, warnings: list[str]) -> float:
        """Local gravity for this capture, one policy for every procedure: metadata ``g_mps2``
        (refused outside 9.7–9.9 m/s², citing its line), else normal gravity at
        ``latitude_deg`` and ``altitude_m`` (``solvers.frames.normal_gravity_mps2``), else
        standard gravity with a warning appended to ``warnings``."""
        from solvers import frames

        g = self.float_meta("g_mps2")
        if g is not None:
            if not 9.7 < g < 9.9:
                raise InputError(self.path, self.meta_lines.get("g_mps2"), f"g_mps2 {g} m/s^2 is not a local gravity")
            return g
        lat = self.float_meta("latitude_deg")
        if lat is not None:
            return frames.normal_gravity_mps2(lat, self.float_meta("altitude_m", 0.0))
        warnings.append(
            "no g_mps2 and no latitude_deg: using standard gravity 9.80665 m/s^2 (local g differs by up "
            "to 0.3 %, which goes straight into the scale factors)"
        )
        return frames.G_STANDARD_MPS2

    def unit(self, name: str) -> str | None:
        """The unit of column ``name`` (raw columns: the capture's ``*_unit``), or None if unknown."""
        return column_unit(name, self.meta)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Capture):
            return NotImplemented
        if list(self.meta.items()) != list(other.meta.items()) or list(self.columns) != list(other.columns):
            return False
        return all(_same_array(self.columns[k], other.columns[k]) for k in self.columns)


def _same_array(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    text_a, text_b = a.dtype.kind in "OUS", b.dtype.kind in "OUS"
    if a.shape != b.shape or text_a != text_b:
        return False
    if text_a:
        return a.tolist() == b.tolist()
    nan = np.isnan(a)  # a NaN's sign is not kept: the file has only empty fields
    return bool(
        np.array_equal(nan, np.isnan(b))
        and np.array_equal(a[~nan], b[~nan])
        and np.array_equal(np.signbit(a[~nan]), np.signbit(b[~nan]))
    )


# ----------------------------------------------------------------------------- small helpers


def fill_missing(values, x=None) -> np.ndarray:
    """A slowly varying column (``temp_c``) with a few empty fields (missing values,
    capture-format.md): each missing value linearly interpolated over ``x`` (time; the row
    order when None) from its finite neighbours, the nearest one at the ends. With no finite
    value, or none missing, the column is returned as it is."""
    v = np.asarray(values, dtype=float)
    ok = np.isfinite(v)
    if ok.all() or not ok.any():
        return v
    xs = np.arange(len(v), dtype=float) if x is None else np.asarray(x, dtype=float)
    if not np.all(np.isfinite(xs)):
        xs = np.arange(len(v), dtype=float)
    order = np.argsort(xs[ok], kind="stable")
    out = v.copy()
    out[~ok] = np.interp(xs[~ok], xs[ok][order], v[ok][order])
    return out


def span_step_s(t) -> float | None:
    """The mean step of a time column over its span, ``(t_last − t_first) / (rows − 1)`` over its
    finite values: the sample step where coarse stamps (whole seconds, host clock ticks; ``t``
    may repeat, capture-format.md) make the median step 0. None with fewer than two finite
    times or no span."""
    t = np.asarray(t, dtype=float)
    t = t[np.isfinite(t)]
    if len(t) < 2 or not t[-1] > t[0]:
        return None
    return float(t[-1] - t[0]) / (len(t) - 1)


def strictly_increasing_t(t) -> np.ndarray:
    """``t`` for algorithms that need strictly increasing times (the stillness detector).

    capture-format.md lets ``t`` repeat (non-decreasing): coarse stamps (whole seconds, host
    clock ticks) give many rows one value. Each run of equal stamps is spread evenly over the
    tick to the next stamp (the last run at the previous run's step), so gaps stay where they
    are. A ``t`` that already increases, or that is not finite and non-decreasing, is returned
    as it is (the caller's own check names the problem)."""
    t = np.asarray(t, dtype=float)
    if len(t) < 2 or not np.all(np.isfinite(t)):
        return t
    d = np.diff(t)
    if np.all(d > 0) or np.any(d < 0):
        return t
    starts = np.flatnonzero(np.r_[True, d > 0])
    lengths = np.diff(np.r_[starts, len(t)])
    if len(starts) < 2:
        return t
    step = np.diff(t[starts]) / lengths[:-1]
    step = np.r_[step, step[-1]]
    run = np.repeat(np.arange(len(starts)), lengths)
    return t[starts][run] + (np.arange(len(t)) - starts[run]) * step[run]


def _show(value: str, limit: int = 40) -> str:
    """A field value quoted for a message: 'abc', or repr() when it holds odd characters."""
    if len(value) > limit:
        value = value[:limit] + "…"
    return f"'{value}'" if value.isprintable() and "'" not in value else repr(value)


def _meta_number(value: str) -> float | None:
    v = value.strip()
    if not _NUMBER.fullmatch(v):
        return None
    x = float(v)
    return x if math.isfinite(x) else None


def _looks_numeric(text: str) -> bool:
    return bool(_NUMBER.fullmatch(text.strip(" \t")))


def _check_meta(path, meta: dict[str, str], lines: dict[str, int]) -> None:
    """Known metadata keys hold valid values (procedure, units, numbers, date, gyro_mode); of
    several bad lines, the first in the file is named."""
    problems: list[tuple[str, str]] = []

    def bad(key: str, message: str) -> None:
        problems.append((key, message))

    proc = meta.get("procedure")
    if proc is not None and registry.get(proc) is None:
        bad("procedure", f"unknown procedure {_show(proc)} (expected one of {', '.join(registry.names())})")
    for key, allowed in UNIT_KEYS.items():
        unit = meta.get(key)
        if unit is None or unit in allowed:
            continue
        if unit in KNOWN_UNITS:
            bad(key, f"{key} {_show(unit)} is not {_UNIT_KIND[key]} unit (expected one of {', '.join(allowed)})")
        else:
            bad(key, f"unknown {key} {_show(unit)} (expected one of {', '.join(allowed)})")
    for key, (ok, why) in _NUMERIC_META.items():
        if key not in meta:
            continue
        x = _meta_number(meta[key])
        if x is None:
            bad(key, f"metadata '{key}': {_show(meta[key])} is not a number")
        elif ok is not None and not ok(x):
            bad(key, f"metadata '{key}': {_show(meta[key])} {why}")
    if "date" in meta:
        try:
            _dt.datetime.fromisoformat(meta["date"])
        except ValueError:
            bad("date", f"metadata 'date': {_show(meta['date'])} is not an ISO date (YYYY-MM-DD[THH:MM:SS])")
    mode = meta.get("gyro_mode")
    if mode is not None and mode not in GYRO_MODES:
        bad("gyro_mode", f"unknown gyro_mode {_show(mode)} (expected one of {', '.join(GYRO_MODES)})")
    if problems:
        order = [(lines.get(key) is None, lines.get(key) or 0, i) for i, (key, _) in enumerate(problems)]
        key, message = problems[min(range(len(problems)), key=order.__getitem__)]
        raise InputError(path, lines.get(key), message)


def _unquoted(field: str) -> str:
    """A field without CSV's quotes around it ('"x_up"' → 'x_up', as csv.writer's QUOTE_NONNUMERIC or
    R's write.table write text); a field with a quote inside is left as it is (and refused)."""
    if len(field) >= 2 and field[0] == '"' == field[-1] and '"' not in field[1:-1]:
        return field[1:-1].strip()
    return field


def _header_problem(names: list[str]) -> str | None:
    """What is wrong with a header row (already split and stripped), or None."""
    if len(names) == 1:  # one name: the columns may be separated by something else than commas
        for sep, said in ((";", "';' (semicolons)"), ("\t", "tabs")):
            if len([n for n in names[0].split(sep) if n.strip()]) > 1:
                return (
                    f"the header's columns are separated by {said}: a capture's are separated by commas, "
                    "with '.' as the decimal mark"
                    # a spreadsheet's "Text (tab delimited)" / "Unicode Text": the way out, in the same line
                    + (" (save it from the spreadsheet as 'CSV (comma delimited)')" if sep == "\t" else "")
                )
    seen: dict[str, int] = {}
    for j, name in enumerate(names, 1):
        if not name:
            return f"empty column name (column {j} of the header)"
        if '"' in name or not name.isprintable():
            return f"column name {_show(name)} is not plain text (no quotes or control characters)"
        if name in seen:
            return f"duplicate column '{name}' (columns {seen[name]} and {j})"
        seen[name] = j
    if all(_looks_numeric(n) for n in names):
        return "no header row: this line holds numbers where the column names should be"
    return None


# What loggers and spreadsheets call a time column. Without a `t` column a capture is a table of
# averages (one row per position), so a time series whose `t` is named so would be read as
# thousands of one-sample positions; such a name beside no `t` is refused (a table's own time
# column, P2's `elapsed_s`, is no such name).
_TIME_LIKE = re.compile(r"(t|time|times|timestamp|sec|secs|seconds)(_?(s|sec|ms|us|ns))?")


def _time_column_problem(names: list[str]) -> str | None:
    if "t" in names:
        return None
    for name in names:
        if _TIME_LIKE.fullmatch(name.lower()):
            return (
                f"column '{name}' looks like the time, but a capture's time column is named 't' (seconds); "
                "without 't' the rows are read as a table of averages, one row per position "
                f"(rename it 't', or convert a plain CSV: station import FILE --map t={name} --unit t=s|ms|us)"
            )
    return None


def _label_problem(label: str) -> str | None:
    if '"' in label:
        return f"column 'position': {_show(label)} holds a quote, which plain CSV cannot hold"
    if not label.isprintable():
        return f"column 'position': {_show(label)} holds a control character"
    return None


# ------------------------------------------------------------------------------------ reading


class _Head:
    """What precedes the data: metadata, header, and where the data start."""

    def __init__(self, path: str):
        self.path = path
        self.meta: dict[str, str] = {}
        self.meta_lines: dict[str, int] = {}
        self.header: list[str] = []
        self.header_line = 0
        self.data_offset = 0
        self.trailing_comma = False  # every line ends in a comma: an unnamed last column, read and dropped


# the unnamed last column of a file whose lines all end in a comma (a spreadsheet's export): it must
# hold nothing, and is not part of the capture
_TRAILING = "(the unnamed column after the last comma)"


def _open(path) -> io.BufferedReader:
    return open_input(path, "a capture file")


class _NotUtf8(InputError):
    """Text that is not UTF-8 (UTF-16, a byte UTF-8 has not): :func:`read_capture` reads such a
    file again as ``station import`` decides its encoding (Windows-1252, UTF-16 with a mark), or
    refuses it in the importer's one line."""


def _decode(path: str, raw: bytes, lineno: int) -> str:
    """One physical line as text without its line ending; binary data is an InputError."""
    nul = raw.find(b"\0")
    if nul >= 0:
        raise InputError(path, lineno, f"NUL byte at column {nul + 1}: binary data, not a text capture")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise _NotUtf8(path, lineno, f"not UTF-8 text: byte 0x{raw[exc.start]:02x} at column {exc.start + 1}") from None
    if text.endswith("\n"):
        text = text[:-1]
    if text.endswith("\r"):
        text = text[:-1]
    if "\r" in text:
        raise InputError(path, lineno, "stray carriage return (\\r) inside the line; use LF or CRLF line endings")
    return text


def _read_head(path: str) -> _Head:
    head = _Head(path)
    with _open(path) as f:
        lineno = 0
        saw_header = False
        padded = False
        while True:
            raw = f.readline(_MAX_HEAD_LINE)
            lineno += 1
            if not raw:
                if lineno == 1:
                    raise InputError(path, 1, "empty file")
                raise InputError(path, lineno, "no header row (a line of column names must follow the metadata)")
            if len(raw) == _MAX_HEAD_LINE and not raw.endswith(b"\n"):
                if b"\r" in raw and raw.lstrip(codecs.BOM_UTF8).startswith(b"#") and b"\0" not in raw:
                    # a whole capture with old Mac line endings reads as one line
                    raise InputError(path, lineno, "carriage returns (\\r) end the lines; use LF or CRLF line endings")
                raise InputError(path, lineno, f"line longer than {_MAX_HEAD_LINE} bytes: not a capture file")
            if lineno == 1:
                log = log_kind(raw + f.peek(8)[:8])
                if log:  # station noise flight.ulg: not 'NUL byte at column 13'
                    raise InputError(
                        path, None, f"{log[1]}, not a capture: turn it into one with station import FILE --procedure P"
                    )
                if raw.startswith(codecs.BOM_UTF8):
                    raw = raw[len(codecs.BOM_UTF8) :]
                elif looks_utf16(raw + f.peek(64)[:64]):  # with a byte-order mark or without
                    raise _NotUtf8(path, 1, "UTF-16 text; capture files are UTF-8")
            text = _decode(path, raw, lineno)
            stripped = text.strip()
            if lineno == 1:
                # a spreadsheet's save pads every row to the table's width: '# station-capture: 1,,,,,,'
                # says so; then '# device: X,,,,,,' (and a blank line as ',,,,,,') are padded too
                padded = stripped.startswith("#") and stripped.endswith(",")
            if padded and (stripped.startswith("#") or not stripped.strip(",")):
                stripped = stripped.rstrip(", \t")
            if lineno == 1:
                _first_line(path, f, stripped)
                head.meta["station-capture"] = FORMAT_VERSION
                head.meta_lines["station-capture"] = 1
                continue
            if not stripped:
                continue  # blank lines before the header are harmless
            if stripped.startswith("#"):
                key, sep, value = stripped[1:].partition(":")
                key, value = key.strip(), value.strip()
                if not sep or not key:
                    raise InputError(path, lineno, f"metadata line without 'key: value': {_show(stripped)}")
                if not (key.isprintable() and value.isprintable()):  # an ESC sequence, a tab, a bidi override
                    raise InputError(path, lineno, _meta_text_problem(key, value))
                if len(head.meta) > MAX_META_LINES:  # the first line counted is station-capture
                    raise InputError(path, lineno, f"more than {MAX_META_LINES} metadata lines: not a capture head")
                if key in head.meta:
                    raise InputError(
                        path, lineno, f"duplicate metadata key '{key}' (first on line {head.meta_lines[key]})"
                    )
                head.meta[key] = value
                head.meta_lines[key] = lineno
                continue
            names = [_unquoted(c.strip()) for c in text.split(",")]
            if len(names) > 1 and names[-1] == "" and all(names[:-1]):
                names, head.trailing_comma = names[:-1], True
            problem = _header_problem(names) or _time_column_problem(names)
            if problem:
                raise InputError(path, lineno, problem)
            head.header = names
            head.header_line = lineno
            head.data_offset = f.tell()
            saw_header = True
            break
    assert saw_header
    twice = _spelled_twice(head.meta)
    if twice:  # 'procedure' and 'PROCEDURE': which one holds would be anyone's guess
        key, first = twice
        raise InputError(
            path,
            head.meta_lines[key],
            f"duplicate metadata key '{key}': the same key as '{first}' on line {head.meta_lines[first]} "
            "(the format's keys are read in any letter case)",
        )
    for key in [k for k in head.meta if k not in SPEC_KEYS and k.lower() in SPEC_KEYS]:
        # 'MAG_UNIT', 'Sample_Rate_Hz': the key it spells
        head.meta[key.lower()] = head.meta.pop(key)
        head.meta_lines[key.lower()] = head.meta_lines.pop(key)
    for key, aliases in UNIT_ALIASES.items():
        if head.meta.get(key) in aliases:
            head.meta[key] = aliases[head.meta[key]]
    _check_meta(path, head.meta, head.meta_lines)
    return head


def _meta_text_problem(key: str, value: str) -> str:
    """Why a metadata line holding a control character is refused: the device id as `station
    import --device` refuses it (it is stored, shown and written into firmware files); any other
    key or value because the writer (`export-capture` of the stored capture) could not give it back."""
    if key.isprintable() and key.lower() == "device":
        return f"metadata {_show(key)}: {_show(value)}: {DEVICE_TEXT_RULE}"
    said = (
        f"metadata {_show(key)}: {_show(value)}: a capture's metadata cannot hold a control character "
        "(a tab, an ESC sequence, a bidi override)"
    )
    if key.isprintable() and "\t" in value and value.replace("\t", "").isprintable():
        # '# source: Wang & Li 2021<TAB> Table 1': the line's commas written as tabs, as a spreadsheet
        # saves the file tab-separated (Excel's "Unicode Text")
        said += "; tabs where the line had commas? A capture is comma-separated: save the file as CSV"
    return said


def _spelled_twice(meta: dict[str, str]) -> tuple[str, str] | None:
    """(a key, the earlier key) where two of ``meta``'s keys spell one key of the format in
    different letter case (``procedure``, ``PROCEDURE``); None when none do."""
    first_of: dict[str, str] = {}
    for key in meta:
        spec = key.lower()
        if spec in SPEC_KEYS:
            if spec in first_of:
                return key, first_of[spec]
            first_of[spec] = key
    return None


def _first_line(path: str, f, stripped: str) -> None:
    want = f"# station-capture: {FORMAT_VERSION}"
    # a log or another CSV has a way in: say which
    way_in = "; for a log or another CSV use `station import FILE --procedure P --out CAPTURE` (README: Import)"
    if not stripped.startswith("#"):
        if not stripped and not f.read(1 << 16).strip():
            raise InputError(path, 1, "empty file")
        raise InputError(path, 1, f"missing first line '{want}': not a station capture file{way_in}")
    key, sep, value = stripped[1:].partition(":")
    if key.strip() != "station-capture" or not sep:
        raise InputError(path, 1, f"missing first line '{want}': not a station capture file{way_in}")
    if value.strip() != FORMAT_VERSION:
        raise InputError(
            path, 1, f"unsupported capture version {_show(value.strip())} (this station reads version {FORMAT_VERSION})"
        )


_LF_AS_COMMA = bytes.maketrans(b"\n", b",")


def _fill_empty_fields(data: bytes) -> bytes:
    """Every empty field of a block (LF line ends, no blank lines) replaced by 'nan'."""
    data = data.replace(b",,", b",nan,").replace(b",,", b",nan,")  # twice: ',,,' overlaps
    data = data.replace(b"\n,", b"\nnan,").replace(b",\n", b",nan\n")
    if data.startswith(b","):
        data = b"nan" + data
    if data.endswith(b","):
        data += b"nan"
    return data


class _Parser:
    """Parses blocks of data lines into column arrays, carrying state (t, labels) across blocks."""

    def __init__(self, path: str, names: list[str], meta: dict[str, str] | None = None):
        self.path = path
        self.names = names
        self.ncols = len(names)
        self.text = [j for j, n in enumerate(names) if n in TEXT_COLUMNS]
        limits = {j: plausible_limit(n, meta or {}) for j, n in enumerate(names) if j not in self.text}
        self.limits = {j: v for j, v in limits.items() if v is not None}
        self.t_index = names.index("t") if "t" in names else None
        self.temp_index = names.index("temp_c") if "temp_c" in names else None
        self.n_index = names.index("n") if "n" in names else None
        self.std_index = [j for j, n in enumerate(names) if n.endswith("_std") and n not in TEXT_COLUMNS]
        self.prev_t = -math.inf
        self.prev_t_text = ""
        self.labels: dict[str, str] = {}  # one str object per distinct label
        if self.text:
            self.dtype = np.dtype(
                [(f"f{j}", f"S{_LABEL_WIDTH}" if j in self.text else "f8") for j in range(self.ncols)]
            )
        else:
            self.dtype = np.dtype("f8")

    # -- the fast path: numpy's C parser on the whole block

    def parse(self, block: bytes, n_lines: int, first_line: int, force_slow: bool = False) -> dict[str, np.ndarray]:
        """Columns of ``block`` (``n_lines`` whole data lines, the first being ``first_line``)."""
        out = None if force_slow else self._fast(block, n_lines)
        if out is None:
            lines = block.split(b"\n")
            if block.endswith(b"\n"):
                lines.pop()
            out = self._slow(lines, first_line, last_cut=not block.endswith(b"\n"))
        elif self.t_index is not None:
            stop = len(block) - 1 if block.endswith(b"\n") else len(block)
            last = block[block.rfind(b"\n", 0, stop) + 1 : stop]
            self.prev_t_text = last.split(b",")[self.t_index].strip().decode("ascii")
            self.prev_t = float(self.prev_t_text)
        return out

    def _fast(self, data: bytes, n_lines: int) -> dict[str, np.ndarray] | None:
        if b"\r" in data:
            data = data.replace(b"\r\n", b"\n")
            if data.endswith(b"\r"):
                data = data[:-1]
        if data.translate(None, _FAST_BYTES) or data.startswith((b"\n", b"#")) or (b"#" in data and b"\n#" in data):
            return None  # control bytes, non-ASCII, comment lines: the per-cell path says which
        # A blank line and an empty field in one scan: with line ends read as commas, each is
        # ',,' (a blank line '\n\n', an empty field ',,' ',\n' '\n,'); most blocks have neither.
        # (Five scans of the block for two bytes each were a sixth of `record --recover`.)
        if b",," in data.translate(_LF_AS_COMMA):
            if b"\n\n" in data:
                return None  # a blank line: the per-cell path says where
            empties = True
        else:
            empties = data.startswith(b",") or data.endswith(b",")
        if empties:  # empty fields become 'nan' for numpy; so no cell may say nan or inf itself
            low = data.lower()
            if b"nan" in low or b"inf" in low:
                return None
            data = _fill_empty_fields(data)
        try:
            arr = np.loadtxt(
                io.BytesIO(data),
                dtype=self.dtype,
                delimiter=",",
                comments=None,
                ndmin=1 if self.text else 2,
                encoding="ascii",
            )
        except Exception:  # noqa: BLE001 - any parse failure: the per-cell path finds and names it
            return None
        if len(arr) != n_lines or (not self.text and arr.shape[1] != self.ncols):
            return None
        cols: dict[str, np.ndarray] = {}
        for j, name in enumerate(self.names):
            if j in self.text:
                labels = self._fast_labels(arr[f"f{j}"], first_column=(j == 0), empties=empties)
                if labels is None:
                    return None
                cols[name] = labels
                continue
            col = np.ascontiguousarray(arr[f"f{j}"] if self.text else arr[:, j], dtype=np.float64)
            if not (np.isfinite(col).all() if not empties or j == self.t_index else not np.isinf(col).any()):
                return None
            if j in self.limits:
                with np.errstate(invalid="ignore"):
                    if (np.abs(col) > self.limits[j][0]).any():
                        return None  # the per-cell path names the line
            if j == self.t_index and (col[0] < self.prev_t or np.any(col[1:] < col[:-1])):
                return None
            if j == self.temp_index and np.any((col < ABSOLUTE_ZERO_C) | (col > TEMP_MAX_C)):
                return None  # the per-cell path names the line
            if j == self.n_index and not np.all(
                np.isnan(col) | ((col >= 1) & (col <= MAX_N_SAMPLES) & (col == np.floor(col)))
            ):
                return None
            if j in self.std_index and np.any(col < 0):
                return None
            cols[name] = col
        return cols

    def _fast_labels(self, raw: np.ndarray, first_column: bool, empties: bool) -> np.ndarray | None:
        starts = np.flatnonzero(np.concatenate(([True], raw[1:] != raw[:-1])))
        lengths = np.diff(np.append(starts, len(raw)))
        heads = []
        for value in raw[starts].tolist():
            if len(value) >= _LABEL_WIDTH:
                return None  # may have been cut at the field width
            label = value.decode("ascii").strip()
            if empties and label == "nan":  # an empty field filled in (the block has no literal nan)
                label = ""
            if _label_problem(label) or (first_column and label.startswith("#")):
                return None
            heads.append(self.labels.setdefault(label, label))
        runs = np.empty(len(heads), dtype=object)
        runs[:] = heads
        return np.repeat(runs, lengths)

    # -- the per-cell path: every rule checked in file order, so the first bad line is named

    def _slow(self, raw_lines: list[bytes], first_line: int, last_cut: bool = False) -> dict[str, np.ndarray]:
        """``last_cut``: the last of ``raw_lines`` is the file's last line and has no line end."""
        path, names, ncols = self.path, self.names, self.ncols
        values: list[list] = [[] for _ in names]
        for k, raw in enumerate(raw_lines):
            lineno = first_line + k
            text = _decode(path, raw, lineno)
            stripped = text.strip()
            if not stripped:
                raise InputError(path, lineno, "blank line inside the data (only trailing blank lines are allowed)")
            if stripped.startswith("#"):
                raise InputError(path, lineno, "comment line inside the data (# lines must come before the header)")
            fields = text.split(",")
            if len(fields) != ncols:
                few = "too few" if len(fields) < ncols else "too many"
                message = f"{few} fields: {len(fields)} where the header has {ncols} columns"
                if last_cut and k == len(raw_lines) - 1 and len(fields) < ncols:
                    message += f", on the last line, which has no line end: {CUT_SHORT}"
                raise InputError(path, lineno, message)
            for j, value in enumerate(fields):
                if j in self.text:
                    label = _unquoted(value.strip())
                    problem = _label_problem(label)
                    if problem:
                        raise InputError(path, lineno, problem)
                    values[j].append(self.labels.setdefault(label, label))
                    continue
                values[j].append(self._number(names[j], value, j, lineno))
        cols: dict[str, np.ndarray] = {}
        for j, name in enumerate(names):
            if j in self.text:
                arr = np.empty(len(values[j]), dtype=object)
                arr[:] = values[j]
            else:
                arr = np.array(values[j], dtype=np.float64)
            cols[name] = arr
        return cols

    def _number(self, name: str, value: str, j: int, lineno: int) -> float:
        v = _unquoted(value.strip(" \t")).strip(" \t")
        if not v:
            if j == self.t_index:
                raise InputError(self.path, lineno, "column 't': empty (every row of a time series needs its time)")
            return math.nan
        if not _NUMBER.fullmatch(v):
            if v.lower().lstrip("+-") in _NONFINITE_WORDS or v.lower() in _MISSING_WORDS:
                raise InputError(
                    self.path,
                    lineno,
                    f"column '{name}': {_show(v)} is not allowed: leave the field empty for a missing value",
                )
            raise InputError(self.path, lineno, f"column '{name}': {_show(v)} is not a number")
        x = float(v)
        if not math.isfinite(x):
            raise InputError(self.path, lineno, f"column '{name}': {_show(v)} is out of range")
        if j in self.limits and abs(x) > self.limits[j][0]:
            raise InputError(self.path, lineno, f"column '{name}': {x:g} is beyond {self.limits[j][1]}")
        if j == self.t_index:
            if x < self.prev_t:
                raise InputError(self.path, lineno, f"t goes backwards: {v} after {self.prev_t_text}")
            self.prev_t, self.prev_t_text = x, v
        elif j == self.temp_index and x < ABSOLUTE_ZERO_C:
            raise InputError(self.path, lineno, f"column '{name}': {x:g} °C is below absolute zero (-273.15 °C)")
        elif j == self.temp_index and x > TEMP_MAX_C:
            raise InputError(
                self.path,
                lineno,
                f"column '{name}': {x:g} °C is beyond what any thermometer on a sensor reports "
                f"(up to {TEMP_MAX_C:g} °C is accepted)",
            )
        elif j == self.n_index and (x < 1 or x != math.floor(x)):
            raise InputError(self.path, lineno, f"column 'n': {_show(v)} is not a whole number of samples (1 or more)")
        elif j == self.n_index and x > MAX_N_SAMPLES:
            raise InputError(self.path, lineno, f"column 'n': {_show(v)} {_TOO_MANY_SAMPLES}")
        elif j in self.std_index and x < 0:
            raise InputError(self.path, lineno, f"column '{name}': {_show(v)} is negative (it is a standard deviation)")
        return x


_TOO_MANY_SAMPLES = (
    f"samples are more than any hold averages (at most {MAX_N_SAMPLES:.0e}, 11.6 days at 1 kHz)".replace("e+0", "e")
)


def _blocks(f, block_bytes: int, path: str, first_line: int) -> Iterator[bytes]:
    """Blocks of whole lines, about ``block_bytes`` long (at most ``BLOCK_BYTES`` plus one
    line of at most ``_MAX_DATA_LINE``): memory stays bounded whatever the line lengths."""
    block_bytes = max(1, min(int(block_bytes), BLOCK_BYTES))
    lineno = first_line
    while True:
        block = f.read(block_bytes)
        if not block:
            return
        if not block.endswith(b"\n"):
            tail = f.readline(_MAX_DATA_LINE + 1)
            block += tail
            start = block.rfind(b"\n", 0, len(block) - 1) + 1
            if len(block.rstrip(b"\r\n")) - start > _MAX_DATA_LINE:
                nul = block.find(b"\0", start)
                raise InputError(
                    path,
                    lineno + block.count(b"\n", 0, start),
                    f"line longer than {_MAX_DATA_LINE} bytes: not a capture row"
                    + (f" (NUL bytes from column {nul - start + 1}: a part never written?)" if nul >= 0 else ""),
                )
        lineno += block.count(b"\n")
        yield block


def _count_lines(block: bytes) -> int:
    return block.count(b"\n") + (0 if block.endswith(b"\n") else 1)


class _Upto:
    """A binary file read only up to byte ``end``: what lies beyond is as if not there (the
    reader of `station record --recover` stops before a cut last line)."""

    def __init__(self, f, end: int) -> None:
        self._f, self._end = f, end

    def _left(self, size: int) -> int:
        left = max(0, self._end - self._f.tell())
        return left if size is None or size < 0 else min(size, left)

    def read(self, size: int = -1) -> bytes:
        return self._f.read(self._left(size))

    def readline(self, size: int = -1) -> bytes:
        left = self._left(size)
        return self._f.readline(left) if left else b""

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._f.seek(offset, whence)

    def tell(self) -> int:
        return self._f.tell()


def _data_chunks(
    head: _Head, rows: int, force_slow: bool = False, notes: list[str] | None = None, end: int | None = None
) -> Iterator[dict[str, np.ndarray]]:
    path = head.path
    parser = _Parser(path, head.header + ([_TRAILING] if head.trailing_comma else []), head.meta)
    wide = WideStd(head.header, head.meta)  # a table of averages' whole-table rule, judged at its end
    runs = _LabelRuns(path, head.header_line + 1) if "t" not in head.header and "position" in head.header else None
    with _open(path) as whole:
        f = whole if end is None else _Upto(whole, end)
        f.seek(head.data_offset)
        sample = f.readline(_MAX_DATA_LINE + 1)
        if len(sample) > _MAX_DATA_LINE:
            raise InputError(path, head.header_line + 1, f"line longer than {_MAX_DATA_LINE} bytes: not a capture row")
        f.seek(head.data_offset)
        lineno = head.header_line + 1
        pending_blank: int | None = None
        n_rows = 0
        ends_line = True
        for block in _blocks(f, rows * max(1, len(sample)), path, lineno):
            ends_line = block.endswith(b"\n")
            first = lineno
            n_lines = _count_lines(block)
            lineno += n_lines
            end = len(block.rstrip())
            if end == 0:  # only blank lines: fine if nothing follows
                pending_blank = first if pending_blank is None else pending_blank
                continue
            if pending_blank is not None:
                raise InputError(
                    path, pending_blank, "blank line inside the data (only trailing blank lines are allowed)"
                )
            nl = block.find(b"\n", end)
            if 0 <= nl < len(block) - 1:  # trailing blank lines: an error only if data follow
                block = block[: nl + 1]
                n_lines = _count_lines(block)
                pending_blank = first + n_lines
            chunk = parser.parse(block, n_lines, first, force_slow=force_slow)
            if head.trailing_comma:
                extra = chunk.pop(_TRAILING)
                filled = np.flatnonzero(~np.isnan(extra))
                if filled.size:
                    raise InputError(
                        path,
                        first + int(filled[0]),
                        f"a value after the last column (column {len(head.header) + 1} has no name in the header)",
                    )
            n_rows += n_lines
            wide.add(chunk)
            if runs is not None:
                runs.add(chunk["position"])
            yield chunk
    if n_rows == 0:
        raise InputError(path, head.header_line + 1, "no data rows after the header")
    first = wide.first()
    if first is not None:  # data rows follow the header line by line (no blank or comment line between)
        row, name, what = first
        raise InputError(path, head.header_line + 1 + row, f"column '{name}': {what}")
    if not ends_line and notes is not None and pending_blank is None:
        notes.append(no_line_end_note(lineno - 1))


# A table of averages has one row per position; this many rows in a row with one label are the
# samples of a hold: a time series whose `t` column is missing (read as a table, each sample
# was a position: 28 400 of them for one P1 recording).
MAX_LABEL_RUN = 100


class _LabelRuns:
    """The longest run of one `position` label in a table of averages, over its chunks:
    InputError at the run's first row once it reaches MAX_LABEL_RUN rows."""

    def __init__(self, path: str, first_line: int) -> None:
        self.path, self.line = path, first_line  # the file line of the next row
        self.label, self.start, self.length = None, first_line, 0

    def add(self, labels: np.ndarray) -> None:
        for k, lab in enumerate(labels):
            lab = lab or None  # an empty label is a position of its own, never a run
            if lab is not None and lab == self.label:
                self.length += 1
                if self.length >= MAX_LABEL_RUN:
                    raise InputError(
                        self.path,
                        self.start,
                        f"this row and the {MAX_LABEL_RUN - 1} after it hold position {_show(str(lab))}: without a 't' "
                        "column the rows are a table of averages, one row per position; a time series needs "
                        "its 't' column (seconds)",
                    )
            else:
                self.label, self.start, self.length = lab, self.line + k, 1
        self.line += len(labels)


CUT_SHORT = "the file was cut short (a write stopped part-way, or one still going on)"


def no_line_end_note(lineno: int) -> str:
    """The warning for a file whose last line, ``lineno``, has no line end (as a file cut short ends)."""
    return (
        f"the last line ({lineno}) has no line end: a file cut short (a copy or a write stopped "
        "part-way) ends so, and then its last value may be cut too (kept as read)"
    )


def iter_capture_chunks(path, rows: int = DEFAULT_CHUNK_ROWS):
    """Stream a capture: ``(meta, header, chunks)``.

    ``meta`` and ``header`` are read and validated at once; ``chunks`` yields
    ``dict[name, ndarray]`` blocks of about ``rows`` rows (read as bytes, sized from the first
    data line), validating as it goes: an InputError may come from any ``next``. A rule on the
    whole table (a table of averages' ``*_std`` bound, :class:`WideStd`) is judged after the
    last chunk, so the ``next`` that would end the stream raises it, on the line
    :func:`read_capture` names.
    """
    path = os.fspath(path)
    head = _read_head(path)
    return dict(head.meta), list(head.header), _data_chunks(head, max(1, int(rows)))


@dataclass
class CheckedRows:
    """What :func:`check_capture_upto` read: the head, where the data rows start and end
    (byte offsets), how many rows they hold."""

    meta: dict[str, str]
    header: list[str]
    header_line: int
    trailing_comma: bool  # every line ends in a comma (read_capture drops that unnamed column)
    data_offset: int
    end: int
    rows: int


def check_capture_upto(path, end: int, *, chunk_rows: int = DEFAULT_CHUNK_ROWS) -> CheckedRows:
    """Validate the capture ``path`` as :func:`read_capture` would read its first ``end``
    bytes (the chunked reader, whole-table rules included), without holding its columns.
    ``end`` is a line end (the byte after it): the bytes from ``data_offset`` to ``end`` are
    then rows the reader takes as they are. ``rows`` 0 when no data row ends before ``end``
    (nor the header row, when ``end`` < ``data_offset``). InputError ``file:line: what is
    wrong`` on the first thing it refuses."""
    path = os.fspath(path)
    head = _read_head(path)
    checked = CheckedRows(
        dict(head.meta), list(head.header), head.header_line, head.trailing_comma, head.data_offset, end, 0
    )
    if end <= head.data_offset:
        return checked
    for chunk in _data_chunks(head, max(1, int(chunk_rows)), end=end):
        checked.rows += len(next(iter(chunk.values())))
    return checked


def read_capture(path, *, rows: int = DEFAULT_CHUNK_ROWS, _force_slow: bool = False) -> Capture:
    """Read and validate a capture file; InputError ``file:line: what is wrong`` on bad input.

    A capture a spreadsheet saved in another encoding than UTF-8 is read as ``station import``
    reads a CSV (one decision, :func:`station.textencoding.text_encoding`): Windows-1252
    (Excel's "CSV (Comma delimited)" on Windows; said in a note, as import says it) and UTF-16
    with a byte-order mark (Excel's "Unicode Text"); anything else is refused in the
    importer's one line (the byte and its line, or what to save the file as)."""
    path = os.fspath(path)
    try:
        return _read_capture(path, rows, _force_slow)
    except _NotUtf8:
        return _read_reencoded(path, rows, _force_slow)


_ENCODING_NAMES = {"cp1252": "Windows-1252", "utf-16": "UTF-16"}


def _read_reencoded(path: str, rows: int, force_slow: bool) -> Capture:
    """:func:`read_capture` of a capture that is not UTF-8: its text, in the encoding the
    importer finds, copied as UTF-8 to a temporary file (line for line, line ends kept) and read
    from there; a refusal names ``path`` and the same line."""
    import tempfile

    from station.textencoding import copy_as_utf8, text_encoding

    encoding, note = text_encoding(path, "a capture file")
    try:
        with tempfile.TemporaryDirectory(prefix="station-capture-") as tmp:
            copy = os.path.join(tmp, "capture.csv")
            copy_as_utf8(path, encoding, copy)
            try:
                capture = _read_capture(copy, rows, force_slow)
            except InputError as exc:
                raise InputError(path, exc.line, exc.message) from None
    except OSError as exc:  # no temporary folder to write in (TMPDIR gone, a full disk)
        raise InputError(
            path,
            None,
            f"{_ENCODING_NAMES.get(encoding, encoding)} text, read through a UTF-8 copy that could not be made "
            f"({exc.strerror or exc}): "
            "save it as UTF-8",
        ) from None
    capture.path = path
    if note:
        capture.notes.insert(0, note)
    return capture


def _read_capture(path: str, rows: int, _force_slow: bool) -> Capture:
    head = _read_head(path)
    parts: dict[str, list[np.ndarray]] = {name: [] for name in head.header}
    notes: list[str] = []
    unknown = unknown_table_columns(head.header)
    if unknown:
        notes.append(unknown_columns_note(unknown, head.header_line, series="t" in head.header))
    for chunk in _data_chunks(head, max(1, int(rows)), force_slow=_force_slow, notes=notes):
        for name, arr in chunk.items():
            parts[name].append(arr)
    columns: dict[str, np.ndarray] = {}
    for name in head.header:  # one column at a time, so the peak is the result plus one column
        pieces = parts[name]
        columns[name] = pieces[0] if len(pieces) == 1 else np.concatenate(pieces)
        pieces.clear()
    return Capture(
        meta=head.meta,
        columns=columns,
        path=path,
        meta_lines=head.meta_lines,
        header_line=head.header_line,
        notes=notes,
    )


# ------------------------------------------------------------------------------------ writing


def _fmt_float(x: float) -> str:
    s = repr(x)
    return s[:-2] if s.endswith(".0") else s


def _meta_for_writing(path, meta: dict[str, str]) -> dict[str, str]:
    out = {"station-capture": FORMAT_VERSION}
    for key, value in meta.items():
        if not isinstance(key, str) or not isinstance(value, str):
            raise InputError(path, None, f"metadata {key!r}: keys and values must be str")
        if key == "station-capture":
            if value != FORMAT_VERSION:
                raise InputError(
                    path,
                    None,
                    f"unsupported capture version {_show(value)} (this station writes version {FORMAT_VERSION})",
                )
            continue
        if not key or key != key.strip() or ":" in key or not key.isprintable():
            raise InputError(
                path,
                None,
                f"metadata key {_show(key)} cannot be written (empty, spaces at the ends, ':' or a control character)",
            )
        if value != value.strip() or not value.isprintable():
            raise InputError(
                path,
                None,
                f"metadata '{key}': {_show(value)} cannot be written (spaces at the ends or a control character)",
            )
        out[key] = value
    twice = _spelled_twice(out)
    if twice:
        raise InputError(path, None, f"metadata keys {_show(twice[1])} and {_show(twice[0])} are one key to the reader")
    if len(out) > MAX_META_LINES + 1:  # the reader's limit (station-capture is the first line)
        raise InputError(path, None, f"{len(out) - 1} metadata keys: a capture holds at most {MAX_META_LINES}")
    _check_meta(path, out, {})
    return out


def _label_text(v) -> str | None:
    """A label value as the text the writer puts in the file (None: not a label)."""
    if isinstance(v, str):
        return v
    if v is None:
        return ""
    if isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return "" if math.isnan(v) else _fmt_float(float(v))
    return None


def _text_cells(path, name: str, col: np.ndarray, start: int, first_column: bool) -> list[str]:
    values = col.tolist()
    try:
        distinct = dict.fromkeys(values)
    except TypeError:  # unhashable values
        distinct = None
    if distinct is None:
        bad = next(i for i, v in enumerate(values) if _label_text(v) is None)
        raise InputError(
            path, None, f"column '{name}', row {start + bad + 1}: {type(values[bad]).__name__} value is not a label"
        )
    for v in distinct:
        s = _label_text(v)
        problem = None
        if s is None:
            problem = f"{type(v).__name__} value {v!r} is not a label"
        elif "," in s:
            problem = f"label {_show(s)} holds a comma, which plain CSV cannot hold"
        elif s != s.strip():
            problem = f"label {_show(s)} has spaces at the ends, which the reader would strip"
        elif first_column and s.startswith("#"):
            problem = f"label {_show(s)} starts with '#' in the first column, which would read as a comment"
        elif _label_problem(s):
            problem = f"label {_show(s)} holds a quote or a control character, which plain CSV cannot hold"
        if problem:
            i = next(i for i, x in enumerate(values) if x is v or x == v)
            raise InputError(path, None, f"column '{name}', row {start + i + 1}: {problem}")
        distinct[v] = s
    if all(type(v) is str for v in distinct):
        return values
    return [distinct[v] for v in values]


def _number_cells(path, name: str, col: np.ndarray, start: int, prev_t: float, is_t: bool) -> list[str]:
    finite = np.isfinite(col)
    bad = ~finite & ~np.isnan(col)
    if is_t:
        bad |= np.isnan(col)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError(
            path,
            None,
            f"column '{name}', row {start + i + 1}: {float(col[i])!r} cannot be written (only finite numbers{'' if is_t else ' or NaN'})",
        )
    if is_t:
        back = np.flatnonzero(np.diff(np.concatenate(([prev_t], col))) < 0)
        if back.size:
            i = int(back[0])
            before = prev_t if i == 0 else col[i - 1]
            raise InputError(
                path,
                None,
                f"column 't', row {start + i + 1}: t goes backwards: {float(col[i])!r} after {float(before)!r}",
            )
    elif name == "n":
        wrong = finite & ~((col >= 1) & (col == np.floor(col)))
        if wrong.any():
            i = int(np.flatnonzero(wrong)[0])
            raise InputError(
                path, None, f"column 'n', row {start + i + 1}: {float(col[i])!r} is not a whole number of samples"
            )
        many = finite & (col > MAX_N_SAMPLES)
        if many.any():
            i = int(np.flatnonzero(many)[0])
            raise InputError(path, None, f"column 'n', row {start + i + 1}: {float(col[i]):g} {_TOO_MANY_SAMPLES}")
    elif name.endswith("_std"):
        wrong = finite & (col < 0)
        if wrong.any():
            i = int(np.flatnonzero(wrong)[0])
            raise InputError(path, None, f"column '{name}', row {start + i + 1}: {float(col[i])!r} is negative")
    # repr() round-trips bit for bit; whole numbers (not -0.0) are written as integers
    whole = finite & (col == np.trunc(col)) & (np.abs(col) < 2.0**53) & ~((col == 0) & np.signbit(col))
    if whole.all():
        return list(map(str, col.astype(np.int64).tolist()))
    cells = list(map(repr, col.tolist()))
    for i in np.flatnonzero(whole).tolist():
        cells[i] = cells[i][:-2]
    if not finite.all():
        for i in np.flatnonzero(~finite).tolist():
            cells[i] = ""
    return cells


def _prepare(path, capture: Capture) -> tuple[dict[str, str], list[str], list[np.ndarray], int]:
    """Metadata, names, 1-D arrays and row count of ``capture``, checked as far as can be
    without formatting every value (that happens block by block as it is written)."""
    meta = _meta_for_writing(path, capture.meta)
    names = list(capture.columns)
    if not names:
        raise InputError(path, None, "capture has no columns")
    if not all(isinstance(n, str) for n in names):
        raise InputError(path, None, "column names must be str")
    if any(n != n.strip() or "," in n for n in names):
        bad = next(n for n in names if n != n.strip() or "," in n)
        raise InputError(path, None, f"column name {_show(bad)} cannot be written (a comma or spaces at the ends)")
    problem = _header_problem(names)
    if problem or names[0].startswith("#"):
        raise InputError(path, None, problem or f"column name {_show(names[0])} would read as a comment")
    arrays: list[np.ndarray] = []
    for name in names:
        col = np.asanyarray(capture.columns[name])
        if col.ndim != 1:
            raise InputError(path, None, f"column '{name}' is not one-dimensional (shape {col.shape})")
        if name not in TEXT_COLUMNS:
            if col.dtype.kind not in "fiub":
                raise InputError(path, None, f"column '{name}' is not numeric (dtype {col.dtype})")
            col = col.astype(np.float64, copy=False)
        arrays.append(col)
    n = len(arrays[0])
    if any(len(a) != n for a in arrays):
        lengths = ", ".join(f"{k}={len(a)}" for k, a in zip(names, arrays))
        raise InputError(path, None, f"columns differ in length ({lengths})")
    if n == 0:
        raise InputError(path, None, "capture has no data rows")
    wide = wide_std({k: a for k, a in zip(names, arrays) if k not in TEXT_COLUMNS}, meta)
    if wide is not None:
        row, name, what = wide
        raise InputError(path, None, f"column '{name}', row {row + 1}: {what}")
    return meta, names, arrays, n


def _emit(f, path, meta: dict[str, str], names: list[str], arrays: list[np.ndarray], n: int, rows: int) -> None:
    f.writelines(f"# {k}: {v}".rstrip() + "\n" for k, v in meta.items())
    f.write(",".join(names) + "\n")
    prev_t = -math.inf
    for start in range(0, n, rows):
        cells = []
        for j, (name, col) in enumerate(zip(names, arrays)):
            part = col[start : start + rows]
            if name in TEXT_COLUMNS:
                cells.append(_text_cells(path, name, part, start, first_column=(j == 0)))
            else:
                cells.append(_number_cells(path, name, part, start, prev_t, is_t=(name == "t")))
                if name == "t":
                    prev_t = float(part[-1])
        lines = [",".join(r) for r in zip(*cells)]
        if len(names) == 1 and not all(lines):
            i = start + lines.index("")
            raise InputError(
                path,
                None,
                f"column '{names[0]}', row {i + 1}: a one-column capture cannot hold "
                "a missing value (the line would be blank)",
            )
        f.write("\n".join(lines))
        f.write("\n")


def format_capture(capture: Capture, stream, *, name: str = "<stdout>", rows: int = DEFAULT_CHUNK_ROWS) -> None:
    """Write ``capture`` in the file format to a text ``stream`` (e.g. stdout), block by block.

    The same checks as :func:`write_capture`; a refusal part-way leaves what was written so
    far in the stream, so use :func:`write_capture` for files.
    """
    meta, names, arrays, n = _prepare(name, capture)
    _emit(stream, name, meta, names, arrays, n, rows)


def write_capture(path, capture: Capture, *, rows: int = DEFAULT_CHUNK_ROWS) -> None:
    """Write ``capture`` to ``path`` atomically; refuses what the reader could not give back.

    Refused (InputError naming the column and 1-based row): labels with commas, quotes,
    control characters or spaces at the ends; inf; NaN in ``t``; ``t`` going backwards;
    metadata the reader would refuse. A failure at any point leaves ``path`` untouched.
    """
    path = os.fspath(path)
    meta, names, arrays, n = _prepare(path, capture)
    with cannot_write(path), atomic_open(path, "w", newline="\n") as f:
        _emit(f, path, meta, names, arrays, n, rows)
