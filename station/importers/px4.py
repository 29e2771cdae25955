"""PX4 flight logs (ULog, ``.ulg``) through pyulog.

Topics read (PX4's own message definitions, ``msg/SensorAccel.msg`` etc.):

- ``sensor_accel`` / ``sensor_gyro`` / ``sensor_mag``: one uORB instance per sensor, with its
  ``device_id``; ``x y z`` in m/s², rad/s and gauss, in the board frame. Since PX4 v1.11 these
  are the drivers' output **before** the calibration: PX4's sensors module applies
  ``CAL_<ACC|GYRO|MAG>n_*`` afterwards (``Correct(): R · ((data − thermal_offset − offset) ∘
  scale)`` in ``src/lib/sensor_calibration``) to the slot ``n`` whose ``CAL_…n_ID`` equals the
  ``device_id``. So ``corrected: false``. Older logs whose ``sensor_accel`` still has ``x_raw``
  were calibrated inside the driver: ``corrected: true``.
- ``sensor_combined`` (when the per-sensor topics are not logged, or ``--source combined``):
  ``accelerometer_m_s2`` and ``gyro_rad`` (and ``magnetometer_ga`` in old logs; since v1.11
  the calibrated compass is ``vehicle_magnetometer.magnetometer_ga``) after the calibration and
  the board rotation (``SENS_BOARD_ROT``): ``corrected: true``.

Every ``CAL_*`` and ``SENS_BOARD_*`` parameter in the log goes into the metadata as
``param.<NAME>`` with its value at the start of the imported data; parameters changed during
the data are listed in ``params_changed``.
"""

from __future__ import annotations

import contextlib
import io

import numpy as np

from station.errors import InputError
from station.fileio import LOG_MAGIC
from station.importers._common import (
    FRD,
    INSTANCE_ADVICE,
    Imported,
    Stream,
    fmt_param,
    frame_in_frd,
    set_date,
    several_instances_warning,
)
from station.importers.options import source_values

RAW_TOPICS = {"accel": "sensor_accel", "gyro": "sensor_gyro", "mag": "sensor_mag"}
CAL_PREFIX = {"accel": "CAL_ACC", "gyro": "CAL_GYRO", "mag": "CAL_MAG"}
UNITS = {"accel": "m/s^2", "gyro": "rad/s", "mag": "gauss"}
COMBINED = {"accel": "accelerometer_m_s2", "gyro": "gyro_rad", "mag": "magnetometer_ga"}
RELATIVE_TIMESTAMP_INVALID = 0x7FFFFFFF  # PX4 sensor_combined: "no sample of this sensor yet"
GPS_TOPICS = ("sensor_gps", "vehicle_gps_position")
PARAM_PREFIXES = ("CAL_", "SENS_BOARD_")
SOURCES = source_values("px4")  # the registry: station.importers.options.SOURCES


class _CutWatch:
    """The log file as pyulog reads it, remembering the first read that came back short (the
    first that met the end of the file): pyulog stops without a word where a cut file ends
    inside a message. The first, not the last: a log cut inside its definitions has pyulog
    read on into its data section, whose next read finds the end cleanly (3 bytes asked, none
    there) and would hide the cut."""

    def __init__(self, fh) -> None:
        self._fh = fh
        self.short: tuple[int, int, int] | None = None  # (asked, got, where) of the first short read

    def read(self, n=-1):
        data = self._fh.read(n)
        if self.short is None and n is not None and 0 < n and len(data) < n:
            self.short = (n, len(data), self._fh.tell())
        return data

    def cut_at(self) -> int | None:
        """The byte where the log ends inside a message, None when it ends between two
        (the read that met the end asked for a message header and found nothing)."""
        if self.short is None or self.short[:2] == (3, 0):
            return None
        return self.short[2]

    def __getattr__(self, name):
        return getattr(self._fh, name)


ULOG_HEADER_BYTES = 16  # the file header: the 7 magic bytes, the version byte, the start time (uint64 us)


def _header_problem(head: bytes) -> str | None:
    """What is wrong with a ULog's first (up to 16) bytes, in the station's words (pyulog's are
    'Invalid file format (Header too short)'), or None: a header cut short, or no ULog header."""
    magic = next(m for m, fmt, _ in LOG_MAGIC if fmt == "px4")
    n = len(head)
    if n >= ULOG_HEADER_BYTES and head.startswith(magic):
        return None
    if n < ULOG_HEADER_BYTES and (head.startswith(magic) or magic.startswith(head)):
        return (
            f"a PX4 ULog cut short inside its {ULOG_HEADER_BYTES}-byte header ({n} byte{'s' if n != 1 else ''} "
            "in the file): nothing to read (a copy or a write stopped part-way)"
        )
    return (
        f"not a PX4 ULog file: it does not start with the ULog header ({magic[:4].decode()} "
        f"{magic[4:].hex(' ')}; its first bytes: {head[:8].hex(' ')})"
    )


def _load(path):
    from pyulog import ULog

    wanted = list(RAW_TOPICS.values()) + [
        "sensor_combined",
        "vehicle_magnetometer",
        "sensor_selection",
        *GPS_TOPICS,
    ]
    try:
        with open(path, "rb") as fh, contextlib.redirect_stdout(io.StringIO()):  # pyulog reports oddities on stdout
            problem = _header_problem(fh.read(ULOG_HEADER_BYTES))
            if problem:
                raise InputError(path, None, problem)
            fh.seek(0)
            watch = _CutWatch(fh)
            ulog = ULog(watch, wanted)
            ulog.station_cut_at = watch.cut_at()
            return ulog
    except InputError:
        raise
    except FileNotFoundError:
        raise InputError(path, None, "no such file") from None
    except IsADirectoryError:
        raise InputError(path, None, "is a directory, not a ULog file") from None
    except PermissionError:
        raise InputError(path, None, "permission denied") from None
    except Exception as exc:  # noqa: BLE001 - pyulog raises bare Exceptions on a bad header
        raise InputError(path, None, f"not a readable PX4 ULog file ({type(exc).__name__}: {exc})") from None


SHOWN_TOPICS = 6  # topics named in the refusal of a log without IMU data


def _what_it_holds(path, ulog) -> str:
    """What a ULog without IMU data holds instead, for its refusal: no data message at all (its
    header and definitions only), or the topics it logged. ``ulog`` was read for the IMU topics
    alone; the others are counted by reading the log again, all of it (this path only)."""
    from pyulog import ULog

    topics = None
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            topics = sorted({d.name for d in ULog(str(path)).data_list})
    except Exception:  # noqa: BLE001 - the refusal stands without the list
        pass
    if topics == []:
        return (
            f"the log holds no data messages, only its header ({len(ulog.message_formats)} topic formats, "
            f"{len(ulog.initial_parameters)} parameters): no topic was logged"
        )
    said = "the log has neither sensor_accel/sensor_gyro/sensor_mag nor sensor_combined"
    if topics:
        more = len(topics) - SHOWN_TOPICS
        said += (
            f"; its {len(topics)} logged topic{'s' if len(topics) != 1 else ''}: {', '.join(topics[:SHOWN_TOPICS])}"
            + (f" (+{more} more)" if more > 0 else "")
        )
    return said


def _readable_param(name, value) -> bool:
    """A parameter as a firmware writes it: a name (no control characters, no ':') and an int or
    float. A flipped byte in its definition ('flxat CAL_ACC0_XOFF') leaves pyulog the raw bytes."""
    number = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
    return number and isinstance(name, str) and name.isprintable() and ":" not in name and name == name.strip() != ""


def _topics(ulog, name: str) -> dict[int, object]:
    return {d.multi_id: d for d in ulog.data_list if d.name == name and len(d.data.get("timestamp", ())) > 0}


def _time_us(data: dict) -> np.ndarray:
    ts = data.get("timestamp_sample")
    if ts is None or not np.any(ts):
        ts = data["timestamp"]
    return np.asarray(ts, dtype=np.int64)


def _slot(params: dict, kind: str, device_id: int | None) -> int | None:
    """n of the CAL_<S>n_ID slot that holds ``device_id`` (the slot PX4 applies), or None."""
    if not device_id:
        return None
    for n in range(8):
        if params.get(f"{CAL_PREFIX[kind]}{n}_ID") == device_id:
            return n
    return None


def _voted_sensor(path, params: dict, kind: str, instance: int | None, needed: bool, warnings: list[str]) -> int | None:
    """The device id of the sensor in ``sensor_combined`` of a log without ``sensor_selection``
    (PX4 before v1.10). There the sensors module's voter (``VotedSensorsUpdate``, ECL's
    ``DataValidatorGroup::get_best``) chose it by the drivers' uORB priority and the sensors'
    health, sample by sample; no parameter chooses it (``CAL_*_PRIME`` is the calibration's
    primary, which only the preflight check requires present). So: the one slot with a
    ``CAL_*n_ID`` when the board has one such sensor; the slot ``--instance`` names; otherwise
    None, said in one warning line naming the candidates (``needed``: the procedure's sensor,
    whose --instance slot must hold one, whose ambiguity is said; the others are left unknown)."""
    prefix = CAL_PREFIX[kind]
    slots = {n: int(params[f"{prefix}{n}_ID"]) for n in range(8) if params.get(f"{prefix}{n}_ID")}
    if instance is not None and instance in slots:
        return slots[instance]
    if instance is not None and needed:
        have = ", ".join(f"{prefix}{n}_ID {v}" for n, v in slots.items()) or f"no {prefix}n_ID set"
        raise InputError(path, None, f"--instance {instance}: no {prefix}{instance}_ID in the log ({have})")
    if len(slots) == 1:
        return next(iter(slots.values()))
    if len(slots) > 1 and needed:
        prime = params.get(f"{prefix}_PRIME")
        warnings.append(
            f"sensor_combined's {kind} is the sensor PX4's voter chose (priority and health; this log has no "
            f"sensor_selection topic to say which): {' or '.join(f'{prefix}{n}_ID {v}' for n, v in slots.items())}"
            + (f" ({prefix}_PRIME {int(prime)} is the calibration's primary, not the voter's choice)" if prime else "")
            + f"; {INSTANCE_ADVICE}"
        )
    return None


def _selected_while(sel: dict, kind: str, t_us) -> list[tuple[int, int]]:
    """(time µs, device id) of each sensor PX4's ``sensor_selection`` names for ``kind`` while the
    samples ``t_us`` run: the record in effect at the first sample (the first record where none
    comes before it), then each change up to the last sample. Records before the samples no longer
    say which sensor they hold (a log whose selection changed before the data start named none)."""
    ts = np.asarray(sel.get("timestamp", []), dtype=np.int64)
    ids = np.asarray(sel.get(f"{kind}_device_id", []), dtype=np.int64)
    if not len(ids) or not len(t_us):
        return []
    start = max(int(np.searchsorted(ts, t_us[0], side="right")) - 1, 0)
    out: list[tuple[int, int]] = []
    for t, i in zip(ts[start:].tolist(), ids[start:].tolist()):
        if t > t_us[-1]:
            break
        if not out or out[-1][1] != i:
            out.append((max(t, int(t_us[0])), i))
    return out


def _external(data: dict) -> bool | None:
    """The topic's own ``is_external`` (sensor_mag has it: the driver's word that the sensor is
    not on the board), or None when the topic has no such field or it changes during the log."""
    flags = np.unique(np.asarray(data.get("is_external", []), dtype=bool))
    return bool(flags[0]) if len(flags) == 1 else None


def read(
    path,
    *,
    instance: int | None = None,
    source: str = "auto",
    kinds=None,
    primary: str | None = None,
) -> Imported:
    """Streams and metadata of a ULog file. ``instance``: the uORB instance of each
    ``sensor_*`` topic (default 0; a sensor without that instance is left out unless it is
    ``primary``, the one the procedure calibrates); ``source``: ``raw``, ``combined`` or ``auto``
    (raw topics where logged, else ``sensor_combined``)."""
    if source not in SOURCES:
        raise InputError(None, None, f"--source {source!r}: expected one of {', '.join(SOURCES)}")
    ulog = _load(path)
    params = {name: v for name, v in ulog.initial_parameters.items() if _readable_param(name, v)}
    unreadable = sorted(
        {repr(name) for name, v in ulog.initial_parameters.items() if not _readable_param(name, v)}
        | {repr(name) for _, name, v in ulog.changed_parameters if not _readable_param(name, v)}
    )
    info = ulog.msg_info_dict
    raw = {kind: _topics(ulog, topic) for kind, topic in RAW_TOPICS.items()}
    wanted = tuple(kinds or RAW_TOPICS)
    have_raw = any(raw[k] for k in wanted)
    combined = _topics(ulog, "sensor_combined")
    use_raw = source == "raw" or (source == "auto" and have_raw)
    cut = getattr(ulog, "station_cut_at", None)
    if not have_raw and not combined:  # whichever source: what the log holds instead
        raise InputError(
            path,
            None,
            "no IMU data: "
            + _what_it_holds(path, ulog)
            + (f" (it is cut short inside a message at byte {cut}, before any)" if cut is not None else ""),
        )
    if source == "raw" and not have_raw:
        raise InputError(
            path,
            None,
            "--source raw: the log has no sensor_accel, sensor_gyro or sensor_mag topic (try the combined source: "
            "--source combined, or 'combined' on the import screen)",
        )
    if not use_raw and not combined:
        raise InputError(
            path,
            None,
            "--source combined: the log has no sensor_combined, only the raw topics "
            + "/".join(RAW_TOPICS[k] for k in wanted if raw[k])
            + " (--source raw, or 'raw topics' on the import screen)",
        )
    streams: dict[str, Stream] = {}
    meta: dict[str, str] = {"firmware": "px4"}
    warnings: list[str] = []
    t0_us = None
    if use_raw:
        corrected = False
        several: dict[str, list[int]] = {}  # read without --instance: the topics with other instances
        reads: set[int] = set()
        for kind, topics in raw.items():
            if not topics:
                continue
            inst = 0 if instance is None else instance
            if instance is None and len(topics) > 1:
                several[RAW_TOPICS[kind]] = sorted(topics)
                reads.add(inst if inst in topics else min(topics))
            if inst not in topics:
                if instance is None:
                    inst = min(topics)
                elif primary is not None and kind != primary:
                    warnings.append(f"--instance {instance}: no {RAW_TOPICS[kind]}[{instance}], so no {kind} columns")
                    continue
                else:
                    raise InputError(
                        path,
                        None,
                        f"--instance {instance}: {RAW_TOPICS[kind]} has instances "
                        f"{', '.join(map(str, sorted(topics)))}",
                    )
            d = topics[inst].data
            ids = np.unique(np.asarray(d.get("device_id", [0])))
            if len(ids) > 1:
                raise InputError(
                    path,
                    None,
                    f"{RAW_TOPICS[kind]}[{inst}] changes device_id during the log "
                    f"({', '.join(map(str, ids))}): not one sensor",
                )
            device_id = int(ids[0]) or None
            if "x_raw" in d:  # before PX4 v1.11 the driver applied the calibration
                corrected = True
            t_us = _time_us(d)
            temp = d.get("temperature")
            streams[kind] = Stream(
                kind,
                t_us.astype(np.float64),
                np.column_stack([d["x"], d["y"], d["z"]]),
                UNITS[kind],
                f"{RAW_TOPICS[kind]}[{inst}]",
                device_id,
                _slot(params, kind, device_id),
                None if temp is None else np.asarray(temp, dtype=np.float64),
                _external(d),
            )
            if device_id is not None and streams[kind].instance is None:
                warnings.append(
                    f"no {CAL_PREFIX[kind]}n_ID holds device id {device_id}: the board applies "
                    "no calibration slot to this sensor"
                )
        meta["corrected"] = "true" if corrected else "false"
        said = several_instances_warning(several, next(iter(reads)) if len(reads) == 1 else "the first of each")
        warnings += [said] if said else []
        n_raw = max(len(s.t_s) for s in streams.values()) if streams else 0
        n_comb = len(combined[min(combined)].data["timestamp"]) if combined else 0
        if n_comb > 4 * n_raw:
            warnings.append(
                f"the raw sensor topics hold {n_raw} sample{'s' if n_raw != 1 else ''}, sensor_combined {n_comb}: "
                "the combined source reads those (already corrected by the board: --source combined, "
                "or 'combined' on the import screen)"
            )
    else:
        selection = _topics(ulog, "sensor_selection")
        # without sensor_selection (PX4 before v1.10), --instance N names the CAL_*N slot of the
        # sensor the voter chose (_voted_sensor); with it, the log says which
        if instance not in (None, 0) and selection:  # one stream: the board's selected sensor
            raise InputError(
                path,
                None,
                f"--instance {instance}: "
                + (
                    "the log has no sensor_accel/sensor_gyro/sensor_mag topics to pick it from; "
                    if not have_raw
                    else ""
                )
                + "sensor_combined holds one stream, the board's selected sensor (--instance 0 or none reads it)",
            )
        d = combined[min(combined)].data
        t_us = np.asarray(d["timestamp"], dtype=np.int64)
        sel = selection[min(selection)].data if selection else {}
        for kind, field in COMBINED.items():
            cols = [f"{field}[{j}]" for j in range(3)]
            if not all(c in d for c in cols):
                continue
            if selection:
                chosen = _selected_while(sel, kind, t_us)
                device_id = chosen[0][1] if len(chosen) == 1 and chosen[0][1] else None
                if len(chosen) > 1 and kind == (primary or kind):
                    warnings.append(
                        f"sensor_combined's {kind} came from {len({i for _, i in chosen})} sensors while the samples "
                        "run (sensor_selection: "
                        + ", ".join(
                            f"{i} from {'the start' if k == 0 else f'{(t - t_us[0]) * 1e-6:.3f} s'}"
                            for k, (t, i) in enumerate(chosen)
                        )
                        + "): the capture mixes them and names no sensor slot; import one sensor's own topic "
                        "(--source raw, --instance N) or a stretch that one sensor recorded"
                    )
            else:
                device_id = _voted_sensor(path, params, kind, instance, kind == (primary or kind), warnings)
            t_k, rows, how = t_us, slice(None), ""
            rel = d.get("magnetometer_timestamp_relative") if kind == "mag" else None
            if rel is not None:
                # the magnetometer is slower than the gyro whose time stamps the topic: its newest
                # sample is repeated in every row until the next one (sample.ulg: 17,070 rows, 6,759
                # samples). Each is read once, at its own time (timestamp + ..._timestamp_relative)
                rel = np.asarray(rel, dtype=np.int64)
                new = (rel != RELATIVE_TIMESTAMP_INVALID) & np.r_[True, np.diff(t_us + rel) != 0]
                t_new = (t_us + rel)[new]
                if new.sum() < len(new) and np.all(np.diff(t_new) > 0):
                    t_k, rows, how = t_new, new, ", each sample once at its own time"
            streams[kind] = Stream(
                kind,
                t_k.astype(np.float64),
                np.column_stack([np.asarray(d[c])[rows] for c in cols]),
                UNITS[kind],
                f"sensor_combined ({field}{how})",
                device_id,
                _slot(params, kind, device_id),
            )
        vmag = _topics(ulog, "vehicle_magnetometer")
        if "mag" not in streams and vmag:  # PX4 ≥ 1.11: the calibrated compass has its own topic
            inst = 0 if instance is None else instance
            if inst not in vmag:
                raise InputError(
                    path,
                    None,
                    f"--instance {inst}: vehicle_magnetometer has instances {', '.join(map(str, sorted(vmag)))}",
                )
            d = vmag[inst].data
            cols = [f"magnetometer_ga[{j}]" for j in range(3)]
            ids = np.unique(np.asarray(d.get("device_id", [0])))
            device_id = int(ids[0]) if len(ids) == 1 and ids[0] else None
            if device_id is None and inst == 0 and "device_id" not in d:
                # PX4 1.11: vehicle_magnetometer has no device_id; it carries the selected compass,
                # which sensor_selection names (1.12 moved the id into vehicle_magnetometer)
                ids = np.unique(np.asarray(sel.get("mag_device_id", [0])))
                device_id = int(ids[0]) if len(ids) == 1 and ids[0] else None
            streams["mag"] = Stream(
                "mag",
                _time_us(d).astype(np.float64),
                np.column_stack([d[c] for c in cols]),
                UNITS["mag"],
                f"vehicle_magnetometer[{inst}]",
                device_id,
                _slot(params, "mag", device_id),
            )
        meta["corrected"] = "true"
    if not streams:
        raise InputError(path, None, "no accelerometer, gyro or magnetometer samples in the log")
    t0_us = min(s.t_s[0] for s in streams.values())
    t1_us = max(s.t_s[-1] for s in streams.values())
    for s in streams.values():  # µs → s from the first sample (subtract first: SITL stamps are Unix µs)
        s.t_s = (s.t_s - t0_us) * 1e-6
    # parameters in use at the start of the data; any change while the data run is listed
    late: set[str] = set()
    for ts, name, value in sorted(ulog.changed_parameters, key=lambda c: c[0]):
        if not _readable_param(name, value) or not name.startswith(PARAM_PREFIXES):
            continue
        if ts <= t0_us:
            params[name] = value
        elif ts <= t1_us:
            late.add(name)
    if cut is not None:  # a power loss or a copy cut short: what was written before it is whole
        n_before = len(next(iter(streams.values())).t_s)
        warnings.append(
            f"the log is cut short inside a message at byte {cut}: the samples before it are imported, "
            f"{n_before} sample{'s' if n_before != 1 else ''} up to {max(s.t_s[-1] for s in streams.values()):g} s"
        )
    if getattr(ulog, "file_corruption", False):  # pyulog skipped to the next sync marker: never silently
        warnings.append(
            "the log holds a corrupt stretch (pyulog skipped it to the next sync marker): the messages in it "
            "are lost, a gap in the samples there"
        )
    # the logger's own record of what it lost (ULog 'O' dropout messages, duration in ms): the
    # samples are missing there, gaps in the time axis, which nothing else in the capture says
    lost = [d.duration for d in getattr(ulog, "dropouts", []) if d.duration > 0 and t0_us <= d.timestamp <= t1_us]
    if lost:
        warnings.append(
            f"the logger dropped messages {len(lost)} time{'s' if len(lost) != 1 else ''} while the samples run "
            f"({sum(lost)} ms in all, the longest {max(lost)} ms; its dropout records): the samples lost there are "
            "gaps in the time axis"
        )
    if unreadable:
        warnings.append(
            f"{len(unreadable)} parameter(s) with no number in the log (a corrupt definition): "
            f"{', '.join(unreadable[:5])}{' ...' if len(unreadable) > 5 else ''} left out of param.*"
        )
    if late:
        meta["params_changed"] = ",".join(sorted(late))
        warnings.append(
            f"parameters changed while the data were logged: {', '.join(sorted(late))} "
            "(param.* holds the values at the start)"
        )
    board = str(info.get("ver_hw") or "px4")
    uid = str(info.get("sys_uuid") or "")
    meta["board"] = board
    if uid:
        meta["board_uid"] = uid
    if info.get("ver_sw"):
        meta["firmware_version"] = str(info.get("ver_sw_branch") or info["ver_sw"])
    frame = FRD if meta["corrected"] == "true" else _board_frame(params, streams)
    if frame:
        meta["frame"] = frame
    _place_and_date(ulog, t0_us, meta, warnings)
    for name in sorted(params):
        if name.startswith(PARAM_PREFIXES):
            meta[f"param.{name}"] = fmt_param(params[name])
    return Imported(streams, meta, warnings)


def _board_frame(params: dict, streams: dict) -> str | None:
    """Where the raw topics' axes point on the vehicle: the board frame reaches the FRD body frame
    through ``CAL_*n_ROT`` (an external sensor, ≥ 0) or ``SENS_BOARD_ROT`` (an internal one;
    ``Correct()``, src/lib/sensor_calibration). None when the rotation is not in the log, not a
    listed one, or not the same for the accelerometer and the gyro. The level adjustment
    ``SENS_BOARD_*_OFF`` (a few degrees) is left out: P4 measures the tilt itself."""
    from station.errors import UnsupportedError
    from station.firmware_export import rotation_matrix

    frames = set()
    for kind in ("accel", "gyro"):
        s = streams.get(kind)
        if s is None:
            continue
        rot = params.get(f"{CAL_PREFIX[kind]}{s.instance}_ROT") if s.instance is not None else None
        name = f"{CAL_PREFIX[kind]}{s.instance}_ROT"
        if rot is None or rot < 0:
            rot, name = params.get("SENS_BOARD_ROT"), "SENS_BOARD_ROT"
        if rot is None:
            return None
        try:
            frames.add(frame_in_frd(rotation_matrix("px4", rot, name, "px4")))
        except UnsupportedError:
            return None
    return frames.pop() if len(frames) == 1 else None


def default_device(imported: Imported, kind: str) -> str | None:
    """``<board>[-<uid>]-<sensor><device id>``: one history per sensor of one board."""
    s = imported.streams.get(kind)
    board = imported.meta.get("board", "px4")
    uid = imported.meta.get("board_uid")
    name = f"{board}-{uid}" if uid else board
    return f"{name}-{kind}{s.device_id}" if s is not None and s.device_id else name


def _place_and_date(ulog, t0_us: float, meta: dict[str, str], warnings: list[str]) -> None:
    """``date`` from the GPS's UTC time, ``latitude_deg``… from its 3-D fixes (median)."""
    for name in GPS_TOPICS:
        topics = _topics(ulog, name)
        if not topics:
            continue
        d = topics[min(topics)].data
        ts = np.asarray(d["timestamp"], dtype=np.float64)
        utc = np.asarray(d.get("time_utc_usec", np.zeros(len(ts))), dtype=np.float64)
        good = utc > 0
        if good.any():
            i = int(np.flatnonzero(good)[0])
            set_date(meta, warnings, (utc[i] - ts[i] + t0_us) * 1e-6, "GPS")
        fix = np.asarray(d.get("fix_type", np.zeros(len(ts))))
        fixed = fix >= 3
        if fixed.any():
            if "latitude_deg" in d:
                lat, lon = (
                    np.asarray(d["latitude_deg"])[fixed],
                    np.asarray(d["longitude_deg"])[fixed],
                )
                alt = np.asarray(d.get("altitude_msl_m", np.full(len(ts), np.nan)))[fixed]
            elif "lat" in d:
                lat, lon = (
                    np.asarray(d["lat"])[fixed] * 1e-7,
                    np.asarray(d["lon"])[fixed] * 1e-7,
                )
                alt = np.asarray(d.get("alt", np.full(len(ts), np.nan)))[fixed] * 1e-3
            else:
                return
            meta["latitude_deg"] = f"{float(np.median(lat)):.7f}"
            meta["longitude_deg"] = f"{float(np.median(lon)):.7f}"
            if np.isfinite(alt).any():
                meta["altitude_m"] = f"{float(np.nanmedian(alt)):.2f}"
        return
