"""Live sample sources for the TUI and `station demo`: one small interface over the
built-in simulated device (in-process) and a serial port (station.device.reader).

A source is started once, then ``drain()`` is called from a worker thread (never the UI
thread); it returns every sample since the last call as a :class:`Samples` (or None)
and never blocks for long. ``place(name)`` asks the bench to move to a named position:
the simulated device moves; a serial device gets ``$STC,ORIENT,<name>`` (which the
simulated device on a pty understands; a real device ignores it).
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

import numpy as np

from solvers.simulate import NOMINAL_ACCEL_SCALE_V_PER_MPS2, NOMINAL_ACCEL_ZERO_V
from station.procedures import registry


def parse_site(text: str) -> dict:
    """``"LAT, LON[, ALT_M]"`` (WGS-84 degrees, metres) -> ``{"latitude_deg", "longitude_deg",
    "altitude_m"}`` (altitude 0 when left out). Raises ValueError with one line on bad input."""
    parts = [p.strip() for p in str(text).replace(";", ",").split(",")]
    if len(parts) not in (2, 3) or not all(parts):
        raise ValueError(f"site {text!r}: expected LAT,LON or LAT,LON,ALT_M (degrees, metres)")
    try:
        lat, lon, alt = (float(p) for p in (parts + ["0"])[:3])
    except ValueError:
        raise ValueError(f"site {text!r}: LAT, LON and ALT_M must be numbers") from None
    if not (math.isfinite(lat) and -90.0 <= lat <= 90.0):
        raise ValueError(f"site {text!r}: latitude must be within -90..90 degrees")
    if not (math.isfinite(lon) and -180.0 <= lon <= 360.0):
        raise ValueError(f"site {text!r}: longitude must be within -180..360 degrees")
    if not (math.isfinite(alt) and -1000.0 <= alt <= 100000.0):
        raise ValueError(f"site {text!r}: altitude must be within -1000..100000 m")
    return {"latitude_deg": lat, "longitude_deg": lon, "altitude_m": alt}


def site_text(site: dict) -> str:
    """The inverse of :func:`parse_site`: ``"39.98, 116.35, 50"``."""
    return f"{site['latitude_deg']:g}, {site['longitude_deg']:g}, {site.get('altitude_m', 0.0):g}"


@dataclass
class Samples:
    """A batch: t_s (n,) device time [s], accel, gyro, mag (n, 3) raw, temp_c (n,);
    ``extra``: any other columns by their capture names (the reference IMU's ``ref_gx``..,
    the LDV's ``vl1``.., ``vx``.., ``wx``..), each (n,)."""

    t_s: np.ndarray
    accel: np.ndarray
    gyro: np.ndarray
    temp_c: np.ndarray
    mag: np.ndarray | None = None
    extra: dict | None = None

    def __len__(self) -> int:
        return len(self.t_s)


@dataclass
class SourceStats:
    samples: int = 0
    rate_hz: float = math.nan
    parse_errors: int = 0
    dropped: int = 0
    connected: bool = False
    last_error: str = ""


class SimSource:
    """The built-in simulated bench device (``solvers.simulate.LiveImu``), paced by a clock.

    speed: device seconds per wall second (the tests run the bench faster than life).
    clock: a monotonic clock in seconds (injectable for deterministic tests).
    """

    kind = "sim"
    label = "built-in simulated device"
    # the simulated triad's data-sheet zero [V] and sensitivity [V per m/s²]
    nominal = (NOMINAL_ACCEL_ZERO_V, NOMINAL_ACCEL_SCALE_V_PER_MPS2)

    def __init__(
        self,
        *,
        seed: int = 0,
        rate_hz: float = 100.0,
        speed: float = 1.0,
        clock=time.monotonic,
        max_batch_s: float = 1.0,
        procedure: str = registry.DEFAULT,
    ):
        # a procedure's guide module makes its device (a guided run: its procedure's)
        entry, reference = registry.device_of(procedure)
        guide = entry.guide() if entry is not None else None
        if guide is None:
            from solvers.simulate import SimulationError

            raise SimulationError(f"unknown procedure {procedure!r}")
        self.imu = guide.live_device(seed=seed, rate_hz=rate_hz, reference=reference)
        self.procedure = procedure
        self.positions = list(self.imu.positions)
        self.rate_hz = float(self.imu.rate_hz)
        self.speed = float(speed)
        self.clock = clock
        self.max_batch_s = max_batch_s
        self.device_id = self.imu.device_id
        self.units = dict(self.imu.units)
        self.site = dict(self.imu.site)
        self._lock = threading.Lock()
        self._t0: float | None = None
        self._produced = 0
        self._stats = SourceStats()
        self._rate_window: list[tuple[float, int]] = []

    @staticmethod
    def device_id_for(seed: int, procedure: str = registry.DEFAULT) -> str:
        """The id the simulated device reports (its guide's live_device), without making it:
        the registry's ``sim_device`` prefix and the seed."""
        entry, _ = registry.device_of(procedure)
        return f"{entry.sim_device}-{seed:04d}" if entry is not None else f"SIM-{procedure.upper()[:3]}-{seed:04d}"

    def start(self) -> SimSource:
        self._t0 = self.clock()
        self._stats.connected = True
        return self

    def stop(self) -> None:
        self._stats.connected = False

    def drain(self) -> Samples | None:
        if self._t0 is None:
            return None
        now = self.clock()
        due = int((now - self._t0) * self.speed * self.rate_hz)
        n = due - self._produced
        if n <= 0:
            return None
        cap = int(self.max_batch_s * self.rate_hz * max(self.speed, 1.0))
        if n > cap:  # a stalled consumer: the device ran on, the samples are lost
            self._stats.dropped += n - cap
            self._produced += n - cap
            n = cap
        with self._lock:
            d = self.imu.read(n)
        self._produced += n
        self._stats.samples += n
        w = self._rate_window
        w.append((now, self._stats.samples))
        while len(w) > 2 and now - w[0][0] > 2.0:
            w.pop(0)
        if len(w) >= 2 and w[-1][0] > w[0][0]:
            self._stats.rate_hz = (w[-1][1] - w[0][1]) / (w[-1][0] - w[0][0]) / max(self.speed, 1e-9)
        nan = np.full((n, 3), np.nan)

        def trio(a, b, c):
            return np.column_stack([d[a], d[b], d[c]]) if a in d else nan

        std = {"t_s", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp_c"}
        extra = {k: v for k, v in d.items() if k not in std}
        gyro = trio("gx", "gy", "gz") if "gx" in d else trio("wx", "wy", "wz")  # the vehicle's body rates
        return Samples(d["t_s"], trio("ax", "ay", "az"), gyro, d["temp_c"], trio("mx", "my", "mz"), extra or None)

    def place(self, name: str) -> None:
        """The operator's hand on the simulated bench: a position, a centrifuge setting
        ``k@ω``, ``sweep`` / ``table`` / ``still``, or a vehicle command (the imu's
        ``set_orientation``)."""
        with self._lock:
            self.imu.set_orientation(name)

    def bench(self, what: str):
        """A property of the simulated bench (``driving``, ``turning``, ...) or None."""
        with self._lock:
            return getattr(self.imu, what, None)

    def stats(self) -> SourceStats:
        return SourceStats(**vars(self._stats))


class SerialSource:
    """A device on a serial port (or pyserial URL), read by ``station.device.reader.Reader``."""

    kind = "serial"
    nominal = None

    def __init__(self, port: str, *, protocol: str = "station", baud: int = 115200, header_timeout_s: float = 3.0):
        from station.device.reader import Reader

        self.port = port
        self.protocol = protocol
        self.label = f"{port} ({protocol})"
        # a flight controller is asked for its IMU stream, uid and parameters (station.device.mavlink.BoardLink)
        self.reader = Reader(port, baud=baud, protocol=protocol, request_hz=200.0 if protocol == "mavlink" else None)
        self.header_timeout_s = max(header_timeout_s, 6.0) if protocol == "mavlink" else header_timeout_s
        self.device_id = ""
        self.units = {"accel_unit": "", "gyro_unit": "", "mag_unit": ""}
        self.rate_hz = math.nan
        self.site: dict = {}

    def start(self) -> SerialSource:
        """Open the port (raises station.device.reader.PortError) and wait for the header."""
        self.reader.start()
        h = self.reader.wait_header(self.header_timeout_s)
        if h is not None:
            self.device_id = h.device_id
            self.units = dict(h.units)
            self.rate_hz = float(h.rate_hz)
        if not math.isfinite(self.rate_hz):
            time.sleep(0.5)
            self.rate_hz = self.reader.stats().rate_hz
        if self.device_id.startswith("SIM-") and self.units.get("accel_unit") == "V":
            self.nominal = SimSource.nominal  # `station sim-device`: the same simulated triad
        return self

    def stop(self) -> None:
        self.reader.stop()

    def drain(self) -> Samples | None:
        b = self.reader.drain()
        if b is None or len(b) == 0:
            return None
        c = b.columns
        return Samples(
            b.t_s,
            np.column_stack([c["ax"], c["ay"], c["az"]]),
            np.column_stack([c["gx"], c["gy"], c["gz"]]),
            c["temp_c"],
            np.column_stack([c["mx"], c["my"], c["mz"]]),
            dict(b.extra) or None,  # protocol 2's extra channels: ref_gx.., vl1.., vx..
        )

    def place(self, name: str) -> None:
        self.reader.command("ORIENT", name)

    # what an acknowledged $STC,ORIENT,<name> leaves the simulated bench doing: (property, value)
    _BENCH = {
        "sweep": ("driving", "sweep"),
        "table": ("driving", "table"),
        "still": ("driving", None),
        "drive": ("driving", True),
        "stop": ("driving", False),
        "turns": ("turning", True),
        "straight": ("turning", False),
    }

    def bench(self, what: str):
        """The simulated bench's state (``driving``, ``turning``) as the device acknowledged
        it (``$STA,ORIENT,OK,<name>``), as ``SimSource.bench`` reads it in-process; None for
        a device that is not `station sim-device`."""
        if not self.device_id.startswith("SIM-"):
            return None
        h = self.reader.header
        vehicle = h is not None and "vl1" in h.channels
        state = {"driving": False, "turning": False} if vehicle else {"driving": None}
        for ack in list(self.reader.acks):
            if ack.verb != "ORIENT" or not ack.ok:
                continue
            key, value = self._BENCH.get(ack.text, ("driving", None))  # a position ends a drive
            state[key] = value
        return state.get(what)

    def stats(self) -> SourceStats:
        s = self.reader.stats()
        return SourceStats(
            samples=s.samples,
            rate_hz=s.rate_hz,
            parse_errors=s.parse_errors,
            dropped=s.dropped,
            connected=s.connected,
            last_error=s.last_error,
        )
