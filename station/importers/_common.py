"""What every log reader hands over, and how it becomes a capture.

A reader returns an :class:`Imported`: one :class:`Stream` per sensor (its own time stamps,
its own unit, as the log has them) and the metadata the log itself holds (firmware, whether
the board had already corrected the data, parameters in use, date, place). :func:`to_capture`
puts the streams on one time grid — the stream of the sensor the procedure calibrates — and
builds the station capture (``../shared/spec/capture-format.md``).

Aligning streams (documented in ``docs/import.md``): a stream at about the grid's rate
(median periods within 25 %) is matched sample to sample by the nearest time stamp, so its
noise is untouched; a stream at another rate is interpolated linearly. A grid time farther
than 1.5 median periods from the stream's nearest sample (nearest) or between samples more
than 3 median periods apart (linear) gets an empty cell. Rows outside the time span common to
all streams are dropped, so the capture starts and ends with every sensor present.
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass, field

import numpy as np

from station.capture import Capture, plausible_limit
from station.errors import InputError
from station.importers.options import primary as primary_kind
from station.procedures import registry

KINDS = ("accel", "gyro", "mag")

FRD = "x forward, y right, z down"  # PX4's, ArduPilot's and MAVLink's vehicle body frame
_FRD_WORDS = {(0, 1): "forward", (0, -1): "back", (1, 1): "right", (1, -1): "left", (2, 1): "down", (2, -1): "up"}


def frame_in_frd(R) -> str | None:
    """The capture's ``frame`` metadata (where its x, y and z point on the vehicle, read by P4)
    for data whose axes reach the FRD body frame through ``R`` (body ← data); None when R does
    not map axes onto axes."""
    out = []
    for j, axis in enumerate("xyz"):
        col = np.asarray(R, dtype=float)[:, j]
        i = int(np.argmax(np.abs(col)))
        if abs(abs(col[i]) - 1.0) > 1e-6:
            return None
        out.append(f"{axis} {_FRD_WORDS[(i, 1 if col[i] > 0 else -1)]}")
    return ", ".join(out)


COLUMNS = {
    "accel": ("ax", "ay", "az"),
    "gyro": ("gx", "gy", "gz"),
    "mag": ("mx", "my", "mz"),
}
NAME = {"accel": "accelerometer", "gyro": "gyro", "mag": "magnetometer"}
# the end of a reader's warning that the log holds several sensors of a kind and the import
# took one (station import --instance; the TUI's Import screen says its own choice instead)
INSTANCE_ADVICE = "give --instance N to name its slot"


def several_instances_warning(instances: dict[str, list[int]], read: int | str) -> str | None:
    """The warning for a log with several sensors of a kind (IMUs, compasses, uORB instances of
    a topic) read without ``--instance``: which instances it has, which was read, what to give
    for another; None where there is one of each."""
    several = {what: v for what, v in instances.items() if len(v) > 1}
    if not several:
        return None
    each = [f"{len(v)} {what} (instances {', '.join(map(str, v))})" for what, v in several.items()]
    has = " and ".join([", ".join(each[:-1]), each[-1]] if len(each) > 1 else each)
    return f"the log has {has}: instance {read} read; {INSTANCE_ADVICE}"


@dataclass
class Stream:
    """One sensor's samples as the log holds them.

    ``t_s``: time in seconds (any origin, the same for every stream of one log), ``xyz``: (n, 3)
    in ``unit``, ``temp_c``: (n,) sensor temperature or None. ``device_id`` and ``instance`` (the
    index in the firmware's parameter names, e.g. n of ``CAL_ACCn_*``) where the log says.
    """

    kind: str
    t_s: np.ndarray
    xyz: np.ndarray
    unit: str
    source: str
    device_id: int | None = None
    instance: int | None = None
    temp_c: np.ndarray | None = None
    external: bool | None = None  # the firmware's own word (PX4 sensor_mag.is_external), None: not said


@dataclass
class Imported:
    """Everything one reader found: streams by kind and metadata (``dict[str, str]``)."""

    streams: dict[str, Stream]
    meta: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


def fmt_param(value) -> str:
    """A parameter value as the firmware stores it: integers as integers, floats as the
    shortest text that gives back the same float32 (PX4 and ArduPilot keep float32)."""
    if isinstance(value, (bool, np.bool_)):
        return str(int(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    x = float(value)
    if not math.isfinite(x):
        return repr(x)
    f32 = np.float32(x)
    if float(f32) == x:  # a float32 value: its shortest form
        text = np.format_float_positional(f32, unique=True, trim="-")
        if len(text) > 16:
            text = np.format_float_scientific(f32, unique=True, trim="-")
        return text
    return repr(x)


def iso_utc(unix_s: float) -> str | None:
    """A Unix time as the capture's ``date``: ISO date-time, UTC, whole seconds; None when it
    is no calendar date (beyond years 1-9999, not finite: a corrupt time field)."""
    try:
        return _dt.datetime.fromtimestamp(unix_s, _dt.UTC).replace(tzinfo=None).isoformat(timespec="seconds")
    except (ValueError, OverflowError, OSError):
        return None


def set_date(meta: dict[str, str], warnings: list[str], unix_s: float, clock: str) -> None:
    """``meta["date"]`` from a log's ``clock`` (e.g. "GPS"), or a warning when that time is no
    calendar date (a flipped byte in a time field): the samples are kept, without a date."""
    text = iso_utc(unix_s)
    if text is None:
        warnings.append(f"the {clock} time gives no calendar date ({unix_s:.6g} s from 1970): the capture has no date")
    else:
        meta["date"] = text


def clean_stream(path, stream: Stream, warnings: list[str] | None = None) -> Stream | None:
    """Rows with a finite time, sorted by time (stable), a sample repeated (same time, same
    values: a log fed twice) kept once; None when nothing is left. What was put in order or
    read once is said in ``warnings``."""
    t = np.asarray(stream.t_s, dtype=np.float64)
    xyz = np.asarray(stream.xyz, dtype=np.float64).reshape(len(t), 3)
    keep = np.isfinite(t)
    back = np.flatnonzero(np.diff(t[keep]) < 0)
    if back.size and warnings is not None:
        tk = t[keep]
        late = float(np.max(np.maximum.accumulate(tk)[back] - tk[back + 1]))
        warnings.append(
            f"{back.size} {NAME[stream.kind]} sample{'s are' if back.size != 1 else ' is'} stamped earlier than the sample before them "
            f"(by up to {late:.3g} s; the first {tk[back[0] + 1] - tk.min():.3f} s into the log): put in time order"
        )
    order = np.argsort(t[keep], kind="stable")
    t, xyz = t[keep][order], xyz[keep][order]
    temp = None if stream.temp_c is None else np.asarray(stream.temp_c, dtype=np.float64)[keep][order]
    if len(t) == 0:
        return None
    same = np.r_[
        False, (t[1:] == t[:-1]) & np.all((xyz[1:] == xyz[:-1]) | (np.isnan(xyz[1:]) & np.isnan(xyz[:-1])), axis=1)
    ]
    if temp is not None:
        same[1:] &= (temp[1:] == temp[:-1]) | (np.isnan(temp[1:]) & np.isnan(temp[:-1]))
    # only where the clock tells samples apart: a coarse one (a CSV's t in ms at 2 kHz) stamps
    # different samples alike, and a quiet sensor in counts may then repeat its values honestly
    coarse = bool(np.any((t[1:] == t[:-1]) & ~same[1:]))
    if same.any() and not coarse:
        t, xyz = t[~same], xyz[~same]
        temp = None if temp is None else temp[~same]
        if warnings is not None:
            k = int(same.sum())
            warnings.append(
                f"{k} repeated {NAME[stream.kind]} sample{'s' if k != 1 else ''} (same time and values) read once"
            )
    return Stream(
        stream.kind,
        t,
        xyz,
        stream.unit,
        stream.source,
        stream.device_id,
        stream.instance,
        temp,
        stream.external,
    )


def _check_limit(path, s: Stream) -> None:
    """Refuse a sample beyond what any sensor of its kind reports (station.capture.plausible_limit,
    in the stream's unit), naming the sample's time in the log: a corrupt record, not a reading."""
    names = COLUMNS[s.kind]
    limit = plausible_limit(names[0], {f"{s.kind}_unit": s.unit})
    if limit is None:  # raw units: any finite number (the fits' guard bounds them)
        return
    bound, reason = limit
    with np.errstate(invalid="ignore"):
        over = np.abs(s.xyz) > bound
    if over.any():
        i, j = (int(k) for k in np.argwhere(over)[0])
        raise InputError(
            path,
            None,
            f"{NAME[s.kind]} sample at t = {s.t_s[i]:.6g} s in the log: {names[j]} = {s.xyz[i, j]:g} is beyond {reason}",
        )


def _median_period(t: np.ndarray) -> float:
    d = np.diff(t)
    d = d[d > 0]
    return float(np.median(d)) if len(d) else math.inf


def align(grid_t: np.ndarray, t: np.ndarray, values: np.ndarray, grid_period: float) -> tuple[np.ndarray, str]:
    """``values`` (n, k) sampled at ``t``, put on ``grid_t``: nearest sample when the rates
    match (noise untouched), linear interpolation otherwise; empty (NaN) across gaps."""
    period = _median_period(t)
    out = np.full((len(grid_t), values.shape[1]), np.nan)
    if len(t) == 1:
        near = np.abs(grid_t - t[0]) <= 0.5 * grid_period
        out[near] = values[0]
        return out, "nearest"
    same_rate = math.isfinite(period) and 0.8 <= period / grid_period <= 1.25
    j = np.searchsorted(t, grid_t)
    lo = np.clip(j - 1, 0, len(t) - 1)
    hi = np.clip(j, 0, len(t) - 1)
    if same_rate:
        pick = np.where(np.abs(t[hi] - grid_t) < np.abs(grid_t - t[lo]), hi, lo)
        ok = np.abs(t[pick] - grid_t) <= 1.5 * period
        out[ok] = values[pick[ok]]
        return out, "nearest"
    span = t[hi] - t[lo]
    inside = (grid_t >= t[0]) & (grid_t <= t[-1]) & (span <= 3 * period)
    w = np.where(span > 0, (grid_t - t[lo]) / np.where(span > 0, span, 1.0), 0.0)[:, None]
    interp = values[lo] * (1 - w) + values[hi] * w
    out[inside] = interp[inside]
    return out, "linear"


TRIM_SHARE = 0.01  # the share of the calibrated sensor's samples the common span may cut off,
TRIM_S = 2.0  # or the time (sensors of one board start and stop within a second or so)


def to_capture(
    path,
    imported: Imported,
    procedure: str,
    *,
    device: str | None = None,
    kinds: tuple[str, ...] | None = None,
) -> Capture:
    """The capture of ``imported`` for ``procedure``: rows at the primary sensor's samples."""
    primary = primary_kind(procedure)
    if primary is None:
        raise InputError(
            None,
            None,
            f"--procedure {procedure!r}: import makes captures for "
            f"{', '.join(registry.importable())} (a log holds no LDV or centrifuge-speed data)",
        )
    streams = {}
    for kind in KINDS:
        s = imported.streams.get(kind)
        if s is not None and (kinds is None or kind in kinds):
            s = clean_stream(path, s, imported.warnings)
            if s is not None:
                bad = np.isinf(s.xyz)  # a corrupt sample: an empty cell, said once
                if bad.any():
                    s.xyz[bad] = np.nan
                    imported.warnings.append(
                        f"{int(bad.any(axis=1).sum())} {NAME[kind]} samples hold infinite values: left empty"
                    )
                _check_limit(path, s)
                finite = s.xyz[np.isfinite(s.xyz)]
                if finite.size and not finite.any():  # a sensor not fitted, disabled or never read
                    zero = f"no {NAME[kind]} data (all zero): every {s.source} sample reads 0, 0, 0"
                    if kind == primary:
                        raise InputError(path, None, f"{procedure}: {zero}")
                    imported.warnings.append(f"{zero}: left out")
                    continue
                streams[kind] = s
    if primary not in streams:
        found = ", ".join(NAME[k] for k in streams) or "no accelerometer, gyro or magnetometer"
        raise InputError(path, None, f"{procedure} needs {NAME[primary]} data; this file has {found}")
    grid = streams[primary]
    if len(grid.t_s) < 2:
        raise InputError(
            path,
            None,
            f"only {len(grid.t_s)} {NAME[primary]} sample in the file: nothing to calibrate",
        )
    if grid.t_s[0] == grid.t_s[-1]:  # a driver that stamped every sample with one time
        raise InputError(
            path,
            None,
            f"{procedure}: the {len(grid.t_s)} {NAME[primary]} samples all carry one time "
            f"({grid.t_s[0]:.6g} s): the file gives them no time axis",
        )
    # rows inside the span every stream covers, unless that drops more than TRIM_SHARE of the
    # calibrated sensor's samples and more than TRIM_S: a sensor that starts late or stops early
    # (a compass that died half way) then keeps its cells empty outside its span, and one that
    # never overlaps is left out
    t0, t1 = grid.t_s[0], grid.t_s[-1]
    for kind, s in list(streams.items()):
        if kind != primary and (s.t_s[-1] < t0 or s.t_s[0] > t1):
            imported.warnings.append(
                f"the {NAME[kind]} ({s.t_s[0]:.3f}–{s.t_s[-1]:.3f} s) never overlaps the {NAME[primary]} "
                f"({t0:.3f}–{t1:.3f} s): left out"
            )
            del streams[kind]
        elif (
            kind != primary
            and not np.isfinite(align(grid.t_s, s.t_s, np.ones((len(s.t_s), 1)), _median_period(grid.t_s))[0]).any()
        ):
            # within the span but never at the same time: blocks taken in turn (ArduPilot's batch sampler)
            imported.warnings.append(
                f"the {NAME[kind]} samples ({s.source}) never fall near the {NAME[primary]}'s "
                "(the log took them at other times): left out"
            )
            del streams[kind]
    start = max(s.t_s[0] for s in streams.values())
    end = min(s.t_s[-1] for s in streams.values())
    rows = (grid.t_s >= start) & (grid.t_s <= end)
    cut_s = max(0.0, start - t0) + max(0.0, t1 - end)
    if len(grid.t_s) - int(rows.sum()) > TRIM_SHARE * len(grid.t_s) and cut_s > TRIM_S:
        for kind, s in streams.items():
            if kind != primary and (s.t_s[0] > t0 or s.t_s[-1] < t1):
                imported.warnings.append(
                    f"the {NAME[kind]} covers {s.t_s[0] - t0:.6g}–{s.t_s[-1] - t0:.6g} s of the "
                    f"{NAME[primary]}'s {t1 - t0:.6g} s: its cells are empty outside that (every "
                    f"{NAME[primary]} sample is kept)"
                )
        rows = np.ones(len(grid.t_s), dtype=bool)
    grid_t = grid.t_s[rows]
    grid_period = _median_period(grid_t)
    if len(grid_t) < 2 or not math.isfinite(grid_period):
        raise InputError(
            path,
            None,
            f"fewer than 2 {NAME[primary]} samples where all sensors overlap",
        )
    # to the nanosecond: no log stamps finer, and no float noise from the subtraction in the file
    columns: dict[str, np.ndarray] = {"t": np.round(grid_t - grid_t[0], 9)}
    meta: dict[str, str] = {"station-capture": "1", "procedure": procedure}
    if device:
        meta["device"] = device
    elif imported.meta.get("device"):
        meta["device"] = imported.meta["device"]
    how = []
    for kind in KINDS:
        s = streams.get(kind)
        if s is None:
            continue
        if kind == primary or (len(s.t_s) == len(grid.t_s) and np.array_equal(s.t_s, grid.t_s)):
            values = s.xyz[rows]  # the same samples (one message or one CSV row holds both)
        else:
            values, mode = align(grid_t, s.t_s, s.xyz, grid_period)
            how.append(f"{kind} {mode}")
        for j, name in enumerate(COLUMNS[kind]):
            columns[name] = values[:, j]
        meta[f"{kind}_unit"] = s.unit
    temp = grid.temp_c[rows] if grid.temp_c is not None else None
    if temp is not None:
        from station.capture import ABSOLUTE_ZERO_C, TEMP_MAX_C

        with np.errstate(invalid="ignore"):
            impossible = (temp < ABSOLUTE_ZERO_C) | (temp > TEMP_MAX_C)
        if impossible.any():  # a driver's "no reading" value, a corrupt field: the IMU data stand
            temp = np.where(impossible, np.nan, temp)
            imported.warnings.append(
                f"{int(impossible.sum())} temperature sample{'s' if impossible.sum() != 1 else ''} below absolute zero "
                f"or above {TEMP_MAX_C:g} °C "
                f"(the first {grid.temp_c[rows][impossible][0]:g}): left empty"
            )
    if temp is not None and np.isfinite(temp).any():
        columns["temp_c"] = temp
    for key, value in imported.meta.items():
        if key != "device":
            meta.setdefault(key, value)
    meta["sample_rate_hz"] = f"{1.0 / grid_period:.6g}"
    if grid.device_id is not None:
        meta["sensor_device_id"] = str(int(grid.device_id))
    if grid.instance is not None:
        meta["sensor_instance"] = str(int(grid.instance))
    for kind, s in streams.items():
        if s.device_id is not None:
            meta[f"{kind}_device_id"] = str(int(s.device_id))
        if s.external is not None:
            meta[f"{kind}_external"] = "true" if s.external else "false"
    meta["import_source"] = "; ".join(dict.fromkeys(streams[k].source for k in KINDS if k in streams))
    if how:
        meta["import_align"] = f"rows at the {primary} samples; " + ", ".join(how)
    # parameters last, in name order, after the keys a reader looks for first
    params = sorted(k for k in meta if k.startswith("param."))
    meta = {k: v for k, v in meta.items() if not k.startswith("param.")} | {k: meta[k] for k in params}
    return Capture(meta=meta, columns=columns, path=None if path is None else str(path))
