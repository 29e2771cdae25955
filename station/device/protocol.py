"""The station line protocol: NMEA-style ASCII sentences (docs/protocol.md).

    $STH,<ver>,<device_id>,<accel_unit>,<gyro_unit>,<mag_unit>,<rate_hz>[,<channel>...]*CS   header
    $STD,<seq>,<t_device_us>,ax,ay,az,gx,gy,gz,mx,my,mz,temp_c[,<value>...]*CS             data
    $STC,<verb>[,<arg>...]*CS                                              host -> device
    $STA,<verb>,OK|ERR[,<text>]*CS                                         device -> host

`CS` is the XOR of the bytes between `$` and `*`, two hex digits; lines end in CRLF
(a bare LF is accepted). `seq` counts modulo 65536, `t_device_us` modulo 2**32.

Version 2 (backward compatible: version-1 parsers ignore trailing fields) lets a header
name extra channels after `rate_hz`, capture column names in the capture format's units
(`ref_gx` rad/s, `vl1` m/s, `vx` m/s, ...: `CHANNELS`); each data sentence then carries
their values after `temp_c`, in that order. A version-1 header has none.

`StationParser` is incremental: feed it byte chunks of any size; it survives garbage,
partial lines, checksum errors, binary noise and wrapping counters, counts every
problem by kind in `stats` and never raises on bad input.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import reduce
from operator import xor

import numpy as np

from station.capture import COLUMN_UNITS

PRE_HEADER_HOLD_US = 2_000_000  # device time held before a first header (then released without extras)
PROTOCOL_VERSION = 2  # 2: extra channels (a v1 header, without them, is still sent as 1)
SEQ_MODULO = 1 << 16
TIME_MODULO = 1 << 32
MAX_LINE = 256  # bytes from `$` to LF; longer partial lines are discarded
SENSOR_FIELDS = ("ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp_c")
# Extra channels a version-2 header may name: the capture format's columns beyond the
# sensors, each in the unit the capture format gives it (../shared/spec/capture-format.md).
CHANNELS = {c: u for c, u in COLUMN_UNITS.items() if c not in ("t", "temp_c", "n", "position")}
ERROR_KINDS = ("checksum", "malformed", "too_long", "noise")
_HEX = frozenset(b"0123456789abcdefABCDEF")
_NAN = math.nan


# ---------------------------------------------------------------- sentences, events


@dataclass(frozen=True)
class Header:
    """What a device says about itself. An empty unit means the sensor is absent."""

    device_id: str
    accel_unit: str = ""
    gyro_unit: str = ""
    mag_unit: str = ""
    rate_hz: float = math.nan
    version: int = 1
    at_sample: int = 0  # parser's sample count when it arrived
    channels: tuple[str, ...] = ()  # version 2: extra channels after temp_c (CHANNELS)

    @property
    def units(self) -> dict[str, str]:
        return {"accel_unit": self.accel_unit, "gyro_unit": self.gyro_unit, "mag_unit": self.mag_unit}

    def same_device(self, other: Header | None) -> bool:
        return other is not None and (
            self.device_id,
            self.accel_unit,
            self.gyro_unit,
            self.mag_unit,
            self.channels,
        ) == (other.device_id, other.accel_unit, other.gyro_unit, other.mag_unit, other.channels)


@dataclass(frozen=True)
class Command:
    """Host -> device: `$STC,<verb>,<args...>`; verb upper-cased."""

    verb: str
    args: tuple[str, ...] = ()
    at_sample: int = 0


@dataclass(frozen=True)
class Ack:
    """Device -> host answer to a command: `$STA,<verb>,OK|ERR,<text>`."""

    verb: str
    ok: bool
    text: str = ""
    at_sample: int = 0


@dataclass(frozen=True)
class Restart:
    """The device restarted (seq 0 right after a header, or seq went backwards)."""

    at_sample: int = 0


@dataclass(frozen=True)
class Unknown:
    """A valid sentence of a type this parser does not know (ignored, not an error)."""

    fields: tuple[str, ...]
    at_sample: int = 0


@dataclass
class SampleBlock:
    """Samples parsed since the last `take()`.

    `seq` as sent (wrapped), `t_dev_us` the device clock unwrapped (float64, exact to
    2**53 us), `values` shape (n, 10) in SENSOR_FIELDS order, NaN where a field was empty;
    `extra`: the header's extra channels by name, each (n,) (empty without any).
    """

    seq: np.ndarray
    t_dev_us: np.ndarray
    values: np.ndarray
    extra: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.seq)

    @classmethod
    def from_rows(cls, rows: list, channels: tuple[str, ...] = ()) -> SampleBlock | None:
        """Rows ``[seq, t_dev_us, *values, *channel values]`` as a block (None when there
        are none); an 'inf' from a device is no usable value: NaN."""
        if not rows:
            return None
        arr = np.array(rows, dtype=np.float64)
        vals = arr[:, 2:]
        vals[np.isinf(vals)] = np.nan
        n = len(SENSOR_FIELDS)
        extra = {name: vals[:, n + i].copy() for i, name in enumerate(channels)}
        return cls(seq=arr[:, 0].astype(np.int64), t_dev_us=arr[:, 1], values=vals[:, :n].copy(), extra=extra)

    @staticmethod
    def concat(blocks: list[SampleBlock]) -> SampleBlock | None:
        """Blocks in order as one; a channel some blocks lack is NaN there."""
        if not blocks:
            return None
        if len(blocks) == 1:
            return blocks[0]
        names = list(dict.fromkeys(k for b in blocks for k in b.extra))
        return SampleBlock(
            np.concatenate([b.seq for b in blocks]),
            np.concatenate([b.t_dev_us for b in blocks]),
            np.concatenate([b.values for b in blocks]),
            {k: np.concatenate([b.extra.get(k, np.full(len(b), np.nan)) for b in blocks]) for k in names},
        )


@dataclass
class ParseStats:
    """Counters; never reset by the parser. `gaps` = samples missed (from seq)."""

    bytes: int = 0
    sentences: int = 0
    samples: int = 0
    gaps: int = 0
    gap_events: int = 0
    duplicates: int = 0
    restarts: int = 0
    unknown: int = 0
    errors: dict[str, int] = field(default_factory=lambda: dict.fromkeys(ERROR_KINDS, 0))

    @property
    def parse_errors(self) -> int:
        return sum(self.errors.values())

    def copy(self) -> ParseStats:
        return ParseStats(
            self.bytes,
            self.sentences,
            self.samples,
            self.gaps,
            self.gap_events,
            self.duplicates,
            self.restarts,
            self.unknown,
            dict(self.errors),
        )


# ---------------------------------------------------------------- encoding


def checksum(payload: bytes) -> int:
    """XOR of the bytes between `$` and `*`."""
    return reduce(xor, payload, 0)


def sentence(*fields: object) -> bytes:
    """`$f0,f1,...*CS\\r\\n`; fields must not contain `$ * , CR LF`."""
    payload = ",".join(str(f) for f in fields).encode("ascii")
    return b"$%s*%02X\r\n" % (payload, checksum(payload))


def format_value(v: float, digits: int = 7) -> str:
    """A value as the shortest of `%.{digits}g`; NaN as an empty field."""
    return "" if v != v else format(v, f".{digits}g")


def header_sentence(h: Header) -> bytes:
    """`$STH`: version 1 without extra channels (what every v1 parser reads), 2 with them."""
    rate = "" if h.rate_hz != h.rate_hz else format_value(h.rate_hz, 9)
    bad = [c for c in h.channels if c not in CHANNELS]
    if bad:
        raise ValueError(f"unknown channel(s) {', '.join(bad)}: known are {', '.join(CHANNELS)}")
    version = max(h.version, 2) if h.channels else h.version
    return sentence("STH", version, h.device_id, h.accel_unit, h.gyro_unit, h.mag_unit, rate, *h.channels)


def data_sentence(seq: int, t_dev_us: int, values, digits: int = 7) -> bytes:
    """One `$STD` sentence; seq and time are reduced modulo their ranges."""
    return sentence(
        "STD",
        int(seq) % SEQ_MODULO,
        int(t_dev_us) % TIME_MODULO,
        *(format_value(float(v), digits) for v in values),
    )


def data_sentences(seq0: int, t_dev_us, values, digits: int = 7) -> bytes:
    """Consecutive `$STD` sentences for a block: seq0, seq0+1, ...; values shape (n, 10),
    or (n, 10 + k) with the values of the header's k extra channels after temp_c."""
    fmt = f".{digits}g"
    out = []
    for i, (t, row) in enumerate(zip(np.asarray(t_dev_us).tolist(), np.asarray(values, dtype=float).tolist())):
        payload = "STD,%d,%d,%s" % (  # noqa: UP031
            (seq0 + i) % SEQ_MODULO,
            int(t) % TIME_MODULO,
            ",".join("" if v != v else format(v, fmt) for v in row),
        )
        b = payload.encode("ascii")
        out.append(b"$%s*%02X\r\n" % (b, reduce(xor, b, 0)))
    return b"".join(out)


def command_sentence(verb: str, *args: object) -> bytes:
    return sentence("STC", verb.upper(), *args)


def ack_sentence(verb: str, ok: bool, text: str = "") -> bytes:
    text = text.replace(",", ";").replace("*", "").replace("$", "")
    return (
        sentence("STA", verb.upper(), "OK" if ok else "ERR", text)
        if text
        else sentence("STA", verb.upper(), "OK" if ok else "ERR")
    )


# ---------------------------------------------------------------- parsing


class StationParser:
    """Incremental parser of the station line protocol (both directions).

    `feed(chunk)` returns the non-sample events (Header, Command, Ack, Restart,
    Unknown) in arrival order; samples accumulate until `take()`. Every problem is
    counted in `stats` by kind:

    - `noise`: a line without `$`, or bytes in front of the `$` of a sentence
      (the sentence itself is still judged);
    - `checksum`: the XOR does not match;
    - `malformed`: no `*CS`, bad hex, not ASCII, too few fields, a bad number,
      a counter out of range;
    - `too_long`: more than MAX_LINE bytes without a line end.

    Values: empty fields, `nan` and `inf` (as an Arduino prints them) become NaN.

    Bytes before the first `$` of a stream (or after `reset_stream()`) are skipped
    without counting: a reader that opens a port mid-stream sees the tail of a line.

    Sequence numbers give `gaps` (samples missed; a step of d > 1 adds d - 1),
    `duplicates` (same seq again, the repeat is dropped) and `restarts` (seq 0 right
    after a header, a step of more than half the range, or the device clock going
    backwards: a new segment, no gap counted). The device clock is unwrapped modulo
    2**32 (steps of less than half the range, in either direction).
    """

    def __init__(self) -> None:
        self.stats = ParseStats()
        self.header: Header | None = None
        self._buf = b""
        self._skipping = False
        self._rows: list[list[float]] = []
        self._channels: tuple[str, ...] = ()  # of the current header: the rows' extra values
        self._blocks: list[SampleBlock] = []  # rows taken off at a change of channels
        self._last_seq: int | None = None
        self._last_t_raw = 0
        self._t_us = 0
        self._header_just_seen = False
        self._synced = False  # a `$` seen since the stream (re)started
        # rows met before the first header (a host that joins a running stream): their
        # trailing values, kept until the header says which channels they are
        self._pre_extra: list[list[float]] = []

    # -- public

    def feed(self, data: bytes) -> list:
        """Parse a chunk; return the events it completed (samples go to `take()`)."""
        events: list = []
        if not data:
            return events
        self.stats.bytes += len(data)
        buf = self._buf + data if self._buf else bytes(data)
        start = 0
        find = buf.find
        while True:
            nl = find(b"\n", start)
            if nl < 0:
                break
            self._line(buf[start:nl], events)
            start = nl + 1
        rest = buf[start:]
        if len(rest) > MAX_LINE:
            self.stats.errors["too_long"] += 1
            d = rest.rfind(b"$")
            if d > 0 and len(rest) - d <= MAX_LINE:
                rest = rest[d:]
            else:
                rest = b""
                self._skipping = True
        self._buf = rest
        return events

    def take(self) -> SampleBlock | None:
        """The samples parsed since the last call, or None. Rows before the first header
        are held (up to PRE_HEADER_HOLD_US of device time) until it names their extra channels."""
        if (
            self.header is None
            and any(self._pre_extra)  # trailing values: a version-2 device
            and self._rows[-1][1] - self._rows[0][1] < PRE_HEADER_HOLD_US
        ):
            return None
        self._pre_extra = []
        rows, self._rows = self._rows, []
        blocks, self._blocks = self._blocks, []
        last = SampleBlock.from_rows(rows, self._channels)
        return SampleBlock.concat(blocks + ([last] if last is not None else []))

    def reset_stream(self) -> None:
        """Drop the partial line (after a reconnect). Sequence and clock continuity are
        kept: a device that ran on while unplugged gets its missed samples counted as a
        gap; one that restarted is detected as a Restart."""
        self._buf = b""
        self._skipping = False
        self._synced = False

    # -- internals

    def _line(self, line: bytes, events: list) -> None:
        errors = self.stats.errors
        if line.endswith(b"\r"):
            line = line[:-1]
        skipping, self._skipping = self._skipping, False
        if not line:
            return
        d = line.rfind(b"$")
        if not self._synced:
            # the tail of a sentence sent before the port was opened: not an error
            if d < 0:
                return
            self._synced = skipping = True
        if d < 0:
            if not skipping:
                errors["noise"] += 1
            return
        if d > 0 and not skipping:
            errors["noise"] += 1
        s = line[d + 1 :]
        star = len(s) - 3
        if star < 0 or s[star] != 0x2A or s[-1] not in _HEX or s[-2] not in _HEX:
            errors["malformed"] += 1
            return
        payload = s[:star]
        if reduce(xor, payload, 0) != int(s[star + 1 :], 16):
            errors["checksum"] += 1
            return
        try:
            fields = payload.decode("ascii").split(",")
        except UnicodeDecodeError:
            errors["malformed"] += 1
            return
        kind = fields[0]
        if kind == "STD":
            self._data(fields, events)
            return
        ev = self._other(kind, fields)
        if ev is None:
            errors["malformed"] += 1
            return
        self.stats.sentences += 1
        if isinstance(ev, Unknown):
            self.stats.unknown += 1
        events.append(ev)

    def _data(self, fields: list[str], events: list) -> None:
        st = self.stats
        if len(fields) < 13:
            st.errors["malformed"] += 1
            return
        k = len(self._channels)
        try:
            seq = int(fields[1])
            t_raw = int(fields[2])
            vals = [float(v) if v else _NAN for v in fields[3:13]]
            pre = [float(v) if v else _NAN for v in fields[13:]] if self.header is None else None
            if k:  # the header's extra channels; missing trailing fields are missing values
                vals += [float(v) if v else _NAN for v in fields[13 : 13 + k]] + [_NAN] * max(0, 13 + k - len(fields))
        except ValueError:
            st.errors["malformed"] += 1
            return
        if not (0 <= seq < SEQ_MODULO and 0 <= t_raw < TIME_MODULO):
            st.errors["malformed"] += 1
            return
        st.sentences += 1
        last = self._last_seq
        if last is None:
            self._t_us = t_raw
        else:
            step = (seq - last) % SEQ_MODULO
            if step == 0:
                st.duplicates += 1
                return
            dt = (t_raw - self._last_t_raw) % TIME_MODULO
            if dt >= TIME_MODULO // 2:
                dt -= TIME_MODULO
            if (self._header_just_seen and seq == 0 and step != 1) or step > SEQ_MODULO // 2 or dt < 0:
                st.restarts += 1
                events.append(Restart(st.samples))
                self._t_us = t_raw
            else:
                if step > 1:
                    st.gaps += step - 1
                    st.gap_events += 1
                self._t_us += dt
        self._last_seq = seq
        self._last_t_raw = t_raw
        self._header_just_seen = False
        self._rows.append([seq, self._t_us, *vals])
        if pre is not None:
            self._pre_extra.append(pre)
        st.samples += 1

    def _other(self, kind: str, fields: list[str]):
        at = self.stats.samples
        if kind == "STH":
            if len(fields) < 7:
                return None
            try:
                version = int(fields[1])
                rate = float(fields[6]) if fields[6] else _NAN
            except ValueError:
                return None
            # version 2: the extra channels; names this parser does not know are malformed
            channels = tuple(fields[7:]) if version >= 2 else ()
            if any(c not in CHANNELS for c in channels) or len(set(channels)) != len(channels):
                return None
            h = Header(fields[2], fields[3], fields[4], fields[5], rate, version, at, channels)
            if self.header is None and self._pre_extra and len(self._pre_extra) == len(self._rows):
                k = len(channels)  # the first header names the held rows' trailing values
                for row, extra in zip(self._rows, self._pre_extra, strict=True):
                    row.extend((extra + [_NAN] * k)[:k])
                self._channels = channels
            self._pre_extra = []
            if channels != self._channels:
                if self._rows:  # rows before it carry the old channels
                    self._blocks.append(SampleBlock.from_rows(self._rows, self._channels))
                    self._rows = []
                self._channels = channels
            self.header = h
            self._header_just_seen = True
            return h
        if kind == "STC":
            if len(fields) < 2 or not fields[1]:
                return None
            return Command(fields[1].upper(), tuple(fields[2:]), at)
        if kind == "STA":
            if len(fields) < 3 or fields[2] not in ("OK", "ERR"):
                return None
            return Ack(fields[1].upper(), fields[2] == "OK", ",".join(fields[3:]), at)
        if not kind:
            return None
        return Unknown(tuple(fields), at)
