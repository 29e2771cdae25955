"""The simulated bench device on a real pseudo-terminal.

`SimDevice(imu)` opens a pty (slave in raw mode), and `run()` streams the simulator's
samples (`solvers.simulate.LiveImu`: the project's forward models, nothing invented
here) in real time, paced by the monotonic clock, in the station protocol or as
MAVLink 2. It reads host commands on the same port (docs/protocol.md):

    $STC,HDR               send the header now
    $STC,ORIENT,<name>     move smoothly to a position (e.g. x_up; s1..s12; level), or
                           sweep / table / still (solvers.simulate.LiveImu.set_orientation)
    $STC,TEMP,<c>          set the temperature set point, degC
    $STC,AUTO,ON|OFF|<procedure>   scripted operator: visit the positions in order
    $STC,RATE,<hz>         change the sample rate

answering `$STA,<verb>,OK` or `$STA,<verb>,ERR,<why>` (station protocol only).

Like a UART, the device never waits for the host: output that the pty cannot take is
queued up to `max_pending_s` of data; beyond that, everything waiting (queued here and
unread in the pty) is discarded and streaming goes on with fresh data. Sequence numbers
keep counting, so a reader that was connected counts the loss as a gap, and one that
opens the port later starts on a contiguous stream.
"""

from __future__ import annotations

import collections
import errno
import fcntl
import math
import os
import select
import termios
import threading
import time
import tty
from dataclasses import dataclass

import numpy as np

from solvers.models import accel as accel_model

# The MAVLink flight-controller stand-in converts the simulated analogue accelerometer
# (V) to m/s^2 with the device family's nominal front end (solvers/simulate.py
# `nominal_tabletop_device`: ~0.0855 V per m/s^2, ~1.65 V at zero), through the accel
# model's own inverse: a factory scaling that leaves the unit's errors to calibrate.
from solvers.simulate import NOMINAL_ACCEL_PARAMS as NOMINAL_ACCEL_V  # noqa: E402
from solvers.units import si_factor
from station.device.protocol import (
    SENSOR_FIELDS,
    Command,
    Header,
    StationParser,
    ack_sentence,
    data_sentences,
    header_sentence,
)

# $STC,TEMP set points [degC]: above absolute zero, within a thermal chamber's reach (-70..180 degC
# for common test chambers, with room to spare)
TEMP_MIN_C, TEMP_MAX_C = -100.0, 300.0
# what each command takes after its verb (docs/protocol.md section 5), said when it comes without
# it; no ',', '$' or '*', which an answer's text cannot carry
_TAKES = {
    "ORIENT": "a position or setting name (x_up; s1; level; sweep; still; 3@12.5; drive ...)",
    "TEMP": f"a set point in degC from {TEMP_MIN_C:g} to {TEMP_MAX_C:g}",
    "AUTO": "a procedure name or ON or OFF",
    "RATE": "a sample rate in Hz from 0.1 to 100000",
}


@dataclass
class SimStats:
    samples: int = 0
    sent_bytes: int = 0
    dropped: int = 0  # samples dropped because the host did not read
    commands: int = 0
    behind_s: float = 0.0  # worst lateness of a sample behind its real-time due moment


class SimDevice:
    """A simulated device streaming `imu` on a pseudo-terminal."""

    def __init__(
        self,
        imu,
        *,
        protocol: str = "station",
        header_every_s: float = 1.0,
        max_pending_s: float = 0.5,
        write_every_s: float = 0.002,
        mavlink_scaled: bool = False,
        digits: int = 7,
        speed: float = 1.0,
    ) -> None:
        """speed: device seconds per wall second (1: real time; tests fast-forward a bench
        whose procedure takes minutes). The device clock in every sentence is its own."""
        if protocol not in ("station", "mavlink"):
            raise ValueError(f"unknown protocol {protocol!r}")
        self.imu = imu
        self.protocol = protocol
        self.header_every_s = header_every_s
        self.max_pending_s = max_pending_s
        self.write_every_s = write_every_s
        self.digits = digits
        self.speed = float(speed)
        # outputs beyond the IMU's, sent as protocol-2 extra channels (the reference IMU,
        # the LDV's beams and reference velocity)
        self.channels = tuple(getattr(imu, "channels", ()))
        self.stats = SimStats()
        self.master: int | None = None
        self.slave: int | None = None
        self.path: str | None = None
        self._pending: collections.deque[tuple[bytes, int]] = collections.deque()
        self._pending_bytes = 0
        self._head_written = 0  # bytes of the head chunk already written
        self._parser = StationParser()
        self._seq = 0
        self._encoded_bytes = 0
        self._encoded_samples = 0
        self._mav = None
        if protocol == "mavlink":
            from station.device.mavlink import MavlinkEncoder

            self._mav = MavlinkEncoder(scaled_too=mavlink_scaled)
            self._to_si = (
                si_factor("gyro", imu.units["gyro_unit"]),
                si_factor("mag", imu.units["mag_unit"]),
            )
            if None in self._to_si:
                raise ValueError(f"cannot express {imu.units} in MAVLink units")

    # ------------------------------------------------------------ pty

    def open(self) -> str:
        """Open the pseudo-terminal; return the slave's path (e.g. /dev/pts/3)."""
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        flags = fcntl.fcntl(self.master, fcntl.F_GETFL)
        fcntl.fcntl(self.master, fcntl.F_SETFL, flags | os.O_NONBLOCK)
        self.path = os.ttyname(self.slave)
        return self.path

    def close(self) -> None:
        for fd in (self.master, self.slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self.master = self.slave = None

    def __enter__(self) -> SimDevice:
        if self.master is None:
            self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------ encoding

    def header(self) -> Header:
        u = self.imu.units
        return Header(
            self.imu.device_id,
            u.get("accel_unit", ""),
            u.get("gyro_unit", ""),
            u.get("mag_unit", ""),
            self.imu.rate_hz,
            channels=self.channels,
        )

    def _encode(self, d: dict[str, np.ndarray]) -> bytes:
        n = len(d["t_s"])
        t_us = np.rint(d["t_s"] * 1e6).astype(np.int64)
        if self._mav is None:
            nan = np.full(n, np.nan)
            if "gx" not in d and "wx" in d:  # the vehicle's body rates are its gyro
                d = dict(d, gx=d["wx"], gy=d["wy"], gz=d["wz"])
            values = np.column_stack([d.get(k, nan) for k in SENSOR_FIELDS + self.channels])
            out = data_sentences(self._seq, t_us, values, self.digits)
            self._seq += n
            return out
        acc_v = np.column_stack([d["ax"], d["ay"], d["az"]])
        acc = (
            accel_model.inverse(acc_v, NOMINAL_ACCEL_V)
            if self.imu.units["accel_unit"] == "V"
            else (acc_v * si_factor("accel", self.imu.units["accel_unit"]))
        )
        kg, km = self._to_si
        gyr = np.column_stack([d["gx"], d["gy"], d["gz"]]) * kg
        mag = np.column_stack([d["mx"], d["my"], d["mz"]]) * (km / 1e5)  # nT -> gauss
        return b"".join(self._mav.imu(int(t_us[i]), acc[i], gyr[i], mag[i], float(d["temp_c"][i])) for i in range(n))

    # ------------------------------------------------------------ output queue

    def _queue(self, data: bytes, samples: int) -> None:
        self._pending.append((data, samples))
        self._pending_bytes += len(data)
        limit = max(4096, int(self.max_pending_s * self._bytes_per_s()))
        if self._pending_bytes > limit:
            # Nobody reads (or the host stalled): like a UART sending into the void,
            # discard what waits, in the pty and here, and go on with fresh data.
            termios.tcflush(self.slave, termios.TCIFLUSH)
            self.stats.dropped += sum(k for _, k in self._pending) - samples
            self._pending.clear()
            self._pending.append((data, samples))
            self._pending_bytes = len(data)
            self._head_written = 0

    def _bytes_per_s(self) -> float:
        per = self._encoded_bytes / self._encoded_samples if self._encoded_samples else 120.0
        return per * self.imu.rate_hz * self.speed

    def _flush(self) -> None:
        while self._pending:
            chunk, k = self._pending[0]
            view = memoryview(chunk)[self._head_written :]
            try:
                n = os.write(self.master, view)
            except BlockingIOError:
                return
            except OSError as exc:
                if exc.errno in (errno.EAGAIN, errno.EIO):
                    return
                raise
            self.stats.sent_bytes += n
            if n < len(view):
                self._head_written += n
                return
            self._pending.popleft()
            self._pending_bytes -= len(chunk)
            self._head_written = 0

    # ------------------------------------------------------------ commands

    def _handle(self, cmd: Command) -> tuple[bool, str]:
        imu = self.imu
        v, a = cmd.verb, cmd.args
        if v in _TAKES and not a:  # a known command without its argument is no unknown command
            return False, f"{v} takes {_TAKES[v]}"
        try:
            if v == "HDR":
                self._queue(self._header_bytes(), 0)
                return True, ""
            if v == "ORIENT" and a:
                imu.set_orientation(a[0])
                return True, a[0]
            if v in ("TEMP", "AUTO") and not hasattr(imu, "set_auto"):
                return False, f"this device ({imu.device_id}) has no {v.lower()} control"
            if v == "TEMP" and a:
                try:
                    t = float(a[0])
                except ValueError:
                    t = math.nan
                # above absolute zero, within what a thermal chamber reaches: beyond, the unit would stream
                # temperatures (1e308) the station's own readers refuse
                if not (TEMP_MIN_C <= t <= TEMP_MAX_C):
                    return False, f"temperature must be a number of degC from {TEMP_MIN_C:g} to {TEMP_MAX_C:g}"
                imu.set_temperature(t)
                return True, a[0]
            if v == "AUTO" and a:
                arg = a[0]
                if arg.upper() == "OFF":
                    imu.set_auto(False)
                    return True, "OFF"
                if arg.upper() == "ON" or arg == imu.procedure:
                    imu.set_auto(True)
                    return True, ",".join(imu.positions)
                return False, f"this device simulates {imu.procedure}"
            if v == "RATE" and a:
                try:
                    hz = float(a[0])
                except ValueError:
                    hz = math.nan  # said below, as a rate out of range
                if not (0.1 <= hz <= 100_000):
                    return False, "rate must be 0.1..100000 Hz"
                self._rebase_rate(hz)
                return True, a[0]
        except (ValueError, KeyError) as exc:  # SimulationError is a ValueError
            return False, str(exc).splitlines()[0][:200]  # the answer stays within a sentence's 256 bytes
        return False, f"unknown command {v}"

    def _header_bytes(self) -> bytes:
        if self._mav is not None:
            return self._mav.heartbeat()
        return header_sentence(self.header())

    def _rebase_rate(self, hz: float) -> None:
        now = time.monotonic()
        self._t0 = now
        self._sent_at_t0 = self.stats.samples
        self.imu.rate_hz = float(hz)

    def _read_commands(self) -> None:
        try:
            data = os.read(self.master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return
        for ev in self._parser.feed(data):
            if isinstance(ev, Command):
                self.stats.commands += 1
                ok, text = self._handle(ev)
                if self._mav is None and ev.verb != "HDR":
                    self._queue(ack_sentence(ev.verb, ok, text), 0)

    # ------------------------------------------------------------ main loop

    def run(self, stop: threading.Event, duration_s: float | None = None) -> SimStats:
        """Stream until `stop` is set (or `duration_s` passes)."""
        if self.master is None:
            self.open()
        self._t0 = time.monotonic()
        self._sent_at_t0 = 0
        start = self._t0
        next_header = self._t0
        while not stop.is_set():
            now = time.monotonic()
            if duration_s is not None and now - start >= duration_s:
                break
            if now >= next_header:
                self._queue(self._header_bytes(), 0)
                next_header += self.header_every_s
            rate = self.imu.rate_hz * self.speed  # samples per wall second
            due = int((now - self._t0) * rate) - (self.stats.samples - self._sent_at_t0)
            if due > 0:
                n = min(due, max(1, int(rate * 0.05)))  # at most 50 ms per step
                self.stats.behind_s = max(self.stats.behind_s, (due - 1) / rate)  # oldest due sample's lateness
                data = self._encode(self.imu.read(n))
                self._encoded_bytes += len(data)
                self._encoded_samples += n
                self._queue(data, n)
                self.stats.samples += n
                self._flush()
                if due > n:
                    continue
            self._flush()
            next_due = self._t0 + (self.stats.samples - self._sent_at_t0 + max(1, rate * self.write_every_s)) / rate
            wait = max(0.0, min(next_due, next_header) - time.monotonic())
            wlist = [self.master] if self._pending else []
            try:
                r, w, _ = select.select([self.master], wlist, [], wait)
            except InterruptedError:
                continue
            if r:
                self._read_commands()
        self._flush()
        return self.stats
