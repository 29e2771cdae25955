"""A serial reader that never blocks its consumers.

`Reader(port)` opens a device path or a pyserial URL (`loop://`, `socket://host:port`,
`rfc2217://...`) and reads it on a background thread. Bytes go through the protocol's
parser; samples are batched (one `Batch` of numpy arrays per read, at most `poll_s`
apart) into a bounded queue that consumers empty with `drain()`, and/or are handed to
callbacks registered with `subscribe()` (called on the reader thread: keep them short,
e.g. `app.call_from_thread(...)` or `post_message`).

Time: `t_s` is seconds since the first sample of the session, from the device clock
(unwrapped). After a device restart the clock is re-anchored on the host's monotonic
clock, so `t_s` stays non-decreasing.

Unplug: a read error (SerialException/OSError, the port vanishing) closes the port and
the reader retries opening the same path with exponential backoff (`backoff_s` up to
`backoff_max_s`) until `stop()`. Each reconnection or device restart starts a new
`segment` (a column of every batch) and appends a `GapEvent`; samples already queued
are never discarded by a reconnection. If the device ran on while unplugged, the
sequence numbers count exactly the samples it missed (`gaps`).

The queue holds at most `max_queued` samples; when a consumer falls behind, the oldest
batches are dropped and counted in `stats().dropped`.
"""

from __future__ import annotations

import collections
import math
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import serial

from station.device.protocol import (
    SENSOR_FIELDS,
    Header,
    Restart,
    StationParser,
    command_sentence,
)
from station.errors import StationError

PROTOCOLS = ("station", "mavlink")


class PortError(StationError):
    """The port could not be opened (first attempt): one line, exit status 2."""


@dataclass
class Batch:
    """Samples in arrival order. `values` shape (n, 10) in SENSOR_FIELDS order; `extra`
    the extra channels a version-2 header names (``ref_gx``, ``vl1``, ...), each (n,)."""

    t_s: np.ndarray
    seq: np.ndarray
    segment: np.ndarray
    values: np.ndarray
    extra: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t_s)

    def column(self, name: str) -> np.ndarray:
        if name == "t":
            return self.t_s
        if name == "segment":
            return self.segment.astype(np.float64)
        if name in self.extra:
            return self.extra[name]
        if name not in SENSOR_FIELDS:
            return np.full(len(self), np.nan)  # a channel this batch's device did not send
        return self.values[:, SENSOR_FIELDS.index(name)]

    @property
    def columns(self) -> dict[str, np.ndarray]:
        cols = {"t": self.t_s, "segment": self.segment.astype(np.float64)}
        cols.update({name: self.values[:, i] for i, name in enumerate(SENSOR_FIELDS)})
        cols.update(self.extra)
        return cols

    def select(self, mask) -> Batch:
        return Batch(
            self.t_s[mask],
            self.seq[mask],
            self.segment[mask],
            self.values[mask],
            {k: v[mask] for k, v in self.extra.items()},
        )

    @staticmethod
    def concat(batches: list[Batch]) -> Batch | None:
        if not batches:
            return None
        if len(batches) == 1:
            return batches[0]
        names = list(dict.fromkeys(k for b in batches for k in b.extra))
        return Batch(
            np.concatenate([b.t_s for b in batches]),
            np.concatenate([b.seq for b in batches]),
            np.concatenate([b.segment for b in batches]),
            np.concatenate([b.values for b in batches]),
            {k: np.concatenate([b.column(k) for b in batches]) for k in names},
        )


@dataclass(frozen=True)
class GapEvent:
    """A break in the stream: the segment `segment` starts after it.

    `t_s`: time of the last sample before the break (NaN if none); `t_resume_s`: of
    the first sample after it (NaN until one arrives); `down_s`: host seconds without
    a connection (0 for a device restart); `missed`: samples the sequence numbers say
    were lost across it (-1 when unknown, i.e. the device restarted).
    """

    segment: int
    reason: str  # 'reconnect', 'restart', 'device changed', 'reconnect, device changed'
    t_s: float
    t_resume_s: float = math.nan
    down_s: float = 0.0
    missed: int = -1
    error: str = ""


@dataclass
class ReaderStats:
    samples: int = 0
    rate_hz: float = math.nan
    parse_errors: int = 0
    errors: dict[str, int] = field(default_factory=dict)
    gaps: int = 0
    restarts: int = 0
    duplicates: int = 0
    reconnects: int = 0
    dropped: int = 0
    bytes: int = 0
    cpu_s: float = 0.0
    connected: bool = False
    segment: int = 0
    last_error: str = ""
    last_sample_at: float = math.nan  # host time.monotonic() the newest sample arrived (nan: none yet)


def make_parser(protocol: str, mavlink_source: str | None = None, request_hz: float | None = None):
    if protocol == "station":
        return StationParser()
    if protocol == "mavlink":
        from station.device.mavlink import MavlinkParser

        return MavlinkParser(mavlink_source, request_hz)
    raise ValueError(f"unknown protocol {protocol!r} (station or mavlink)")


NETWORK_PREFIXES = ("udp:", "udpin:", "udpout:", "udpbcast:", "tcp:", "tcpin:")  # = mavlink.NETWORK_PREFIXES
# pyserial's URL schemes: what each looks like, the options it takes (None: not checked here)
URL_SCHEMES = {
    "socket": ("socket://HOST:PORT", {"logging"}),
    "rfc2217": ("rfc2217://HOST:PORT", {"logging", "ign_set_control", "poll_modem", "timeout"}),
    "loop": ("loop://", {"logging"}),
    "spy": ("spy://DEVICE", None),
    "alt": ("alt://DEVICE?class=NAME", None),
    "hwgrep": ("hwgrep://REGEXP", None),
    "cp2110": ("cp2110://BUS:DEVICE:INTERFACE", None),
}
LOG_LEVELS = ("debug", "info", "warning", "error")
EMPTY_READ_GRACE_S = 0.25  # empty "ready" reads for this long: the port is gone


def _path_still_there(port: str) -> bool:
    """False only for a device path that has vanished (URLs and endpoints: True)."""
    return "://" in port or port.lower().startswith(NETWORK_PREFIXES) or os.path.exists(port)


def _port_number_problem(text: str, form: str) -> str | None:
    if not text.isdigit():
        return f"port number {text!r} is not a number: expected {form}" if text else f"no port number: expected {form}"
    if not 1 <= int(text) <= 65535:
        return f"port number {int(text)} is out of range 1-65535: expected {form}"
    return None


def port_problem(port: str) -> str | None:
    """What is wrong with a device path or URL before anything is opened (a host and port
    number, a URL scheme, its options), None when nothing can be said yet: pyserial's own
    messages for these quote its format strings or fail inside them."""
    from urllib.parse import parse_qs, urlsplit

    if not port.strip():
        return "no port given"
    if port.lower().startswith(NETWORK_PREFIXES):
        scheme, _, rest = port.partition(":")
        host, sep, number = rest.rpartition(":")
        form = f"{scheme.lower()}:HOST:PORT"
        return _port_number_problem(number, form) if sep else f"no port number: expected {form}"
    if "://" not in port:
        return None  # a device path: the system says what is wrong with it
    scheme = port.split("://", 1)[0].lower()
    if scheme not in URL_SCHEMES:
        known = ", ".join(f"{k}://" for k in URL_SCHEMES)
        return f"unknown URL scheme {scheme!r}: a device path such as /dev/ttyUSB0, or one of {known}"
    form, options = URL_SCHEMES[scheme]
    try:
        parts = urlsplit(port)
    except ValueError as exc:  # a bad IPv6 bracket
        return f"not a valid URL ({exc}): expected {form}"
    if scheme in ("socket", "rfc2217"):
        host, sep, number = parts.netloc.rpartition(":")
        if not sep:
            return f"no port number: expected {form}"
        problem = _port_number_problem(number, form)
        if problem:
            return problem
    if options is not None:
        for option, values in parse_qs(parts.query, keep_blank_values=True).items():
            if option not in options:
                return f"unknown option {option!r}: {scheme}:// takes {', '.join(sorted(options))}"
            if option == "logging" and values[0] not in LOG_LEVELS:
                return f"logging={values[0]!r}: one of {', '.join(LOG_LEVELS)}"
    return None


def open_error_text(port: str, exc: BaseException) -> str:
    """One line for a port that did not open: the system's reason without pyserial's
    "could not open port PORT: [Errno N] ..." wrapping."""
    import os

    errno = getattr(exc, "errno", None)
    if isinstance(errno, int) and errno > 0:
        return os.strerror(errno)
    import re

    text = " ".join(str(exc).split()) or type(exc).__name__
    prefix = f"could not open port {port}: "
    if text.lower().startswith(prefix.lower()):
        text = text[len(prefix) :]
    return re.sub(r"^\[Errno -?\d+\] ", "", text)


def open_port(port: str, baud: int = 115200, timeout_s: float = 0.02):
    """A device path or any pyserial URL, opened, raw 8N1; a MAVLink network endpoint
    (`udp:HOST:PORT`, `udpout:`, `tcp:`, `tcpin:`) through pymavlink's connection layer."""
    if port.lower().startswith(NETWORK_PREFIXES):
        from station.device.mavlink import NetworkPort  # pymavlink's import is slow: only for these

        return NetworkPort(port, timeout_s)
    return serial.serial_for_url(port, baudrate=baud, timeout=timeout_s, write_timeout=1.0)


class Reader:
    """Background reader of one port. Use as a context manager or start()/stop()."""

    def __init__(
        self,
        port: str,
        *,
        baud: int = 115200,
        protocol: str = "station",
        mavlink_source: str | None = None,
        poll_s: float = 0.02,
        chunk_bytes: int = 1 << 16,
        max_queued: int = 200_000,
        backoff_s: float = 0.05,
        backoff_max_s: float = 1.0,
        request_header: bool = True,
        request_hz: float | None = None,
    ) -> None:
        if protocol not in PROTOCOLS:
            raise ValueError(f"unknown protocol {protocol!r} (station or mavlink)")
        self.port = port
        self.baud = baud
        self.protocol = protocol
        self.poll_s = poll_s
        self.chunk_bytes = chunk_bytes
        self.max_queued = max_queued
        self.backoff_s = backoff_s
        self.backoff_max_s = backoff_max_s
        self.request_header = request_header and protocol == "station"
        self.parser = make_parser(protocol, mavlink_source, request_hz)
        self.header: Header | None = None
        # (old header, new header, first segment of the new device)
        self.header_changes: list[tuple[Header, Header, int]] = []
        self._cuts: dict[int, tuple[str, Header | None, Header | None]] = {}  # sample index -> break
        self.acks: collections.deque = collections.deque(maxlen=100)
        self._ser = None
        self._lock = threading.Lock()  # queue, stats, events
        self._wlock = threading.Lock()  # port writes / swaps
        self._queue: collections.deque[Batch] = collections.deque()
        self._queued = 0
        self._callbacks: list[Callable[[Batch], None]] = []
        self._out: collections.deque[bytes] = collections.deque(maxlen=1000)  # to the device
        self._events: list[GapEvent] = []
        self._stop = threading.Event()
        self._header_seen = threading.Event()
        self._thread: threading.Thread | None = None
        self._stats = ReaderStats()
        self._rate_window: collections.deque = collections.deque()
        # time anchoring
        self._segment = 0
        self._anchor_t_s: float | None = None
        self._anchor_dev_us = 0.0
        self._t0_host: float | None = None
        self._last_t_s = math.nan
        self._taken = 0  # parser samples already turned into batches
        self._pending_gap: GapEvent | None = None
        self._gaps_before_break = 0
        self._empty_since: float | None = None  # first of a run of empty "ready" reads

    # ------------------------------------------------------------ lifecycle

    def start(self, *, wait_for_port: bool = False) -> Reader:
        """Open the port and start the thread. Raises PortError if the port cannot be
        opened, unless `wait_for_port` (then the thread keeps trying)."""
        if self._thread is not None:
            return self
        problem = port_problem(self.port)  # never retried: waiting would not mend it
        if problem:
            raise PortError(f"{self.port}: {problem}")
        if not wait_for_port:
            try:
                self._ser = open_port(self.port, self.baud, self.poll_s)
            except Exception as exc:  # noqa: BLE001 - pyserial's URL handlers raise KeyError, TypeError ...
                raise PortError(f"{self.port}: cannot open: {open_error_text(self.port, exc)}") from None
            self._on_connect()
        self._thread = threading.Thread(target=self._run, name=f"reader {self.port}", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 2.0) -> None:
        self._stop.set()
        ser = self._ser
        if ser is not None and hasattr(ser, "cancel_read"):
            try:
                ser.cancel_read()
            except Exception:  # noqa: BLE001 - closing anyway
                pass
        if self._thread is not None:
            self._thread.join(timeout_s)
        self._close()

    def __enter__(self) -> Reader:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    # ------------------------------------------------------------ consumers

    def subscribe(self, callback: Callable[[Batch], None]) -> None:
        """Call `callback(batch)` on the reader thread for every batch."""
        self._callbacks.append(callback)

    def drain(self) -> Batch | None:
        """Every queued sample since the last drain, as one Batch (or None). Never blocks
        for I/O."""
        with self._lock:
            batches = list(self._queue)
            self._queue.clear()
            self._queued = 0
        return Batch.concat(batches)

    def wait_header(self, timeout_s: float) -> Header | None:
        self._header_seen.wait(timeout_s)
        return self.header

    def events(self) -> list[GapEvent]:
        with self._lock:
            return list(self._events)

    def stats(self) -> ReaderStats:
        with self._lock:
            s = self._stats
            p = self.parser.stats
            out = ReaderStats(**{k: getattr(s, k) for k in s.__dataclass_fields__})
            out.errors = dict(p.errors)
            out.parse_errors = p.parse_errors
            out.gaps = p.gaps
            out.restarts = p.restarts
            out.duplicates = p.duplicates
            out.bytes = p.bytes
            out.segment = self._segment
            return out

    def send(self, data: bytes) -> bool:
        """Queue raw bytes for the device; the reader thread writes them within ~`poll_s`.

        Never blocks the caller. False if the port is not connected (nothing queued).
        """
        if self._ser is None:
            return False
        self._out.append(bytes(data))
        return True

    def _write_pending(self, ser) -> None:
        while self._out:
            data = self._out.popleft()
            with self._wlock:
                ser.write(data)

    def command(self, verb: str, *args: object) -> bool:
        """Send `$STC,<verb>,<args>` (station protocol commands, docs/protocol.md)."""
        return self.send(command_sentence(verb, *args))

    # ------------------------------------------------------------ thread

    def _run(self) -> None:
        cpu0 = time.thread_time()
        backoff = self.backoff_s
        down_since: float | None = None
        last_error = ""
        while not self._stop.is_set():
            ser = self._ser
            if ser is None:
                if down_since is None:
                    down_since = time.monotonic()
                try:
                    new = open_port(self.port, self.baud, self.poll_s)
                except (serial.SerialException, OSError, ValueError) as exc:
                    last_error = str(exc)
                    self._stop.wait(backoff)
                    backoff = min(backoff * 2, self.backoff_max_s)
                    continue
                with self._wlock:
                    self._ser = new
                backoff = self.backoff_s
                if self._t0_host is not None or self._stats.reconnects or self._pending_gap:
                    self._mark_reconnect(time.monotonic() - down_since, last_error)
                down_since = None
                self._on_connect()
                continue
            try:
                data = ser.read(self.chunk_bytes)
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                # TypeError/AttributeError: pyserial racing a close from stop()
                if self._stop.is_set():
                    break
                if self._empty_read_is_transient(exc):
                    continue
                last_error = str(exc)
                with self._lock:
                    self._stats.connected = False
                    self._stats.last_error = last_error
                self._close()
                down_since = time.monotonic()
                continue
            if data:
                self._empty_since = None
                self._ingest(data, time.monotonic())
            if self._out:
                try:
                    self._write_pending(ser)
                except (serial.SerialException, OSError) as exc:  # seen by the next read too
                    self._stats.last_error = f"write: {exc}"
            with self._lock:
                self._stats.cpu_s = time.thread_time() - cpu0
        with self._lock:
            self._stats.cpu_s = time.thread_time() - cpu0

    def _empty_read_is_transient(self, exc: Exception) -> bool:
        """pyserial's "readiness to read but returned no data" is what an unplugged port
        shows, always; but a loaded Linux pty shows it once too (select wakes before the
        line discipline has handed the bytes over; pyserial reads with VMIN=0). Closing
        then would flush what the device sent meanwhile, so the port is given
        `EMPTY_READ_GRACE_S` of such reads, and closed at once if its path is gone."""
        if "returned no data" not in str(exc):
            return False
        now = time.monotonic()
        if self._empty_since is None:
            self._empty_since = now
        if now - self._empty_since >= EMPTY_READ_GRACE_S or not _path_still_there(self.port):
            self._empty_since = None
            return False
        self._stop.wait(min(self.poll_s, 0.005))
        return True

    def _close(self) -> None:
        with self._wlock:
            ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except Exception:  # noqa: BLE001 - the port is gone already
                pass

    def _on_connect(self) -> None:
        with self._lock:
            self._stats.connected = True
        self.parser.reset_stream()
        if self.request_header:
            try:
                with self._wlock:
                    self._ser.write(command_sentence("HDR"))
            except (serial.SerialException, OSError):
                pass  # the next read will see a dead port

    def _mark_reconnect(self, down_s: float, error: str) -> None:
        with self._lock:
            self._stats.reconnects += 1
            self._segment += 1
            self._pending_gap = GapEvent(self._segment, "reconnect", self._last_t_s, down_s=down_s, error=error)
            self._gaps_before_break = self.parser.stats.gaps

    # ------------------------------------------------------------ parsing, timing

    def _ingest(self, data: bytes, host_now: float) -> None:
        events = self.parser.feed(data)
        for frame in getattr(self.parser, "take_outgoing", lambda: [])():
            self.send(frame)
        block = self.parser.take()
        for ev in events:
            if isinstance(ev, Header):
                if self.header is not None and not ev.same_device(self.header):
                    # another device on the port: a break before its first sample
                    self._cuts[ev.at_sample] = ("device changed", self.header, ev)
                self.header = ev
                self._header_seen.set()
            elif isinstance(ev, Restart):
                self._cuts.setdefault(ev.at_sample, ("restart", None, None))
            elif type(ev).__name__ == "Ack":
                self.acks.append(ev)
        if block is None:
            return
        n = len(block)
        first = self._taken
        self._taken += n
        mine = {max(0, i - first): self._cuts.pop(i) for i in sorted(self._cuts) if i < first + n}
        dev = block.t_dev_us
        # arrival time of the first sample of this block, from the device clock
        t_first_host = host_now - (dev[-1] - dev[0]) * 1e-6
        if self._t0_host is None:
            self._t0_host = t_first_host
        t_s = np.empty(n)
        seg = np.empty(n, dtype=np.int64)
        cuts = sorted(set(mine) | {0, n})
        for a, b in zip(cuts[:-1], cuts[1:]):
            cut = mine.get(a)
            if cut is not None or self._anchor_t_s is None:
                host_t = self._t0_host if self._anchor_t_s is None else (host_now - (dev[b - 1] - dev[a]) * 1e-6)
                t_anchor = host_t - self._t0_host
                if not math.isnan(self._last_t_s):
                    t_anchor = max(t_anchor, self._last_t_s + 1e-6)
                if cut is not None:
                    reason, old, new = cut
                    with self._lock:
                        if self._pending_gap is None or not math.isnan(self._pending_gap.t_resume_s):
                            self._segment += 1
                            self._pending_gap = GapEvent(self._segment, reason, self._last_t_s)
                        else:  # reconnected onto a restarted (or another) device: one break
                            self._pending_gap = GapEvent(
                                self._pending_gap.segment,
                                "reconnect" if reason == "restart" else f"reconnect, {reason}",
                                self._pending_gap.t_s,
                                down_s=self._pending_gap.down_s,
                                error=self._pending_gap.error,
                            )
                            self._gaps_before_break = -1
                    if old is not None:
                        self.header_changes.append((old, new, self._segment))
                self._anchor_t_s = t_anchor
                self._anchor_dev_us = dev[a]
            t_s[a:b] = self._anchor_t_s + (dev[a:b] - self._anchor_dev_us) * 1e-6
            seg[a:b] = self._segment
            if self._pending_gap is not None and math.isnan(self._pending_gap.t_resume_s):
                g = self._pending_gap
                missed = (
                    -1
                    if (g.reason != "reconnect" or self._gaps_before_break < 0)
                    else (self.parser.stats.gaps - self._gaps_before_break)
                )
                with self._lock:
                    self._events.append(GapEvent(g.segment, g.reason, g.t_s, float(t_s[a]), g.down_s, missed, g.error))
                    self._pending_gap = None
            self._last_t_s = float(t_s[b - 1])
        batch = Batch(t_s, block.seq, seg, block.values, dict(getattr(block, "extra", {}) or {}))
        with self._lock:
            self._stats.samples += n
            self._stats.last_sample_at = host_now
            self._rate(host_now, self._stats.samples)
            self._queue.append(batch)
            self._queued += n
            while self._queued > self.max_queued and len(self._queue) > 1:
                old = self._queue.popleft()
                self._queued -= len(old)
                self._stats.dropped += len(old)
        for cb in list(self._callbacks):
            try:
                cb(batch)
            except Exception as exc:  # noqa: BLE001 - a consumer bug must not stop the reader
                self._stats.last_error = f"callback: {exc!r}"

    def _rate(self, now: float, total: int) -> None:
        w = self._rate_window
        w.append((now, total))
        while len(w) > 2 and now - w[0][0] > 2.0:
            w.popleft()
        if len(w) >= 2 and w[-1][0] > w[0][0]:
            self._stats.rate_hz = (w[-1][1] - w[0][1]) / (w[-1][0] - w[0][0])
