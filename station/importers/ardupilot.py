"""ArduPilot DataFlash logs (``.bin``) and MAVLink telemetry logs (``.tlog``) through pymavlink.

DataFlash (``DFReader_binary``), ArduPilot's ``LogStructure`` definitions:

- ``IMU`` (``TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ,…,T``, units ``s#EEEooo--O``): rad/s and
  m/s², the IMU's output after the calibration in use, rotated to the body frame. Old logs name
  the second and third IMU ``IMU2``/``IMU3`` (no ``I`` field).
- ``ACC`` / ``GYR`` (``TimeUS,I,SampleUS,AccX,AccY,AccZ`` / ``…,GyrX,GyrY,GyrZ``, units
  ``s#sooo`` / ``s#sEEE``): every sample of each sensor at its own rate (``LOG_BITMASK`` IMU_RAW,
  ``INS_RAW_LOG_OPT``), corrected and rotated as ``IMU`` is (``_rotate_and_correct_accel`` before
  ``log_accel_raw``), timed by ``SampleUS``. Read where the log has no ``IMU`` records, or with
  ``--source raw``. Logs before the ``I`` field name them ``ACC1``…``ACC3``, ``GYR1``…``GYR3``.
- ``ISBH`` / ``ISBD`` (the batch sampler, ``INS_LOG_BAT_MASK``): blocks of one sensor's samples, int16
  × ``ISBH.mul``, the accelerometer's and the gyro's in turn (never at the same time), each
  sample at ``SampleUS + k/smp_rate``; corrected and rotated as ACC/GYR. Read where the log has
  neither ``IMU`` nor ``ACC``/``GYR`` records, or with ``--source batch`` (``_df_batches``).
- ``MAG`` (``TimeUS,I,MagX,MagY,MagZ,OfsX,…``, units ``G`` × multiplier ``C`` = 10⁻³): milligauss,
  offsets, diagonals and motor compensation applied, body frame.
- ``PARM`` (``Name,Value``): the parameters; a name's first record is its value in use (the
  start-up dump runs on among the first samples), a later different one a change.
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
import re
import struct
from collections import Counter

import numpy as np

from station.errors import InputError
from station.importers._common import FRD, Imported, Stream, fmt_param, set_date, several_instances_warning
from station.importers.options import source_values

# INS4_/INS5_: IMUs 4 and 5 (AP_InertialSensor_Params, where INS_MAX_INSTANCES > 3)
PARAM_PREFIXES = ("INS_", "INS4_", "INS5_", "COMPASS_", "AHRS_ORIENTATION", "AHRS_TRIM_")
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
# GPS − UTC [s] from each leap second on (IERS Bulletin C), keyed by GPS seconds since the GPS
# epoch (UTC 1999-01-01, 2006-01-01, 2009-01-01, 2012-07-01, 2015-07-01, 2017-01-01)
_GPS_LEAPS = ((599184013.0, 13.0), (820108814.0, 14.0), (914803215.0, 15.0), (1025136016.0, 16.0),
              (1119744017.0, 17.0), (1167264018.0, 18.0))  # fmt: skip


def gps_minus_utc_s(gps_s: float) -> float:
    """GPS − UTC at ``gps_s`` seconds after the GPS epoch (leap seconds up to 2017-01-01)."""
    return next((leap for start, leap in reversed(_GPS_LEAPS) if gps_s >= start), _GPS_LEAPS[0][1])


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


class _SkippedBytes(io.TextIOBase):
    """pymavlink's DataFlash indexer as it reports a byte where no message starts ("bad header
    0x00 0x00 at 30005", one line per byte skipped: a corrupt or unwritten stretch, whose
    messages are lost): counted in stretches, the rest of its chatter dropped, nothing kept."""

    _LINE = re.compile(r"bad header 0x[0-9a-fA-F]{2} 0x[0-9a-fA-F]{2} at (\d+)")

    def __init__(self) -> None:
        self.bytes = 0
        self.stretches = 0
        self.first: int | None = None
        self.cut_at: int | None = None  # a tlog's last record, cut by the end of the file (_tlog_unreadable)
        self._last = -2
        self._tail = ""

    def write(self, s: str) -> int:
        *lines, self._tail = (self._tail + s).split("\n")
        for line in lines:
            m = self._LINE.match(line)
            if m:
                self.add(int(m.group(1)))
        return len(s)

    def add(self, at: int, n: int = 1) -> None:
        """``n`` bytes from byte ``at`` hold no readable message (a stretch goes on when ``at``
        follows the last byte counted)."""
        self.bytes += n
        self.stretches += at != self._last + 1
        self.first = at if self.first is None else self.first
        self._last = at + n - 1

    def follows(self, at: int) -> bool:
        """Whether byte ``at`` comes right after the last byte counted."""
        return at == self._last + 1

    def warning(self) -> str | None:
        if not self.bytes:
            return None
        where = "one stretch" if self.stretches == 1 else f"{self.stretches} stretches"
        return (
            f"{self.bytes} bytes of the log in {where} (the first at byte {self.first}) hold no readable message "
            "(corrupt or never written): the messages there are lost, a gap in the samples"
        )


def _open_error(path, exc: Exception, what: str) -> InputError:
    if isinstance(exc, FileNotFoundError):
        return InputError(path, None, "no such file")
    if isinstance(exc, IsADirectoryError):
        return InputError(path, None, f"is a directory, not {what}")
    if isinstance(exc, PermissionError):
        return InputError(path, None, "permission denied")
    return InputError(path, None, f"not a readable {what} ({type(exc).__name__}: {exc})")


_HEAD_BYTES = 1 << 20


def _no_header_in_head(path, markers: tuple[bytes, ...]) -> bool:
    """Whether the first MiB of ``path`` holds none of ``markers`` (a message header): then it
    is no log, and pymavlink would search the whole file byte by byte (2 GiB of zeros: minutes)."""
    from station.fileio import open_input

    with open_input(path, "a log file") as f:
        head = f.read(_HEAD_BYTES)
    return bool(head) and not any(m in head for m in markers)


def _params_meta(params: dict[str, float], meta: dict[str, str]) -> None:
    for name in sorted(params):
        if name.startswith(PARAM_PREFIXES):
            meta[f"param.{name}"] = fmt_param(params[name])


def _ap_device_id(params: dict, kind: str, instance: int) -> int | None:
    """The sensor's id from INS_ACC_ID / INS_ACC2_ID … INS4_ACC_ID, INS5_ACC_ID, INS_GYR_ID …,
    COMPASS_DEV_ID / _DEV_ID2 …"""
    n = "" if instance == 0 else str(instance + 1)
    if kind != "mag" and instance >= 3:  # IMUs 4 and 5: the INS4_/INS5_ groups
        value = params.get(f"INS{instance + 1}_{'ACC' if kind == 'accel' else 'GYR'}_ID")
        return int(value) if value else None
    name = {
        "accel": f"INS_ACC{n}_ID",
        "gyro": f"INS_GYR{n}_ID",
        "mag": f"COMPASS_DEV_ID{n}",
    }[kind]
    value = params.get(name)
    return int(value) if value else None


# COMPASS_LEARN (AP_Compass.cpp): 1 internal learning (older firmware), 2 the EKF's offsets saved
# at disarm, 3 in flight (Compass_learn.cpp: mag_cal_fixed_yaw once the GSF yaw converges, then
# COMPASS_LEARN set back to 0). A saved parameter is logged as a PARM record (GCS::send_parameter_value
# "also log to AP_Logger"); the offsets each MAG sample was corrected with are its OfsX..OfsZ.
COMPASS_LEARN = {1: "internal learning", 2: "EKF learning", 3: "in-flight learning"}


def _offsets_learnt(mag_ofs, have_mag: bool, inst: int, unit: str | None, params: dict, late: set[str]) -> str:
    """Where the offsets in MAG's OfsX..OfsZ change during the imported samples (in-flight
    learning changes them with or without a PARM record): their names join ``late``, and the
    change is said (values, time, COMPASS_LEARN); "" when they do not change."""
    if mag_ofs is None or not have_mag:
        return ""
    t_us, ofs = mag_ofs
    if len(ofs) < 2 or not np.any(ofs != ofs[0]):
        return ""
    n = "" if inst == 0 else str(inst + 1)
    late.update(f"COMPASS_OFS{n}_{a}" for a in "XYZ")
    at = int(np.flatnonzero(np.any(ofs != ofs[0], axis=1))[0])
    mgauss = 1000.0 if DF_UNITS.get(unit or "") == "gauss" else 1.0  # FMTU 'G' x 'C': the reader gave gauss

    def show(v) -> str:
        return ",".join(f"{x * mgauss:g}" for x in v)

    mode = params.get("COMPASS_LEARN")
    how = f", COMPASS_LEARN = {int(mode)}: {COMPASS_LEARN[int(mode)]}" if mode in COMPASS_LEARN else ""
    return (
        f"MAG[{inst}] offsets {show(ofs[0])} -> {show(ofs[-1])} mGauss from {(t_us[at] - t_us[0]) * 1e-6:.3g} s"
        f"{how}: the samples were corrected with offsets that changed"
    )


# ------------------------------------------------------------------------------------- DataFlash


def _df_instances(log, c: dict | None, seen: set[int], base: str) -> list[int]:
    """The instances of ``base`` (IMU, MAG) in a DataFlash log: ``seen``, its ``I`` field's
    values as the decoding counted them (``c``: its columns; instance 0 where it has no ``I``),
    and IMU2/IMU3 (MAG2/MAG3; ACC1-ACC3, GYR1-GYR3) of the logs before that field."""
    found: set[int] = set()
    if c is not None:
        found.update(seen) if "I" in c else found.add(0)
    for n in (1, 2, 3) if base in ("ACC", "GYR") else (2, 3):
        type_id = getattr(log, "name_to_id", {}).get(f"{base}{n}")
        if type_id is not None and log.offsets[type_id]:
            found.add(n - 1)
    return sorted(found)


# ArduPilot's full-rate sensor messages (AP_InertialSensor/LogStructure.h): kind -> (message, fields)
DF_RAW = {"accel": "ACC", "gyro": "GYR"}
SOURCES_BIN = source_values("ardupilot")  # --source of a DataFlash log: the registry (importers.options.SOURCES)
DF_LOOKED_FOR = "IMU, ACC/GYR, ISBH/ISBD or MAG"  # the messages read_bin reads samples from


def _df_what(log) -> str:
    """The message names a DataFlash log holds whole records of (FMT, UNIT, MULT, FMTU and PARM
    aside; a record cut by the end of the file is none)."""
    names = [
        n
        for n, i in sorted(getattr(log, "name_to_id", {}).items())
        if n not in ("FMT", "UNIT", "MULT", "FMTU", "PARM")
        and any(o + log.formats[i].len <= log.data_len for o in log.offsets[i][-2:])
    ]
    if not names:
        return "no sensor records"
    more = f" and {len(names) - 8} more" if len(names) > 8 else ""
    return ", ".join(names[:8]) + more + " records"


def _df_has(log, *names: str) -> bool:
    """Whether the log holds a record of any of message ``names`` (a format alone is none)."""
    ids = getattr(log, "name_to_id", {})
    return any(n in ids and len(log.offsets[ids[n]]) for n in names)


def _closed_refusal(log, path, message: str) -> InputError:
    """The log closed, and the one line that says why it was refused (raise what this returns)."""
    with contextlib.suppress(Exception):
        log.close()
    return InputError(path, None, message)


def _raw_notes(params: dict[str, float], inst_read: dict[str, int]) -> list[str]:
    """What ``INS_RAW_LOG_OPT`` says about the ACC/GYR samples read (AP_InertialSensor_Backend
    ``log_gyro_raw``/``log_accel_raw``): bit 2 (4) post filter, the samples after the IMU's
    low-pass and notch filters; bit 3 (8) pre and post filter, each sensor's filtered copy logged as
    instance + the number of sensors (the batch sampler's numbering)."""
    opt = int(params.get("INS_RAW_LOG_OPT", 0) or 0)
    if opt & 8:
        out = []
        for kind, inst in inst_read.items():
            ids = (
                ("INS_ACC_ID", "INS_ACC2_ID", "INS_ACC3_ID", "INS4_ACC_ID", "INS5_ACC_ID")
                if kind == "accel"
                else ("INS_GYR_ID", "INS_GYR2_ID", "INS_GYR3_ID", "INS4_GYR_ID", "INS5_GYR_ID")
            )
            count = sum(1 for n in ids if (params.get(n) or 0) > 0)
            if count and inst >= count:
                out.append(
                    f"INS_RAW_LOG_OPT {opt} (pre and post filter): {DF_RAW[kind]}[{inst}] is the filtered copy of "
                    f"{DF_RAW[kind]}[{inst - count}] ({count} sensors): a calibration needs the unfiltered one, "
                    f"--instance {inst - count}"
                )
        return out
    if opt & 4:
        return [
            f"INS_RAW_LOG_OPT {opt} (post filter): the ACC/GYR samples were logged after the IMU's low-pass and notch "
            "filters, not as the sensor gave them"
        ]
    return []


# The batch sampler (AP_InertialSensor BatchSampler, INS_LOG_BAT_MASK/_CNT/_OPT/_LGIN/_LGCT): a block of
# INS_LOG_BAT_CNT samples of one sensor at a time, accelerometer then gyro of each IMU in the mask in turn.
# LogStructure.h: ISBH "QHBBHHQf" TimeUS,N,type,instance,mul,smp_cnt,SampleUS,smp_rate (N the block's
# number, type IMU_SENSOR_TYPE, mul the int16 scale, SampleUS the first sample's time, smp_rate in Hz);
# ISBD "QHHaaa" TimeUS,N,seqno,x,y,z (x, y, z: int16[32], samples seqno*32 ... seqno*32+31 of block N).
# BatchSampler::sample stores multiplier*sample (m/s^2, rad/s: the sample after _rotate_and_correct_*, as
# ACC/GYR), so a sample is x/mul, taken at SampleUS + k/smp_rate (pymavlink's tools/isb_extract.py).
ISB_KIND = {0: "accel", 1: "gyro"}  # AP_InertialSensor::IMU_SENSOR_TYPE_ACCEL = 0, _GYRO = 1
ISB_UNIT = {"accel": "m/s/s", "gyro": "rad/s"}  # ISBD's FMTU says 'o' (m/s/s) for both: the type decides
ISB_NAME = {kind: f"ISBD {kind}" for kind in ISB_KIND.values()}  # the stream's source, as read


def _isb_values(column: np.ndarray) -> np.ndarray:
    """ISBD's ``a`` field (pymavlink: 64 bytes) as its int16[32] samples, one row per record."""
    raw = np.ascontiguousarray(column).tobytes()
    return np.frombuffer(raw, dtype="<i2").reshape(len(column), -1).astype(np.float64)


def _batch_notes(params: dict[str, float], inst_read: dict[str, int]) -> list[str]:
    """What ``INS_LOG_BAT_OPT`` says about the batches read (BatchSampler, Write_ISBH): bit 1 (2)
    post filter, the samples after the IMU's low-pass and notch filters; where every sample is
    logged twice (bit 2 (4), pre and post filter, in later firmware), the filtered block is
    numbered instance + the number of sensors."""
    opt = int(params.get("INS_LOG_BAT_OPT", 0) or 0)
    if opt & 4:
        count = sum(1 for n in ("INS_ACC_ID", "INS_ACC2_ID", "INS_ACC3_ID") if (params.get(n) or 0) > 0)
        return [
            f"INS_LOG_BAT_OPT {opt} (pre and post filter): ISBD {kind}[{inst}] is the filtered copy of "
            f"ISBD {kind}[{inst - count}] ({count} sensors): a calibration needs the unfiltered one, --instance {inst - count}"
            for kind, inst in inst_read.items()
            if count and inst >= count
        ]
    if opt & 2:
        return [
            f"INS_LOG_BAT_OPT {opt} (post filter): the ISBD samples were logged after the IMU's low-pass and notch "
            "filters, not as the sensor gave them"
        ]
    return []


def _df_batches(log, inst: int, named: bool) -> tuple[dict, dict, dict, int, list[str]]:
    """The batch sampler's samples of IMU ``inst`` (``named``: --instance given; else the first
    instance each sensor type has): ({kind: (n, 4) t_us, x, y, z}, {kind: instance read},
    {kind: instances in the log}, file offset of the first header read, notes)."""
    h = _df_columns(log, "ISBH")
    d = _df_columns(log, "ISBD")
    rows: dict[str, np.ndarray] = {}
    read: dict[str, int] = {}
    seen: dict[str, set[int]] = {k: set() for k in ISB_KIND.values()}
    notes: list[str] = []
    first_ofs = math.inf
    if h is None:
        return rows, read, seen, first_ofs, notes
    htype = h["type"].astype(int)
    hinst = h["instance"].astype(int)
    for t, kind in ISB_KIND.items():
        seen[kind] = {int(i) for i in np.unique(hinst[htype == t])}
    if d is None:
        n = len(htype)
        notes.append(
            f"{n} ISBH batch header{'s' if n != 1 else ''} but no ISBD records: the batch sampler's samples are "
            "not in the log"
        )
        return rows, read, seen, first_ofs, notes
    # each ISBD belongs to the last ISBH before it in the file, where their batch numbers N agree
    owner = np.searchsorted(h["_offset"], d["_offset"]) - 1
    ok = owner >= 0
    ok[ok] = h["N"][owner[ok]] == d["N"][ok]
    stray = int((~ok).sum())
    values = {a: _isb_values(d[a]) for a in ("x", "y", "z")}
    per = values["x"].shape[1]  # samples per ISBD (32)
    holes = 0
    bad = 0
    for t, kind in ISB_KIND.items():
        have = seen[kind]
        if not have:
            continue
        pick = inst if named or inst in have else min(have)
        read[kind] = pick
        parts = []
        for j in np.flatnonzero((htype == t) & (hinst == pick)):
            mul, rate, count = float(h["mul"][j]), float(h["smp_rate"][j]), int(h["smp_cnt"][j])
            mine = np.flatnonzero(ok & (owner == j))
            if not (mul > 0 and math.isfinite(rate) and rate > 0) or not len(mine):
                bad += 1
                continue
            seq, first = np.unique(d["seqno"][mine].astype(np.int64), return_index=True)
            mine = mine[first]
            k = (seq[:, None] * per + np.arange(per)).ravel()  # each sample's place in the block
            block = np.column_stack([values[a][mine].ravel() for a in ("x", "y", "z")]) / mul
            keep = k < count if count > 0 else np.ones(len(k), dtype=bool)
            # ISBD records missing: inside the block, or after its last one but for the file's last
            # block (a log that ends there: the cut is said on its own)
            last = j == len(htype) - 1
            holes += int(seq[-1] + 1 - len(seq)) + (
                0 if last or count <= 0 else max(0, count // per - int(seq[-1]) - 1)
            )
            t_us = float(h["SampleUS"][j]) + k[keep] * 1e6 / rate
            parts.append(np.column_stack([t_us, block[keep]]))
            first_ofs = min(first_ofs, int(h["_offset"][j]))
        if parts:
            rows[kind] = np.concatenate(parts)
    if holes > 0:
        notes.append(
            f"{holes} ISBD record{'s' if holes != 1 else ''} of the batches read {'are' if holes != 1 else 'is'} "
            f"missing (the logger dropped {'them' if holes != 1 else 'it'}): {holes * per} samples lost, a gap in the block"
        )
    if bad:
        notes.append(
            f"{bad} ISBH batch{'es' if bad != 1 else ''} with no ISBD records, or a zero multiplier or rate: left out"
        )
    if stray:
        notes.append(f"{stray} ISBD record{'s' if stray != 1 else ''} after no ISBH of their batch number: left out")
    return rows, read, seen, first_ofs, notes


def read_bin(path, *, instance: int | None = None, kinds=None, source: str = "auto") -> Imported:
    """IMU/MAG of one instance (default 0) and the parameters in use from a DataFlash log;
    ``source``: ``raw`` reads the accelerometer and gyro from ACC/GYR (every sample),
    ``combined`` from IMU, ``batch`` from ISBH/ISBD, ``auto`` from IMU where the log has it,
    else from ACC/GYR, else from ISBH/ISBD."""
    from pymavlink import DFReader

    if source not in SOURCES_BIN:
        raise InputError(None, None, f"--source {source!r}: expected one of {', '.join(SOURCES_BIN)}")
    inst = 0 if instance is None else int(instance)
    if _no_header_in_head(path, (b"\xa3\x95",)):  # DataFlash message header (DFReader_binary HEAD1, HEAD2)
        raise InputError(
            path,
            None,
            f"no {DF_LOOKED_FOR} messages in the DataFlash log (no DataFlash message header in its first 1 MiB)",
        )
    # pymavlink's compiled indexer prints "bad header" lines straight to file descriptor 2, past
    # any Python redirection: its pure-Python indexer (same result) prints through sys.stderr.
    fast = os.environ.get("PYMAVLINK_FAST_INDEX")
    os.environ["PYMAVLINK_FAST_INDEX"] = "0"
    skipped = _SkippedBytes()
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(skipped):
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
    # ACC/GYR (ACC1-3/GYR1-3 before the I field): where asked, or where the log has no IMU records
    raw_names = {k: m if m in names else f"{m}{inst + 1}" for k, m in DF_RAW.items()}
    has_imu = _df_has(log, "IMU", "IMU2", "IMU3")
    has_raw = _df_has(log, "ACC", "GYR", *(f"{m}{n}" for m in DF_RAW.values() for n in (1, 2, 3)))
    if source == "raw" and not has_raw:
        raise _closed_refusal(
            log,
            path,
            "--source raw: the log has no ACC or GYR records (ArduPilot logs them with LOG_BITMASK's IMU_RAW "
            "or INS_RAW_LOG_OPT); its IMU records are read without --source",
        )
    has_isb = _df_has(log, "ISBH")
    if source == "batch" and not has_isb:
        raise _closed_refusal(
            log,
            path,
            "--source batch: the log has no ISBH/ISBD batches (ArduPilot logs them for the IMUs in "
            f"INS_LOG_BAT_MASK); it has {_df_what(log)}",
        )
    # ISBH/ISBD: where asked, or where the log has neither IMU nor ACC/GYR records
    use_batch = source == "batch" or (source == "auto" and not has_imu and not has_raw and has_isb)
    use_raw = not use_batch and (source == "raw" or (source == "auto" and not has_imu and has_raw))
    # the message each kind is read from
    src_of = (
        dict(ISB_NAME)
        if use_batch
        else {"accel": raw_names["accel"], "gyro": raw_names["gyro"]}
        if use_raw
        else {"accel": imu_name, "gyro": imu_name}
    )
    src_of["mag"] = mag_name
    rows: dict[str, np.ndarray] = {}
    batch_notes: list[str] = []
    temps = None
    params: dict[str, float] = {}
    late: set[str] = set()
    gps_utc_offset = None
    fixes: list[tuple[float, float, float]] = []
    units = {}
    instances_seen: dict[str, set] = {n: set() for n in (imu_name, mag_name, *src_of.values())}
    inst_of: dict[str, int] = dict.fromkeys(instances_seen, inst)  # the instance read of each
    mag_ofs = None
    try:
        # The bulk (IMU, MAG: hundreds of thousands of fixed-size records) is decoded at once
        # from pymavlink's own index (offsets per message type) and format table; a DFMessage
        # per record cost ~100 µs each. Parameters and GPS, a few hundred, the same way.
        cols = {name: _df_columns(log, name) for name in (imu_name, mag_name, *src_of.values(), "PARM", "GPS")}
        first_ofs = math.inf  # file offset of the first sample used: parameters before it are in use
        reads = (
            ((mag_name, ("mag",)),)
            if use_batch
            else ((src_of["gyro"], ("gyro",)), (src_of["accel"], ("accel",)), (mag_name, ("mag",)))
            if use_raw
            else ((imu_name, ("gyro", "accel")), (mag_name, ("mag",)))
        )
        if use_batch:
            batch_rows, batch_read, batch_seen, first_ofs, batch_notes = _df_batches(log, inst, instance is not None)
            for kind, arr in batch_rows.items():
                rows[kind] = arr
                units[kind] = ISB_UNIT[kind]
            for kind, name in ISB_NAME.items():
                instances_seen[name] = batch_seen[kind]
                inst_of[name] = batch_read.get(kind, inst)
        for name, kind_cols in reads:
            c = cols[name]
            if c is None:
                continue
            keep = np.ones(len(c["_offset"]), dtype=bool)
            if "I" not in c and name in ("IMU", "MAG", *DF_RAW.values()) and inst != 0:
                # a log before the I field: IMU (MAG) is instance 0 alone, the others are IMU2, IMU3
                # (MAG2, MAG3), here not in its formats; instance 0 read as the one asked went to its slot
                instances_seen[name].add(0)
                continue
            if "I" in c:
                instances_seen[name].update(int(i) for i in np.unique(c["I"]))
                if name in ("IMU", "MAG", *DF_RAW.values()):
                    # without --instance, a log whose sensors start above 0 is read from its first
                    # (as PX4's raw topics are), not refused as if --instance 0 had been asked
                    first = inst if instance is not None or inst in instances_seen[name] else min(instances_seen[name])
                    inst_of[name] = first
                    keep = c["I"] == first
            if not keep.any():
                continue
            first_ofs = min(first_ofs, int(c["_offset"][keep][0]))
            fmt = log.formats[log.name_to_id[name]]
            # TimeUS: µs since boot; logs before ArduPilot 3.3 (2015) have TimeMS, ms since boot
            t_us = c["TimeUS"][keep].astype(np.float64) if "TimeUS" in c else c["TimeMS"][keep] * 1000.0
            if "SampleUS" in c:  # ACC/GYR: the time the sensor took the sample (TimeUS where the driver gives none)
                sample_us = c["SampleUS"][keep].astype(np.float64)
                t_us = np.where(sample_us > 0, sample_us, t_us)
            fields = {
                "gyro": ("GyrX", "GyrY", "GyrZ"),
                "accel": ("AccX", "AccY", "AccZ"),
                "mag": ("MagX", "MagY", "MagZ"),
            }
            for kind in kind_cols:
                rows[kind] = np.column_stack([t_us] + [c[f][keep].astype(np.float64) for f in fields[kind]])
                units[kind] = fmt.get_unit(fields[kind][0]) if fmt.units else ""
            if name == imu_name and not use_raw:
                temps = c["T"][keep].astype(np.float64) if "T" in c else np.full(len(t_us), math.nan)
            if name == mag_name and all(f in c for f in ("OfsX", "OfsY", "OfsZ")):
                # the offsets each MAG sample was corrected with (compass.get_offsets: COMPASS_OFS in use)
                mag_ofs = (t_us, np.column_stack([c[f][keep].astype(np.float64) for f in ("OfsX", "OfsY", "OfsZ")]))
        if cols["PARM"] is not None:
            c = cols["PARM"]
            for ofs, raw, value in zip(c["_offset"].tolist(), c["Name"].tolist(), c["Value"].tolist()):
                pname = _df_text(raw)
                # ArduPilot writes its start-up dump of every parameter while the sensor data
                # already flow: a name's first PARM is its value in use, a later different one a change
                if ofs < first_ofs or pname not in params:
                    params[pname] = value
                elif pname.startswith(PARAM_PREFIXES) and params[pname] != value:
                    late.add(pname)
        if cols["GPS"] is not None:
            c = cols["GPS"]
            if "TimeUS" not in c and "T" in c and "Week" in c:  # before 3.3: TimeMS = GPS ms of week, T = boot ms
                c = dict(c, TimeUS=c["T"] * 1000.0, GWk=c["Week"], GMS=c["TimeMS"])
            keys = [k for k in ("TimeUS", "Status", "GWk", "GMS", "Lat", "Lng", "Alt") if k in c]
            for values in zip(*(c[k].tolist() for k in keys)):
                d = dict(zip(keys, values))
                _df_gps(d, fixes)
                if gps_utc_offset is None and d.get("GWk") and d.get("Status", 0) >= 3 and "TimeUS" in d:
                    gps_s = d["GWk"] * 604800.0 + d["GMS"] * 1e-3
                    gps_utc_offset = GPS_EPOCH_UNIX_S + gps_s - gps_minus_utc_s(gps_s) - d["TimeUS"] * 1e-6
        available = {}  # the instances the log holds, for the refusal of one it lacks
        held = _df_what(log) if not rows else ""
        if not rows and not use_batch:
            for base in ("IMU", "MAG", *(DF_RAW.values() if use_raw else ())):
                c = cols[base] if base in cols else _df_columns(log, base)
                have = _df_instances(
                    log, c, {int(i) for i in np.unique(c["I"])} if c is not None and "I" in c else set(), base
                )
                if have:
                    available[base] = have
        first_us = float(min(r[0, 0] for r in rows.values())) if rows else None
        cut = _df_cut(log)
        several = None
        if instance is None:  # the first instance read by default: say so where the log has others
            imu_read = src_of["gyro"]
            read_inst = {inst_of[n] for n, k in ((imu_read, "gyro"), (mag_name, "mag")) if k in rows}
            base = DF_RAW["gyro"] if use_raw else "IMU"
            imus = (
                sorted(instances_seen[ISB_NAME["accel"]] | instances_seen[ISB_NAME["gyro"]])
                if use_batch
                else _df_instances(log, cols.get(base), instances_seen.get(base, set()), base)
            )
            several = several_instances_warning(
                {  # without --instance, the names read are IMU (GYR) and MAG
                    "IMUs": imus,
                    "compasses": _df_instances(log, cols["MAG"], instances_seen["MAG"], "MAG"),
                },
                next(iter(read_inst))
                if len(read_inst) == 1
                else f"{inst_of[imu_read]} (IMU), {inst_of[mag_name]} (compass)",
            )
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001
        raise InputError(path, None, f"cannot read the DataFlash log ({type(exc).__name__}: {exc})") from None
    finally:
        with contextlib.suppress(Exception):
            log.close()
    if not rows:
        also = f"; warning: {cut}" if cut else ""  # what the cut left may be why there is nothing
        if use_batch and batch_notes:  # batch headers without their samples: that is what is wrong
            raise InputError(path, None, f"{batch_notes[0]} (it looked for {DF_LOOKED_FOR})" + also)
        seen = available or {k: sorted(v) for k, v in instances_seen.items() if v}
        if seen:
            raise InputError(
                path,
                None,
                f"--instance {inst}: the log has "
                + "; ".join(f"{k} instances {', '.join(map(str, v))}" for k, v in seen.items())
                + also,
            )
        raise InputError(path, None, f"no {DF_LOOKED_FOR} messages in the DataFlash log (it has {held})" + also)
    streams = {}
    for kind, arr in rows.items():
        if not len(arr) or (kinds is not None and kind not in kinds):
            continue
        unit = DF_UNITS.get(units.get(kind) or "", None)
        if units.get(kind) and unit is None:
            raise InputError(
                path,
                None,
                f"{kind} unit {units[kind]!r} in the log's FMTU is not one the station knows",
            )
        name = src_of[kind]
        stream = Stream(
            kind,
            arr[:, 0] * 1e-6,
            arr[:, 1:4],
            unit or DF_DEFAULT[kind],
            f"{name}[{inst_of[name]}]",
            _ap_device_id(params, kind, inst_of[name]),
            inst_of[name],
            temps if kind == "accel" and not use_raw else None,
        )
        streams[kind] = stream
    # IMU and MAG are rotated to the vehicle's body frame (AHRS_ORIENTATION) before they are logged
    meta: dict[str, str] = {"firmware": "ardupilot", "corrected": "true", "frame": FRD}
    warnings = [w for w in (skipped.warning(), cut, several) if w] + batch_notes
    if use_raw:
        warnings += _raw_notes(params, {k: inst_of[src_of[k]] for k in DF_RAW if k in streams})
    elif use_batch:
        warnings += _batch_notes(params, {k: inst_of[src_of[k]] for k in ISB_NAME if k in streams})
    elif has_raw and source == "auto" and ("accel" in streams or "gyro" in streams):
        warnings.append("the log also has ACC/GYR, every sample at the sensor's rate: --source raw reads them")
    if has_isb and not use_batch and source == "auto" and ("accel" in streams or "gyro" in streams):
        warnings.append("the log also has ISBH/ISBD batches of raw IMU samples: --source batch reads them")
    if instance is not None:  # the instance asked, where one of IMU/MAG lacks it (as PX4's raw topics say it)
        said = (
            ((src_of["gyro"], "gyro"), (src_of["accel"], "accel"))
            if use_raw or use_batch
            else ((imu_name, "accel and gyro"),)
        )
        for name, kind in (*said, (mag_name, "mag")):
            have = sorted(instances_seen[name])
            if have and inst not in have:
                warnings.append(
                    f"--instance {inst}: no {name}[{inst}] (its instances: {', '.join(map(str, have))}), so no {kind} columns"
                )
    learnt = _offsets_learnt(mag_ofs, "mag" in streams, inst_of[mag_name], units.get("mag"), params, late)
    if late:
        meta["params_changed"] = ",".join(sorted(late))
        warnings.append(
            f"parameters changed while the data were logged: {', '.join(sorted(late))} "
            "(param.* holds the values at the start" + (f"; {learnt}" if learnt else "") + ")"
        )
    if gps_utc_offset is not None and first_us is not None:
        set_date(meta, warnings, gps_utc_offset + first_us * 1e-6, "GPS")
    _place(fixes, meta)
    _params_meta(params, meta)
    return Imported(streams, meta, warnings)


_DF_NUMPY = {  # DFReader.FORMAT_TO_STRUCT's struct codes as numpy types (little-endian, packed)
    "b": "i1", "B": "u1", "h": "<i2", "H": "<u2", "i": "<i4", "I": "<u4", "q": "<i8", "Q": "<u8",
    "f": "<f4", "d": "<f8", "e": "<f2",
}  # fmt: skip


def _df_columns(log, name: str) -> dict[str, np.ndarray] | None:
    """Every record of message ``name`` decoded at once: {column: values} as DFMessage gives
    them (its format's multipliers applied: 'c' /100, 'L' /1e7 …), plus ``_offset`` (file
    order). Built from pymavlink's own index (``offsets``) and format (``msg_struct``)."""
    import re

    type_id = getattr(log, "name_to_id", {}).get(name)
    if type_id is None or not log.offsets[type_id]:
        return None
    fmt = log.formats[type_id]
    codes = re.findall(r"(\d*)([a-zA-Z?])", fmt.msg_struct.lstrip("<"))
    fields = []
    for (count, code), column in zip(codes, fmt.columns):
        fields.append((column, f"S{count}" if code == "s" else _DF_NUMPY[code]))
    dtype = np.dtype(fields)
    body = fmt.len - 3  # after the 2 header bytes and the type byte
    if dtype.itemsize != body:
        raise ValueError(f"{name}: format {fmt.format!r} is {dtype.itemsize} bytes, the log says {body}")
    offsets = np.asarray(log.offsets[type_id], dtype=np.int64)
    offsets = offsets[offsets + fmt.len <= log.data_len]  # a record cut by the end of the file
    if not len(offsets):  # its one record was the one cut
        return None
    data = np.frombuffer(log.data_map, dtype=np.uint8)
    recs = data[(offsets + 3)[:, None] + np.arange(body)].view(dtype).reshape(len(offsets))
    out: dict[str, np.ndarray] = {"_offset": offsets}
    for i, column in enumerate(fmt.columns):
        v = recs[column]
        mult = fmt.msg_mults[i]
        if mult is not None:  # as DFMessage: divide by 1/mult where that is exact (1e2, 1e7)
            v = v / (1 / mult) if 0.0 < mult < 1.0 else v * mult
        out[column] = v
    return out


def _df_cut(log) -> str:
    """The warning for a DataFlash log that ends inside a record (a power loss while logging, a
    copy stopped part-way), "" when it ends where a record ends. pymavlink indexes a record whose
    3 header bytes are there and leaves it out where its body is not (``_df_columns`` too),
    without a word; 1 to 3 bytes of a record's header at the very end it does not index at all."""
    end = log.data_len
    last_end, cut = 0, None
    for type_id, offsets in enumerate(log.offsets):
        fmt = log.formats.get(type_id) if offsets else None
        if fmt is None:
            continue
        ofs = int(offsets[-1])
        if ofs + fmt.len > end:
            cut = (ofs, fmt.name, fmt.len)
            ofs = int(offsets[-2]) if len(offsets) > 1 else -fmt.len
        last_end = max(last_end, ofs + fmt.len)
    tail = end - last_end
    if cut is None and 0 < tail <= 3 and log.data_map[last_end] == 0xA3:  # DataFlash HEAD1
        fmt = log.formats.get(log.data_map[last_end + 2]) if tail == 3 else None
        if fmt is None:
            return (
                f"the log is cut short inside a record's header at byte {last_end} ({tail} of its 3 bytes there): "
                "the records before it are imported"
            )
        cut = (last_end, fmt.name, fmt.len)
    if cut is None:
        return ""
    ofs, name, length = cut
    return (
        f"the log is cut short inside a record ({name}) at byte {ofs} ({end - ofs} of its {length} bytes there): "
        "the records before it are imported"
    )


def _df_text(raw) -> str:
    """A DataFlash char[] field as DFMessage gives it: up to the first NUL, UTF-8 else Latin-1."""
    raw = bytes(raw).split(b"\0", 1)[0]
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.decode("ISO-8859-1")


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


def _tlog_unreadable(data, mavlink) -> _SkippedBytes:
    """The bytes of a tlog (``data``: its bytes or mmap) that hold no readable message.

    pymavlink gives no sign of them: ``mavmmaplog`` indexes the records (an 8-byte time, then
    a frame that starts 0xFE, MAVLink 1, or 0xFD, MAVLink 2, with its payload length) without
    checking them, steps over any byte where no frame starts one at a time, and drops a frame
    whose checksum fails when it reads it. The records are walked here by the same rule, and
    counted: the bytes stepped over, and the records whose frame fails its checksum (CRC-16/
    MCRF4XX with the message's CRC_EXTRA, as pymavlink checks it). A record cut by the end of the
    file right after a sound one (a power loss, a copy stopped part-way; 1 to 14 bytes of one
    too) is not counted but kept as ``cut_at``, its first byte; inside a stretch counted, it is
    part of the stretch. A frame of a message the dialect does not know cannot be
    checked; it is counted only where a stretch counted touches it (a false start in garbage),
    else taken as sound.
    """
    from pymavlink.generator.mavcrc import x25crc

    known = mavlink.mavlink_map
    signed = mavlink.MAVLINK_IFLAG_SIGNED
    n = len(data)
    bad = _SkippedBytes()
    unknown = None  # (offset, length) of the last record of an unknown message, taken as sound

    def lost(at: int, length: int) -> None:
        nonlocal unknown
        if unknown is not None and sum(unknown) == at:  # it began the stretch: a false start too
            bad.add(*unknown)
        unknown = None
        bad.add(at, length)

    ofs = 0
    while ofs + 8 + 6 < n:  # as mavmmaplog.init_arrays walks the file
        marker = data[ofs + 8]
        if marker == 0xFE:
            header, mtype = 6, data[ofs + 13]
        elif marker == 0xFD and ofs + 8 + 10 <= n:
            header, mtype = 10, data[ofs + 15] | data[ofs + 16] << 8 | data[ofs + 17] << 16
        elif marker == 0xFD:
            break
        else:
            lost(ofs, 1)
            ofs += 1
            continue
        length = data[ofs + 9]
        frame_end = ofs + 8 + header + length + 2
        mlen = frame_end - ofs + (13 if marker == 0xFD and data[ofs + 10] & signed else 0)
        if ofs + mlen > n:  # the file ends inside this record
            if bad.follows(ofs):  # a false start in a stretch of garbage that runs to the end
                lost(ofs, n - ofs)
                ofs = n
            break
        cls = known.get(mtype)
        if cls is None:
            sound = not bad.follows(ofs)
        elif frame_end > n:
            sound = False
        else:
            crc = x25crc(bytes(data[ofs + 9 : frame_end - 2]))
            crc.accumulate(bytes((cls.crc_extra,)))
            sound = crc.crc == data[frame_end - 2] | data[frame_end - 1] << 8
        if not sound:
            lost(ofs, min(mlen, n - ofs))
        elif cls is None:
            unknown = (ofs, mlen)
        else:
            unknown = None
        ofs += mlen
    if ofs < n and not bad.follows(ofs):  # after a sound record (or at the start): a cut
        bad.cut_at = ofs
    return bad


def _mmaplog_upto(path, end: int):
    """pymavlink's ``mavmmaplog`` of ``path`` indexing only its first ``end`` bytes: it reads the
    first record of each message type whole while it indexes, and fails (AttributeError on the
    None it gets) where the file ends inside the first record of its type."""
    from pymavlink import mavutil

    class Upto(mavutil.mavmmaplog):
        def init_arrays(self, progress_callback=None):
            self.data_len = min(self.data_len, end)
            super().init_arrays(progress_callback)

    return Upto(str(path))


def _tlog_cut_at(path) -> int | None:
    """Where a tlog ends inside a record (``_tlog_unreadable``), None when it ends whole or
    cannot be read."""
    import mmap

    from pymavlink import mavutil

    try:
        with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
            return _tlog_unreadable(data, mavutil.mavlink).cut_at
    except (OSError, ValueError):
        return None


def _param_value(msg, firmware: str | None) -> float | int:
    value = msg.param_value
    if msg.param_type in INT_PARAM_TYPES:
        if firmware == "px4":  # byte-wise: the integer's bytes sent inside the float
            return struct.unpack("<i", struct.pack("<f", value))[0]
        return round(value)
    return value


@contextlib.contextmanager
def _same_mavlink_version():
    """pymavlink's reader, meeting a MAVLink 2 frame, sets ``os.environ['MAVLINK20']`` and reloads
    its dialect (``mavfile.auto_mavlink_version``): every MAVLink object the process makes after
    that speaks MAVLink 2. A log read is no reason to change the process: both are put back."""
    from pymavlink import mavutil

    env, module = os.environ.get("MAVLINK20"), mavutil.mavlink
    try:
        yield
    finally:
        if os.environ.get("MAVLINK20") != env:
            if env is None:
                os.environ.pop("MAVLINK20", None)
            else:
                os.environ["MAVLINK20"] = env
        mavutil.mavlink = module


def read_tlog(path, *, instance: int | None = None, kinds=None) -> Imported:
    """RAW_IMU / SCALED_IMU{,2,3} / HIGHRES_IMU and PARAM_VALUE from a MAVLink log (and
    SENSOR_OFFSETS: compass offsets that change while the data run are ``params_changed``)."""
    with _same_mavlink_version():
        return _read_tlog(path, instance=instance, kinds=kinds)


LINK_GAP_FACTOR = 1.5  # a step this many times the median interval: a sample or more lost, not jitter


def _link_gaps(t: np.ndarray, name: str) -> str | None:
    """The warning for samples a telemetry link lost: steps in the IMU messages' own time of more
    than ``LINK_GAP_FACTOR`` times their median interval (a radio link drops packets; the log
    keeps only what arrived, and nothing else in the capture says where the holes are)."""
    if len(t) < 3:
        return None
    dt = np.diff(t)
    med = float(np.median(dt))
    if not med > 0:
        return None
    big = dt > LINK_GAP_FACTOR * med
    if not big.any():
        return None
    lost = int(np.sum(np.round(dt[big] / med)) - big.sum())
    return (
        f"the telemetry link lost {name} messages: {int(big.sum())} gaps longer than "
        f"{LINK_GAP_FACTOR:g} times the median interval ({med * 1e3:.0f} ms), about {lost} samples "
        f"in all, the longest {float(dt[big].max()):.2f} s at t = {float(t[1:][big][np.argmax(dt[big])] - t[0]):.1f} s"
    )


def _read_tlog(path, *, instance: int | None = None, kinds=None) -> Imported:
    from pymavlink import mavutil

    from station.device.mavlink import compass_offsets_changed  # as the live MAVLink link reads them

    inst = 0 if instance is None else int(instance)
    if inst not in IMU_MESSAGES:
        raise InputError(
            None,
            None,
            f"--instance {inst}: a MAVLink log carries IMU instances 0, 1, 2",
        )
    if _no_header_in_head(path, (b"\xfe", b"\xfd")):  # MAVLink 1 and 2 start-of-frame bytes
        raise InputError(
            path,
            None,
            f"no {' / '.join(IMU_MESSAGES[inst])} messages in the MAVLink log (no MAVLink frame in its first 1 MiB)",
        )
    try:
        with _quiet():
            # mavmmaplog directly: mavlink_connection() would try to *execute* a path holding '/bin/'
            log = mavutil.mavmmaplog(str(path))
    except Exception as exc:  # noqa: BLE001
        cut = _tlog_cut_at(path) if not isinstance(exc, OSError) else None
        if cut is None:
            raise _open_error(path, exc, "MAVLink log") from None
        try:  # the records before the cut, as a log that ends whole
            with _quiet():
                log = _mmaplog_upto(path, cut)
        except Exception as exc2:  # noqa: BLE001
            raise _open_error(path, exc2, "MAVLink log") from None
    try:
        unreadable = _tlog_unreadable(log.data_map if log.data_map is not None else b"", mavutil.mavlink)
    except Exception:  # noqa: BLE001 - the check must not stop a log pymavlink reads
        unreadable = _SkippedBytes()
    # the IMU instances the log holds (mavmmaplog's index: message counts by id)
    counts, ids = getattr(log, "counts", {}), getattr(log, "name_to_id", {})
    imus = [i for i, names in IMU_MESSAGES.items() if any(counts.get(ids.get(n), 0) for n in names)]
    if instance is None and imus and inst not in imus:  # no --instance: the first the log has
        inst = imus[0]
    wanted = list(IMU_MESSAGES[inst])
    by_type: dict[str, list] = {name: [] for name in wanted}
    arrivals: dict[tuple[str, int, int], float] = {}  # (message, system, component) → first arrival
    params: dict[str, object] = {}
    param_msgs = []
    offset_msgs = []
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
                m = log.recv_match(
                    type=wanted + ["PARAM_VALUE", "HEARTBEAT", "GPS_RAW_INT", "AUTOPILOT_VERSION", "SENSOR_OFFSETS"]
                )
                if m is None:
                    break
                name = m.get_type()
                if name == "HEARTBEAT":
                    if firmware is None and m.autopilot in MAV_AUTOPILOT and m.get_srcComponent() == 1:
                        firmware = MAV_AUTOPILOT[m.autopilot]
                elif name == "PARAM_VALUE":
                    param_msgs.append((first_t is not None, m))
                elif name == "SENSOR_OFFSETS":  # ArduPilot's primary compass offsets in use (mGauss)
                    offset_msgs.append((first_t is not None, m))
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
                    arrivals.setdefault((name, m.get_srcSystem(), m.get_srcComponent()), m._timestamp)
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
            f"no {' / '.join(wanted)} messages in the MAVLink log (instance {inst})"
            + (f"; it has IMU instances {', '.join(map(str, imus))}" if imus else "")
            + (
                f"; warning: it is cut short inside a message at byte {unreadable.cut_at}"
                if unreadable.cut_at is not None
                else ""
            ),
        )
    # a link with several vehicles (or autopilots) on it: one source's IMU, not theirs interleaved
    sources = Counter((m.get_srcSystem(), m.get_srcComponent()) for _, m in by_type[name])
    source = max(sources, key=lambda k: (sources[k], -list(sources).index(k)))
    skipped = []
    if len(sources) > 1:
        by_type[name] = [(t, m) for t, m in by_type[name] if (m.get_srcSystem(), m.get_srcComponent()) == source]
        param_msgs = [(a, m) for a, m in param_msgs if m.get_srcSystem() == source[0]] or param_msgs
        offset_msgs = [(a, m) for a, m in offset_msgs if m.get_srcSystem() == source[0]]
        others = ", ".join(
            f"system {s_}, component {c_} ({sources[(s_, c_)]})" for s_, c_ in sources if (s_, c_) != source
        )
        skipped.append(
            f"{name} from {len(sources)} MAVLink sources: read system {source[0]}, component {source[1]} "
            f"({sources[source]} messages, its parameters); {others} left out"
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
    # offsets learnt in flight (COMPASS_LEARN) reach a telemetry log as SENSOR_OFFSETS, not always
    # as a PARAM_VALUE: a change after the data began is a changed COMPASS_OFS_* all the same
    first_ofs = None
    for after_start, m in offset_msgs:
        ofs = (m.mag_ofs_x, m.mag_ofs_y, m.mag_ofs_z)
        if first_ofs is None:
            first_ofs = ofs
        elif after_start:
            late.update(compass_offsets_changed(first_ofs, ofs))
    samples = by_type[name]
    t = np.array([s[0] for s in samples])
    link_gaps = _link_gaps(t, name)
    units = getattr(msg_class[name], "fieldunits_by_name", {})
    streams = {}
    for kind, fields in MAV_FIELDS.items():
        if kinds is not None and kind not in kinds:
            continue
        values = np.array([[getattr(m, f) for f in fields] for _, m in samples], dtype=np.float64)
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
    if meta["corrected"] == "true":  # scaled and rotated to the body frame: MAVLink's FRD
        meta["frame"] = FRD
    if board_uid:
        meta["board_uid"] = str(board_uid)
    cut = (
        f"the log is cut short inside a message at byte {unreadable.cut_at}: the messages before it are imported"
        if unreadable.cut_at is not None
        else None
    )
    several = several_instances_warning({"IMUs": imus}, inst) if instance is None else None
    warnings = [w for w in (unreadable.warning(), cut, several, link_gaps) if w]
    warnings += skipped
    arrival = arrivals[(name, *source)]
    if arrival > 946684800:  # the ground station's clock (UTC) when the first sample came
        set_date(meta, warnings, arrival, "ground station's")
    _place(fixes, meta)
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
