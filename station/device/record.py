"""Headless recording of a device into a capture file (../shared/spec/capture-format.md).

The recording is written as it arrives to `<out>.partial`, itself a capture file whose
metadata says `complete: false`, flushed after every batch. At the end (the time is up,
SIGINT/SIGTERM, the device changed) the final metadata are known; they are written with
the rows copied from the partial file into a temporary file beside `<out>`, which is
then renamed to `<out>` (atomic), and the partial file is removed. So a recording that
is stopped leaves a complete capture; one that is killed outright (SIGKILL, power cut)
leaves only `<out>.partial`, a valid capture up to its last line, which may be cut in
the middle, or a tail of NUL bytes after a power cut: `recover_partial()` (`station record
--recover FILE.partial`) keeps every whole row, drops that cut last line (and says so), and
finishes the file as `complete: false`; it refuses, writing nothing, a file whose rows the
capture reader refuses before the last line.

Columns: `t` (s, from the device clock, see reader.py), `segment` (0, 1, ...: a new
segment after each reconnection or device restart, so a gap is visible in the data),
then the sensor columns the device has (a header unit that is empty means absent) and
`temp_c`. Metadata beyond the spec's keys: `recorded_at`, `source`, `protocol`,
`samples`, `gaps` (samples missed, from sequence numbers), `parse_errors` (and
`parse_errors_by_kind`), `dropped` (reader queue overflow), `reconnects`, `restarts`,
`segments`, one `gap_<k>` line per break, `nominal_rate_hz`, `duration_s`, `complete`.

A device that is lost and never comes back before the end, or that is connected but sends
nothing for the last `SILENCE_S` seconds (after a reconnection: it came back silent), leaves
a capture with every sample it did send, `complete: false`, `incomplete: <why>` and
`last_data_s` (when the data stop, s from the start); `station record` exits 1.
"""

from __future__ import annotations

import datetime as _dt
import math
import os
import re
import threading
import time
from dataclasses import dataclass, field

import numpy as np

try:
    import fcntl
except ImportError:  # pragma: no cover - not on POSIX
    fcntl = None

from station.device.protocol import Header
from station.device.reader import Batch, GapEvent, Reader, ReaderStats
from station.errors import InputError, StationError
from station.fileio import atomic_open, open_input, same_file, scratch_file

SENSOR_GROUPS = {"accel_unit": ("ax", "ay", "az"), "gyro_unit": ("gx", "gy", "gz"), "mag_unit": ("mx", "my", "mz")}
PARTIAL_SUFFIX = ".partial"


class RecordError(StationError):
    """The recording could not produce a capture (no samples, cannot write, ...)."""


@dataclass
class RecordResult:
    path: str
    samples: int
    meta: dict[str, str]
    stats: ReaderStats
    events: list[GapEvent] = field(default_factory=list)
    stopped_because: str = ""
    incomplete: str = ""  # why the capture is `complete: false` (device lost, or silent), "" when complete


def _known_units() -> dict[str, tuple[str, ...]]:
    from station.capture import UNIT_KEYS

    return UNIT_KEYS


def columns_for(header: Header | None) -> list[str]:
    """`t`, `segment`, the sensors the header says the device has (all without one), `temp_c`,
    then the header's extra channels (protocol version 2: `ref_gx`, `vl1`, ...)."""
    cols = ["t", "segment"]
    for key, names in SENSOR_GROUPS.items():
        if header is None or getattr(header, key):
            cols.extend(names)
    cols.append("temp_c")
    cols.extend(getattr(header, "channels", ()) if header is not None else ())
    return cols


def _fmt(x: float) -> str:
    if x != x:
        return ""
    s = repr(x)
    return s[:-2] if s.endswith(".0") else s


def format_rows(batch: Batch, columns: list[str]) -> str:
    """CSV rows for a batch: t to the microsecond, values as repr (round-trip exact)."""
    vals = np.column_stack([batch.column(c) for c in columns[2:]]).tolist()
    t = batch.t_s.tolist()
    seg = batch.segment.tolist()
    out = []
    for i, row in enumerate(vals):
        out.append("%.6f,%d,%s\n" % (t[i], seg[i], ",".join(["" if v != v else _fmt(v) for v in row])))  # noqa: UP031
    return "".join(out)


def _lock(f) -> bool:
    """Take the advisory lock (flock) a recording holds on its partial file while it writes
    it; the kernel drops it when the process ends, however it ends (SIGKILL, a power cut too).
    False when another process holds it: a recording is writing the file."""
    if fcntl is None:  # no flock here: a live partial cannot be told from a killed one's
        return True
    try:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError:  # a file system without locks: nothing to learn from it
        return True
    return True


def _being_written(path: str) -> bool:
    """Whether a running recording holds ``path`` (its partial file) locked."""
    if not os.path.isfile(path):
        return False
    try:
        with open(path, "rb") as f:
            return not _lock(f)
    except OSError:
        return False


def refuse_unrecovered(out: str) -> None:
    """Refuse a recording into ``out`` while ``<out>.partial`` exists: the rows of a killed
    recording, not yet recovered, which the new one would write over and remove (or of a
    recording still running)."""
    partial = os.fspath(out) + PARTIAL_SUFFIX
    if _being_written(partial):
        raise InputError(
            partial, None, "a recording is writing it now: wait for it to end, or stop it (Ctrl-C, SIGTERM)"
        )
    if os.path.lexists(partial):
        raise InputError(
            partial,
            None,
            f"a killed recording's rows, not yet recovered: station record --recover {partial} "
            "first (or remove the file)",
        )


class CaptureStream:
    """Writes a capture incrementally to `<out>.partial`, then finishes it as `<out>`."""

    def __init__(self, out: str, columns: list[str], meta: dict[str, str]) -> None:
        self.out = os.fspath(out)
        self.partial = self.out + PARTIAL_SUFFIX
        self.columns = columns
        self.rows = 0
        head = dict(meta)
        head["complete"] = "false"
        if os.path.isdir(self.out):
            raise InputError(self.out, None, "is a folder: give --out a file name for the capture")
        try:  # "x": a partial a killed recording left is never truncated (refuse_unrecovered says why)
            self._f = open(self.partial, "x", encoding="utf-8", newline="\n")
        except FileExistsError:
            refuse_unrecovered(self.out)
            raise
        except OSError as exc:
            raise InputError(self.partial, None, f"cannot write: {exc.strerror or exc}") from None
        _lock(self._f)  # held until the partial is finished and removed: --recover leaves it alone
        self._f.write(_head_text(head, columns))
        self._f.flush()
        try:  # the head must be one the capture reader accepts (units, --meta values)
            from station.capture import iter_capture_chunks

            iter_capture_chunks(self.partial)
        except InputError:
            self.abandon()
            raise

    def write(self, batch: Batch) -> None:
        if not len(batch):
            return
        self._f.write(format_rows(batch, self.columns))
        self._f.flush()
        self.rows += len(batch)

    def abandon(self) -> None:
        try:
            os.unlink(self.partial)
        except FileNotFoundError:
            pass
        finally:
            self._f.close()

    def finish(self, meta: dict[str, str]) -> None:
        """Final metadata + the partial file's rows -> temp file -> os.replace(out). The
        partial stays open (locked) until it is removed."""
        try:
            self._f.flush()
            _rewrite_head(self.partial, self.out, meta, self.columns)
            os.unlink(self.partial)
        finally:
            self._f.close()


def _head_text(meta: dict[str, str], columns: list[str]) -> str:
    lines = ["# station-capture: 1\n"]
    for k, v in meta.items():
        if k == "station-capture":
            continue
        v = " ".join(str(v).split())  # one line, no control characters
        lines.append(f"# {k}: {v}\n")
    lines.append(",".join(columns) + "\n")
    return "".join(lines)


_COPY_BYTES = 1 << 20


def _rewrite_head(src: str, dst: str, meta: dict[str, str], columns: list[str]) -> int:
    """Copy src's data rows under a new head into dst atomically (``_copy_rows``); returns rows copied."""
    with open_input(src) as fin:
        # skip the old head: metadata lines, then the header row
        while True:
            line = fin.readline()
            if not line:
                raise InputError(src, None, "no header row: not a partial recording")
            if not line.startswith(b"#"):
                break
        start = fin.tell()
        end, size, _ = _last_line_end(fin)
    end = max(end, start)
    if size > end:
        raise InputError(src, None, "last line is cut short (use --recover)")
    return _copy_rows(src, dst, _head_text(meta, columns), start, end)


def _last_line_end(f) -> tuple[int, int, int]:
    """(the byte after the last line end of the open binary file ``f``, 0 when it has none;
    the file's size; the NUL bytes after that line end)."""
    size = os.fstat(f.fileno()).st_size
    pos = size
    nul = 0
    while pos > 0:
        start = max(0, pos - _COPY_BYTES)
        f.seek(start)
        block = f.read(pos - start)
        nl = block.rfind(b"\n")
        nul += block.count(b"\0", nl + 1)
        if nl >= 0:
            return start + nl + 1, size, nul
        pos = start
    return 0, size, nul


def _holds_lines(path: str, end: int, n: int) -> bool:
    """Whether the first ``end`` bytes of ``path`` hold ``n`` whole lines (read only as far as needed)."""
    seen = 0
    with open_input(path) as f:
        left = end
        while left > 0 and seen < n:
            block = f.read(min(left, _COPY_BYTES))
            if not block:
                break
            seen += block.count(b"\n")
            left -= len(block)
    return seen >= n


def _copy_rows(src: str, dst: str, head: str, start: int, end: int) -> int:
    """Write ``head`` then src's bytes ``start`` to ``end`` into dst atomically; returns the
    line ends copied."""
    lines = 0
    with open_input(src) as fin, atomic_open(dst, "wb") as fout:
        fout.write(head.encode("utf-8"))
        fin.seek(start)
        left = end - start
        while left > 0:
            block = fin.read(min(left, _COPY_BYTES))
            if not block:  # the file shrank since it was checked
                raise InputError(src, None, "changed while it was being recovered (is a recording still writing it?)")
            fout.write(block)
            lines += block.count(b"\n")
            left -= len(block)
    return lines


@dataclass
class Recovered:
    path: str  # the capture written
    rows: int  # the data rows it holds: every whole row of the partial file
    dropped: str = ""  # the cut last line that was left out, said as a warning ("" when none)


def recover_partial(partial: str, out: str | None = None, *, warn=None, force: bool = False) -> Recovered:
    """Finish a `<out>.partial` left by a killed recording: keep every whole row, drop a cut
    last line (``warn``: one line naming it), keep `complete: false`, add `recovered: true`;
    write `out` (default: the name without `.partial`) atomically and remove the partial file.

    The rows kept are checked by the capture reader (station.capture.check_capture_upto): a
    file with a bad row before its last line (a line that has its line end) is no cut a kill
    or a power cut made, and is refused on that line with nothing written; so is one without a
    whole row. A power cut can leave the last blocks of the file as NUL bytes with no line end
    among them: that tail is the cut last line.

    An ``out`` other than the recording's own (the partial's name without ``.partial``, which the
    recording was started to replace) that exists is refused, nothing written, unless ``force``."""
    from station.capture import check_capture_upto

    warn = warn or (lambda msg: None)
    partial = os.fspath(partial)
    if out is None:
        if not partial.endswith(PARTIAL_SUFFIX):
            raise InputError(partial, None, f"not a {PARTIAL_SUFFIX} file; give --out")
        out = partial[: -len(PARTIAL_SUFFIX)]
    if same_file(out, partial):  # written over, then removed as recovered: the recording gone
        raise InputError(out, None, "--out is the .partial file being recovered: choose another name")
    if not os.path.lexists(partial) and os.path.isfile(out):  # run twice, or after a finished recording
        raise InputError(
            partial, None, f"no such file: nothing to recover ({out} is there: recovered, or the recording finished)"
        )
    own = partial.endswith(PARTIAL_SUFFIX) and same_file(out, partial[: -len(PARTIAL_SUFFIX)])
    if not force and not own and os.path.lexists(out):
        raise InputError(
            out, None, "already exists: --recover writes no file over another (give --force to replace it)"
        )
    with open_input(partial) as f:  # open, and locked, until the partial is removed
        if not _lock(f):
            raise InputError(
                partial,
                None,
                f"a recording is writing it now: nothing to recover; stopped (Ctrl-C, SIGTERM) it finishes {out} "
                "itself",
            )
        end, size, nul = _last_line_end(f)
        try:
            checked = check_capture_upto(partial, end)  # the head, then every whole row as the reader takes it
        except InputError as exc:
            if exc.line is not None and exc.path == partial and not _holds_lines(partial, end, exc.line):
                # refused on the cut last line: the kill came before the head was written whole
                raise InputError(
                    partial, None, f"no complete data row to recover (the head is cut short on line {exc.line})"
                ) from None
            raise
        if checked.rows == 0:
            raise InputError(partial, None, "no complete data row to recover")
        meta = dict(checked.meta)
        meta["complete"] = "false"
        meta["recovered"] = "true"
        columns = checked.header + ([""] if checked.trailing_comma else [])  # the rows keep their last comma
        lines = _copy_rows(partial, out, _head_text(meta, columns), checked.data_offset, end)
        try:
            os.unlink(partial)
        except FileNotFoundError:  # another --recover removed it after writing the same capture
            pass
    dropped = ""
    if size > end:
        line = checked.header_line + lines + 1
        cut = f"{size - end} byte{'s' if size - end > 1 else ''}"
        never = f"{nul} NUL byte{'s' if nul > 1 else ''}: blocks never written, as a power cut leaves a file"
        if not nul:
            what = f"a row the recording was writing when it stopped, {cut}"
        elif nul == size - end:
            what = never
        else:
            what = f"a row cut short, then {never}; {cut}"
        dropped = f"{partial}:{line}: the last line has no line end ({what}): dropped"
        warn(dropped)
    return Recovered(out, checked.rows, dropped)


def _median_dt(batch: Batch, before: tuple[float, int] | None = None) -> float | None:
    """Median step between the batch's samples of one segment, the step from ``before`` (the
    previous batch's last t and segment) included: a device at 10 Hz gives a batch of one
    sample per 0.1 s poll, whose rate was never measured (no sample_rate_hz)."""
    t, seg = batch.t_s, batch.segment
    if before is not None:
        t, seg = np.concatenate(([before[0]], t)), np.concatenate(([before[1]], seg))
    if len(t) < 2:
        return None
    same = seg[1:] == seg[:-1]
    d = np.diff(t)[same]
    d = d[d > 0]
    return float(np.median(d)) if len(d) else None


def record(
    port: str,
    out: str,
    *,
    baud: int = 115200,
    protocol: str = "station",
    seconds: float | None = None,
    procedure: str | None = None,
    extra_meta: dict[str, str] | None = None,
    mavlink_source: str | None = None,
    mavlink_rate_hz: float | None = 200.0,
    header_timeout_s: float = 3.0,
    stop: threading.Event | None = None,
    reader: Reader | None = None,
    warn=None,
) -> RecordResult:
    """Record `port` into the capture `out` until `seconds` pass or `stop` is set (anything with
    ``wait(timeout) -> bool``: a ``threading.Event``, or from a signal handler
    ``station.commands.record.SignalFlag``, which an Event must not be).

    Returns the final metadata and the reader's statistics. Raises PortError when the
    port cannot be opened and RecordError when no sample arrived.
    """
    stop = stop or threading.Event()
    warn = warn or (lambda msg: None)
    out = os.fspath(out)
    directory = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(directory):
        raise InputError(out, None, "its folder does not exist")
    _check_extra_meta(directory, procedure, extra_meta)
    own_reader = reader is None
    if reader is None:
        reader = Reader(
            port,
            baud=baud,
            protocol=protocol,
            mavlink_source=mavlink_source,
            request_hz=mavlink_rate_hz if protocol == "mavlink" else None,
        )
        reader.start()
    started = time.monotonic()
    recorded_at = _dt.datetime.now(_dt.UTC).replace(microsecond=0)
    stream: CaptureStream | None = None
    try:
        # a flight controller asked for its stream answers after a heartbeat or two (1 Hz)
        asked = protocol == "mavlink" and mavlink_rate_hz
        header = reader.wait_header(max(header_timeout_s, 6.0) if asked else header_timeout_s)
        if header is None:
            warn(f"no header from {port} in {header_timeout_s:g} s: recording all columns, units unknown")
        columns = columns_for(header)
        meta = _start_meta(header, procedure, recorded_at, port, protocol, baud, extra_meta, warn)
        stream = CaptureStream(out, columns, meta)
        dts: list[float] = []
        last_t: tuple[float, int] | None = None  # the last row's (t, segment): steps across batches count
        stopped = "stopped"
        # host time the newest rows arrived (the reader's arrival time, not when they were taken
        # from it: rows that came during the header wait are taken after it)
        last_rows_at: float | None = None
        while True:
            if stop.wait(0.1):
                stopped = "stopped"
                break
            b = reader.drain()
            changes = list(reader.header_changes)  # registered before their samples are queued
            if b is not None and changes:
                b = b.select(b.segment < changes[0][2])
            if b is not None and len(b):
                stream.write(b)
                last_rows_at = _arrived(reader, last_rows_at)
                d = _median_dt(b, last_t)
                if d is not None:
                    dts.append(d)
                last_t = (float(b.t_s[-1]), int(b.segment[-1]))
            if changes:
                old, new, _ = changes[0]
                warn(f"device changed ({old.device_id} {old.units} -> {new.device_id} {new.units}): recording stopped")
                stopped = "device changed"
                break
            if seconds is not None and time.monotonic() - started >= seconds:
                stopped = "time"
                break
        ended_at, at_end = time.monotonic(), reader.stats()  # before stop() marks the port closed
        if own_reader:
            reader.stop()
        b = reader.drain()
        if b is not None and len(b):
            last_rows_at = min(ended_at, _arrived(reader, last_rows_at))
        if b is not None and stopped != "device changed":
            if reader.header_changes:
                b = b.select(b.segment < reader.header_changes[0][2])
            stream.write(b)
        if stream.rows == 0:
            stream.abandon()
            stream = None
            raise RecordError(
                f"{port}: no samples received in {time.monotonic() - started:.1f} s"
                + _why_no_samples(reader.stats(), protocol, baud)
            )
        stats = reader.stats()
        events = reader.events()
        final = dict(meta)
        board = getattr(reader.parser, "board_meta", dict)()  # MAVLink: firmware, uid, parameters in use
        have = {k.lower() for k in final}
        final.update({k: v for k, v in board.items() if k.lower() not in have})
        final.update(_end_meta(stats, events, stream.rows, dts, time.monotonic() - started))
        incomplete = _ending(at_end, last_rows_at, started, ended_at, dts, stopped, seconds)
        if incomplete:
            final["complete"] = "false"
            final["incomplete"] = incomplete
            final["last_data_s"] = f"{(last_rows_at or started) - started:.3f}"
            warn(f"{port}: {incomplete}: the capture is marked complete: false")
        stream.finish(final)
        return RecordResult(out, stream.rows, final, stats, events, stopped, incomplete)
    except BaseException:
        if own_reader:
            reader.stop()
        raise
    finally:
        # a partial file stays only if finishing failed after rows were written
        if stream is not None and stream.rows == 0 and os.path.exists(stream.partial):
            stream.abandon()


# what a recording writes about itself (_start_meta, _end_meta, the ending, recover_partial)
_OWN_KEYS = frozenset(
    {"station-capture", "recorded_at", "source", "protocol", "baud", "nominal_rate_hz", "samples", "gaps"}
    | {"parse_errors", "parse_errors_by_kind", "dropped", "reconnects", "restarts", "segments", "duration_s"}
    | {"complete", "incomplete", "last_data_s", "recovered"}
    # measured from the samples' times (_end_meta): a --meta value was replaced silently, and one
    # spelled in other letter case (Sample_Rate_Hz) stayed beside it: a capture the reader refuses
    | {"sample_rate_hz"}
)


def _check_extra_meta(directory: str, procedure: str | None, extra: dict[str, str] | None) -> None:
    """Refuse metadata the capture reader would refuse, before the port is opened."""
    from station.capture import iter_capture_chunks

    meta = {"procedure": procedure} if procedure else {}
    meta.update(extra or {})
    if not meta:
        return
    for k in meta:
        if not k or ":" in k or k != k.strip() or not k.isprintable():
            raise InputError(None, None, f"--meta {k!r}: not a usable key")
        if k.lower() in _OWN_KEYS or re.fullmatch(r"gap_\d+", k.lower()):
            raise InputError(None, None, f"--meta {k}: the recording writes it (what it saw of the device), not --meta")
    with scratch_file(directory, "station-record-meta", _head_text(meta, ["t"])) as tmp:
        try:
            iter_capture_chunks(tmp)
        except InputError as exc:
            raise InputError(None, None, f"--meta: {exc.message}") from None


def _start_meta(header, procedure, recorded_at, port, protocol, baud, extra, warn) -> dict[str, str]:
    meta: dict[str, str] = {}
    if procedure:
        meta["procedure"] = procedure
    meta["device"] = header.device_id if header and header.device_id else "unknown"
    known = _known_units()
    if header is not None:
        for key in SENSOR_GROUPS:
            unit = getattr(header, key)
            if not unit:
                continue
            if unit in known[key]:
                meta[key] = unit
            else:
                meta[f"device_{key}"] = unit
                warn(f"{key} {unit!r} is not a capture unit; kept as device_{key}")
        if header.rate_hz == header.rate_hz:
            meta["nominal_rate_hz"] = f"{header.rate_hz:g}"
    meta["date"] = recorded_at.date().isoformat()
    meta["recorded_at"] = recorded_at.isoformat().replace("+00:00", "Z")
    meta["source"] = port
    meta["protocol"] = protocol
    if not port.split(":", 1)[0].endswith(("socket", "loop", "rfc2217", "udp", "udpin", "udpout", "tcp", "tcpin")):
        meta["baud"] = str(baud)
    for k, v in (extra or {}).items():
        # the reader takes a key in any letter case: --meta Device=X replaces 'device', never
        # stands beside it (a head with both is refused as one key spelled twice)
        same = next((have for have in meta if have.lower() == k.lower()), k)
        if same in SENSOR_GROUPS and same in meta and meta[same] != v:
            raise InputError(
                None,
                None,
                f"--meta {k}={v}: the device says {same} {meta[same]} (its header); "
                "--meta sets a unit only for a device that does not say it",
            )
        meta[same] = v
    return meta


def _why_no_samples(stats: ReaderStats, protocol: str, baud: int) -> str:
    """What the port gave instead of samples, for the one line that says there were none."""
    if not stats.bytes:
        return ": the device sent nothing (powered, connected, streaming?)"
    kinds = ", ".join(f"{k} {v}" for k, v in stats.errors.items() if v)
    return (
        f": {stats.bytes} bytes came, no {protocol} sample among them"
        + (f" ({stats.parse_errors} bad: {kinds})" if kinds else "")
        + f"; a wrong --baud (this read at {baud}) or --protocol?"
    )


def _arrived(reader: Reader, before: float | None) -> float:
    """Host time the newest sample reached ``reader`` (now, for a reader that does not say)."""
    at = getattr(reader.stats(), "last_sample_at", math.nan)
    return time.monotonic() if math.isnan(at) else max(at, before or at)


SILENCE_S = 2.0  # no rows for this long (and 20 sample periods) at the end: the device went silent


def _ending(
    stats: ReaderStats,
    last_rows_at: float | None,
    started: float,
    ended_at: float,
    dts: list[float],
    stopped: str,
    seconds: float | None = None,
) -> str:
    """Why a recording that ran to its end is incomplete: the device was lost and never came
    back, or it is connected but sends nothing (after a reconnection: came back silent), or
    it was interrupted (SIGINT, SIGTERM) or another device came on the port before the
    ``seconds`` asked for. "" when the data ran to the end (without ``seconds`` an interrupt or a
    device change is the end)."""
    if stopped == "device changed":
        if seconds is not None and ended_at - started < seconds:
            return f"device changed {ended_at - started:.2f} s into the {seconds:g} s asked for"
        return ""
    last = last_rows_at if last_rows_at is not None else started
    quiet_s = ended_at - last
    period = float(np.median(dts)) if dts else 0.0
    at = f"{last - started:.2f} s into the {ended_at - started:.2f} s recording"
    if not stats.connected:
        return f"device lost {at} and never came back"
    if quiet_s > max(SILENCE_S, 20.0 * period):
        if stats.reconnects:
            return f"device came back silent: no data since {at}"
        return f"device went silent: no data since {at}"
    if stopped == "stopped" and seconds is not None and ended_at - started < seconds:
        return f"interrupted {ended_at - started:.2f} s into the {seconds:g} s asked for"
    return ""


def _end_meta(
    stats: ReaderStats, events: list[GapEvent], rows: int, dts: list[float], duration_s: float
) -> dict[str, str]:
    m: dict[str, str] = {}
    if dts:
        m["sample_rate_hz"] = f"{1.0 / float(np.median(dts)):.6g}"
    m["samples"] = str(rows)
    m["gaps"] = str(stats.gaps)
    m["parse_errors"] = str(stats.parse_errors)
    m["parse_errors_by_kind"] = " ".join(f"{k}={v}" for k, v in stats.errors.items())
    m["dropped"] = str(stats.dropped)
    m["reconnects"] = str(stats.reconnects)
    m["restarts"] = str(stats.restarts)
    m["segments"] = str(stats.segment + 1)
    for k, ev in enumerate(events, 1):
        missed = "unknown" if ev.missed < 0 else str(ev.missed)
        before = "start" if math.isnan(ev.t_s) else f"{ev.t_s:.6f}"
        m[f"gap_{k}"] = (
            f"segment {ev.segment} {ev.reason}: t {before} -> {ev.t_resume_s:.6f} s, "
            f"down {ev.down_s:.3f} s, missed {missed}"
        )
    m["duration_s"] = f"{duration_s:.3f}"
    m["complete"] = "true"
    return m
