"""ArduPilot DataFlash logs (``.bin``) and MAVLink telemetry logs (``.tlog``) through pymavlink.

DataFlash (``DFReader_binary``), ArduPilot's ``LogStructure`` definitions:

- ``IMU`` (``TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,…,T``, units ``s#EEEooo--O``): rad/s and
  m/s², the IMU's output after the calibration in use, rotated to the body frame. Old logs name
  the second and third IMU ``IMU2``/``IMU3`` (no ``I`` field).
- ``MAG`` (``TimeUS,I,MagX,MagY,MagZ,OfsX,…``, units ``G`` × multiplier ``C`` = 10⁻³): milligauss,
  offsets, diagonals and motor compensation applied, body frame.
- ``PARM`` (``Name,Value``): the parameters; their value before the first sample is the one in use.
  Where the log carries ``FMTU``/``UNIT``/``MULT``, the units are taken from it.

MAVLink logs (``.tlog``: each message preceded by its 8-byte big-endian arrival time in µs, as
pymavlink's ``mavlogfile`` writes them) are read with ``mavutil.mavmmaplog``. Units come from
pymavlink's own message definitions (``fieldunits_by_name``): ``RAW_IMU`` and ``SCALED_IMU*``
are mG (milli-g), mrad/s and mgauss; ``HIGHRES_IMU`` m/s², rad/s, gauss. ArduPilot fills
``RAW_IMU`` with the same scaled, corrected values as ``SCALED_IMU``; the MAVLink standard
calls ``RAW_IMU`` raw ADC counts, so from any other autopilot it is imported as ``counts``.
Parameters come from ``PARAM_VALUE`` (ArduPilot sends integers as float values, PX4 byte-wise).

All of these are corrected by the board: ``corrected: true``.
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import struct

import numpy as np

from station.errors import InputError
from station.importers._common import Imported, Stream, fmt_param, iso_utc

PARAM_PREFIXES = ("INS_", "COMPASS_", "AHRS_ORIENTATION", "AHRS_TRIM_")
# DataFlash unit strings (after FMTU/MULT) → capture units
DF_UNITS = {
    "rad/s": "rad/s",
    "m/s/s": "m/s^2",
    "m/s^2": "m/s^2",
    "mGauss": "mgauss",
    "Gauss": "gauss",
    "mG": "mgauss",
    "G": "gauss",
}
DF_DEFAULT = {
    "accel": "m/s^2",
    "gyro": "rad/s",
    "mag": "mgauss",
}  # ArduPilot LogStructure IMU/MAG
GPS_EPOCH_UNIX_S = 315964800.0  # 1980-01-06T00:00:00Z
GPS_LEAP_S = 18.0  # GPS − UTC since 2017-01-01
MAV_AUTOPILOT = {3: "ardupilot", 12: "px4"}
# pymavlink's unit strings → capture units (per sensor: 'mG' is milli-g in MAVLink)
MAV_UNITS = {
    ("accel", "mG"): "mg",
    ("accel", "m/s/s"): "m/s^2",
    ("gyro", "mrad/s"): "mrad/s",
    ("gyro", "rad/s"): "rad/s",
    ("mag", "mgauss"): "mgauss",
    ("mag", "gauss"): "gauss",
}
MAV_FIELDS = {
    "accel": ("xacc", "yacc", "zacc"),
    "gyro": ("xgyro", "ygyro", "zgyro"),
    "mag": ("xmag", "ymag", "zmag"),
}
IMU_MESSAGES = {
    0: ("RAW_IMU", "SCALED_IMU", "HIGHRES_IMU"),
    1: ("SCALED_IMU2",),
    2: ("SCALED_IMU3",),
}
INT_PARAM_TYPES = {1, 2, 3, 4, 5, 6, 7, 8}  # MAV_PARAM_TYPE_UINT8 … INT64


@contextlib.contextmanager
def _quiet():
    """pymavlink prints progress and oddities on stdout/stderr: not for the operator."""
    with (
        contextlib.redirect_stdout(io.StringIO()),
        contextlib.redirect_stderr(io.StringIO()),
    ):
        yield


def _open_error(path, exc: Exception, what: str) -> InputError:
    if isinstance(exc, FileNotFoundError):
        return InputError(path, None, "no such file")
    if isinstance(exc, IsADirectoryError):
        return InputError(path, None, f"is a directory, not {what}")
    if isinstance(exc, PermissionError):
        return InputError(path, None, "permission denied")
    return InputError(path, None, f"not a readable {what} ({type(exc).__name__}: {exc})")


def _params_meta(params: dict[str, float], meta: dict[str, str]) -> None:
    for name in sorted(params):
        if name.startswith(PARAM_PREFIXES):
            meta[f"param.{name}"] = fmt_param(params[name])


def _ap_device_id(params: dict, kind: str, instance: int) -> int | None:
    """The sensor's id from INS_ACC_ID / INS_ACC2_ID …, INS_GYR_ID …, COMPASS_DEV_ID / _DEV_ID2 …"""
    n = "" if instance == 0 else str(instance + 1)
    name = {
        "accel": f"INS_ACC{n}_ID",
        "gyro": f"INS_GYR{n}_ID",
        "mag": f"COMPASS_DEV_ID{n}",
    }[kind]
    value = params.get(name)
    return int(value) if value else None


# ------------------------------------------------------------------------------------- DataFlash


def read_bin(path, *, instance: int | None = None, kinds=None) -> Imported:
    """IMU/MAG of one instance (default 0) and the parameters in use from a DataFlash log."""
    from pymavlink import DFReader

    inst = 0 if instance is None else int(instance)
    # pymavlink's compiled indexer prints "bad header" lines straight to file descriptor 2, past
    # any Python redirection: its pure-Python indexer (same result) prints through sys.stderr.
    fast = os.environ.get("PYMAVLINK_FAST_INDEX")
    os.environ["PYMAVLINK_FAST_INDEX"] = "0"
    try:
        with _quiet():
            log = DFReader.DFReader_binary(str(path), zero_time_base=True)
    except Exception as exc:  # noqa: BLE001 - any reader failure is one line
        raise _open_error(path, exc, "ArduPilot DataFlash log") from None
    finally:
        if fast is None:
            os.environ.pop("PYMAVLINK_FAST_INDEX", None)
        else:
            os.environ["PYMAVLINK_FAST_INDEX"] = fast
    names = set(getattr(log, "name_to_id", {}))
    imu_name = "IMU" if inst == 0 or "IMU" in names and f"IMU{inst + 1}" not in names else f"IMU{inst + 1}"
    mag_name = "MAG" if inst == 0 or "MAG" in names and f"MAG{inst + 1}" not in names else f"MAG{inst + 1}"
    types = [imu_name, mag_name, "PARM", "GPS"]
    rows: dict[str, list] = {"accel": [], "gyro": [], "mag": []}
    temps: list[float] = []
    params: dict[str, float] = {}
    late: set[str] = set()
    first_us = None
    gps_utc_offset = None
    fixes: list[tuple[float, float, float]] = []
    units = {}
    instances_seen: dict[str, set] = {imu_name: set(), mag_name: set()}
    try:
        with _quiet():
            while True:
                m = log.recv_match(type=types)
                if m is None:
                    break
                name = m.get_type()
                if name in (
                    "IMU",
                    "MAG",
                    imu_name,
                    mag_name,
                ):  # the bulk: only the fields used
                    cols = m.fmt.colhash
                    if "I" in cols:
                        i = m.I
                        instances_seen[name].add(i)
                        if i != inst and name in ("IMU", "MAG"):
                            continue
                    t_us = m.TimeUS
                    first_us = t_us if first_us is None else first_us
                    if name == imu_name:
                        rows["gyro"].append((t_us, m.GyrX, m.GyrY, m.GyrZ))
                        rows["accel"].append((t_us, m.AccX, m.AccY, m.AccZ))
                        temps.append(m.T if "T" in cols else math.nan)
                        if "accel" not in units:
                            units["accel"] = m.fmt.get_unit("AccX") if m.fmt.units else ""
                            units["gyro"] = m.fmt.get_unit("GyrX") if m.fmt.units else ""
                    else:
                        rows["mag"].append((t_us, m.MagX, m.MagY, m.MagZ))
                        if "mag" not in units:
                            units["mag"] = m.fmt.get_unit("MagX") if m.fmt.units else ""
                    continue
                d = m.to_dict()
                if name == "PARM":
                    if first_us is None:
                        params[d["Name"]] = d["Value"]
                    elif str(d["Name"]).startswith(PARAM_PREFIXES) and params.get(d["Name"]) != d["Value"]:
                        late.add(d["Name"])
                    continue
                if name == "GPS":
                    _df_gps(d, fixes)
                    if gps_utc_offset is None and d.get("GWk") and d.get("Status", 0) >= 3:
                        gps_utc_offset = (
                            GPS_EPOCH_UNIX_S + d["GWk"] * 604800.0 + d["GMS"] * 1e-3 - GPS_LEAP_S - d["TimeUS"] * 1e-6
                        )
                    continue
    except Exception as exc:  # noqa: BLE001
        raise InputError(path, None, f"cannot read the DataFlash log ({type(exc).__name__}: {exc})") from None
    finally:
        with contextlib.suppress(Exception):
            log.close()
    if not any(rows.values()):
        seen = {k: sorted(v) for k, v in instances_seen.items() if v}
        if seen:
            raise InputError(
                path,
                None,
                f"--instance {inst}: the log has "
                + "; ".join(f"{k} instances {', '.join(map(str, v))}" for k, v in seen.items()),
            )
        raise InputError(path, None, "no IMU or MAG messages in the DataFlash log")
    streams = {}
    for kind, r in rows.items():
        if not r or (kinds is not None and kind not in kinds):
            continue
        arr = np.asarray(r, dtype=np.float64)
        unit = DF_UNITS.get(units.get(kind) or "", None)
        if units.get(kind) and unit is None:
            raise InputError(
                path,
                None,
                f"{kind} unit {units[kind]!r} in the log's FMTU is not one the station knows",
            )
        stream = Stream(
            kind,
            arr[:, 0] * 1e-6,
            arr[:, 1:4],
            unit or DF_DEFAULT[kind],
            f"{imu_name if kind != 'mag' else mag_name}[{inst}]",
            _ap_device_id(params, kind, inst),
            inst,
            np.asarray(temps, dtype=np.float64) if kind == "accel" else None,
        )
        streams[kind] = stream
    meta: dict[str, str] = {"firmware": "ardupilot", "corrected": "true"}
    warnings = []
    if late:
        meta["params_changed"] = ",".join(sorted(late))
        warnings.append(
            f"parameters changed while the data were logged: {', '.join(sorted(late))} "
            "(param.* holds the values at the start)"
        )
    if gps_utc_offset is not None and first_us is not None:
        meta["date"] = iso_utc(gps_utc_offset + first_us * 1e-6)
    _place(fixes, meta)
    _params_meta(params, meta)
    return Imported(streams, meta, warnings)


def _df_gps(d: dict, fixes: list) -> None:
    if d.get("Status", 0) >= 3 and "Lat" in d and "Lng" in d:
        fixes.append((d["Lat"], d["Lng"], d.get("Alt", math.nan)))


def _place(fixes: list, meta: dict[str, str]) -> None:
    if not fixes:
        return
    arr = np.asarray(fixes, dtype=np.float64)
    meta["latitude_deg"] = f"{float(np.median(arr[:, 0])):.7f}"
    meta["longitude_deg"] = f"{float(np.median(arr[:, 1])):.7f}"
    if np.isfinite(arr[:, 2]).any():
        meta["altitude_m"] = f"{float(np.nanmedian(arr[:, 2])):.2f}"


# ---------------------------------------------------------------------------------- MAVLink tlog


def _param_value(msg, firmware: str | None) -> float | int:
    value = msg.param_value
    if msg.param_type in INT_PARAM_TYPES:
        if firmware == "px4":  # byte-wise: the integer's bytes sent inside the float
            return struct.unpack("<i", struct.pack("<f", value))[0]
        return round(value)
    return value


def read_tlog(path, *, instance: int | None = None, kinds=None) -> Imported:
    """RAW_IMU / SCALED_IMU{,2,3} / HIGHRES_IMU and PARAM_VALUE from a MAVLink log."""
    from pymavlink import mavutil

    inst = 0 if instance is None else int(instance)
    if inst not in IMU_MESSAGES:
        raise InputError(
            None,
            None,
            f"--instance {inst}: a MAVLink log carries IMU instances 0, 1, 2",
        )
    try:
        with _quiet():
            # mavmmaplog directly: mavlink_connection() would try to *execute* a path holding '/bin/'
            log = mavutil.mavmmaplog(str(path))
    except Exception as exc:  # noqa: BLE001
        raise _open_error(path, exc, "MAVLink log") from None
    wanted = list(IMU_MESSAGES[inst])
    by_type: dict[str, list] = {name: [] for name in wanted}
    arrivals: dict[str, float] = {}
    params: dict[str, object] = {}
    param_msgs = []
    firmware = None
    board_uid = None
    fixes: list[tuple[float, float, float]] = []
    first_t = None
    msg_class = {}
    seen: set = set()
    duplicates = 0
    try:
        with _quiet():
            while True:
                m = log.recv_match(type=wanted + ["PARAM_VALUE", "HEARTBEAT", "GPS_RAW_INT", "AUTOPILOT_VERSION"])
                if m is None:
                    break
                name = m.get_type()
                if name == "HEARTBEAT":
                    if firmware is None and m.autopilot in MAV_AUTOPILOT and m.get_srcComponent() == 1:
                        firmware = MAV_AUTOPILOT[m.autopilot]
                elif name == "PARAM_VALUE":
                    param_msgs.append((first_t is not None, m))
                elif name == "GPS_RAW_INT":
                    if m.fix_type >= 3:
                        fixes.append((m.lat * 1e-7, m.lon * 1e-7, m.alt * 1e-3))
                elif name == "AUTOPILOT_VERSION":
                    board_uid = board_uid or (m.uid or None)
                else:
                    t = m.time_usec * 1e-6 if hasattr(m, "time_usec") else m.time_boot_ms * 1e-3
                    key = (name, tuple(m.to_dict().values()))
                    if key in seen:  # the same message again (a log fed by two links): once
                        duplicates += 1
                        continue
                    seen.add(key)
                    by_type[name].append((t, m))
                    arrivals.setdefault(name, m._timestamp)
                    msg_class[name] = type(m)
                    first_t = t if first_t is None else first_t
    except Exception as exc:  # noqa: BLE001
        raise InputError(path, None, f"cannot read the MAVLink log ({type(exc).__name__}: {exc})") from None
    finally:
        with contextlib.suppress(Exception):
            log.close()
    name = next((n for n in wanted if by_type[n]), None)
    if name is None:
        raise InputError(
            path,
            None,
            f"no {' / '.join(wanted)} messages in the MAVLink log (instance {inst})",
        )
    late = set()
    for after_start, m in param_msgs:
        pid = m.param_id if isinstance(m.param_id, str) else m.param_id.decode(errors="replace")
        pid = pid.rstrip("\x00")
        value = _param_value(m, firmware)
        if not after_start or pid not in params:
            params[pid] = value
        elif params[pid] != value and pid.startswith(PARAM_PREFIXES):
            late.add(pid)
    samples = by_type[name]
    t = np.array([s[0] for s in samples])
    units = getattr(msg_class[name], "fieldunits_by_name", {})
    streams = {}
    for kind, fields in MAV_FIELDS.items():
        if kinds is not None and kind not in kinds:
            continue
        values = np.array([[getattr(m, f) for f in fields] for _, m in samples], dtype=np.float64)
        if kind == "mag" and not np.any(values):
            continue  # no compass behind this IMU message
        unit = MAV_UNITS.get((kind, units.get(fields[0], "")))
        if name == "RAW_IMU" and firmware != "ardupilot":
            unit = "counts"  # the MAVLink standard's raw ADC values
        if unit is None:
            raise InputError(
                path,
                None,
                f"{name}.{fields[0]}: unit {units.get(fields[0])!r} is not one the station knows",
            )
        streams[kind] = Stream(
            kind,
            t,
            values,
            unit,
            f"{name}",
            None if firmware != "ardupilot" else _ap_device_id(params, kind, inst),
            inst,
        )
    temps = [getattr(m, "temperature", None) for _, m in samples]
    if "accel" in streams and all(v is not None for v in temps) and any(temps):
        scale = 0.01 if units.get("temperature") == "cdegC" else 1.0
        streams["accel"].temp_c = np.asarray(temps, dtype=np.float64) * scale
    meta: dict[str, str] = {}
    if firmware:
        meta["firmware"] = firmware
    meta["corrected"] = "false" if (name == "RAW_IMU" and firmware != "ardupilot") else "true"
    if board_uid:
        meta["board_uid"] = str(board_uid)
    if arrivals[name] > 946684800:  # the ground station's clock (UTC) when the first sample came
        meta["date"] = iso_utc(arrivals[name])
    _place(fixes, meta)
    warnings = []
    if late:
        meta["params_changed"] = ",".join(sorted(late))
        warnings.append(f"parameters changed while the data were logged: {', '.join(sorted(late))}")
    if duplicates:
        warnings.append(f"{duplicates} repeated IMU messages (same time and values) read once")
    if firmware == "px4":
        for pname in sorted(params):
            if pname.startswith(("CAL_", "SENS_BOARD_")):
                meta[f"param.{pname}"] = fmt_param(params[pname])
    else:
        _params_meta(params, meta)
    return Imported(streams, meta, warnings)
