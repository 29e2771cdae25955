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


class CentrifugeImu:
    """A simulated P2 bench (``station sim``'s centrifuge): the triad of
    ``solvers.simulate.simulate_centrifuge(seed)`` (its S, b, D, outputs in g) mounted in
    one of ``solvers.simulate.centrifuge_orientations`` and spun at ω on radius R.

    ``set_orientation("k@ω")`` asks for orientation k (1-based) at ω rad/s; the bench then
    changes over like a real one: a speed change ramps for ``ramp_s``; a new orientation
    first spins down, is handled (remounted) for ``handle_s``, then spins up. The speed it
    holds is the set point within its controller's error (1e-8 relative, 1σ, a new one each
    time it is set: an encoder-locked drive; P2 needs it, since |f| moves twice the relative
    speed error and at 36 g a 1e-6 error is already 7e-5 g, ten times a row's averaged
    noise); the gyro on the table (1e-3 rad/s noise per sample) measures it. Specific force
    in the table frame (radial out, tangential, up) is ``(−ω²R/g, 0, 1)`` g (the simulator's
    convention); the forward model is ``solvers.models.accel.forward``. The gyro reads the
    table's rate, ``(0, 0, ω)`` in the table frame, in rad/s."""

    def __init__(
        self,
        *,
        seed: int = 0,
        rate_hz: float = 100.0,
        radius_m: float = 1.0,
        g_mps2: float = 9.8,
        noise_g: float = 1e-4,
        ramp_s: float = 2.0,
        handle_s: float = 3.0,
    ):
        from solvers.simulate import centrifuge_orientations, simulate_centrifuge

        sim = simulate_centrifuge(seed, radius_m=radius_m, g_mps2=g_mps2)
        self.params = {k: np.asarray(sim.truth[k], float) for k in ("S", "b", "D")}
        self.orients = centrifuge_orientations(20)
        self.rate_hz, self.radius_m, self.g_mps2 = float(rate_hz), float(radius_m), float(g_mps2)
        self.noise_g, self.ramp_s, self.handle_s = noise_g, ramp_s, handle_s
        self.speed_error = 1e-8
        self.rng = np.random.default_rng(seed + 1)
        self.device_id = f"SIM-CFG-{seed:04d}"
        self.units = {"accel_unit": "g", "gyro_unit": "rad/s"}
        self.site: dict = {}
        self.positions = [f"{k}@0" for k in range(1, 21)]
        self._i = 0  # samples produced
        self._plan = [(-math.inf, 1, 0.0, 1, 0.0, "steady")]  # (t0, k0, w0, k1, w1, kind)
        self.k, self.w = 1, 0.0

    def truth(self) -> dict:
        return {k: v.tolist() for k, v in self.params.items()}

    def set_orientation(self, name: str) -> None:
        k_s, _, w_s = str(name).partition("@")
        k, w = int(k_s), float(w_s or 0.0)
        if not 1 <= k <= len(self.orients) or not (math.isfinite(w) and w >= 0):
            raise ValueError(f"unknown centrifuge setting {name!r}: 'k@omega', k in 1..{len(self.orients)}")
        t = self._i / self.rate_hz
        k0, w0 = (float(x[0]) for x in self._state(t)[:2])
        k0 = int(k0)
        w = w * (1.0 + self.speed_error * self.rng.normal()) if w > 0 else 0.0
        if k == k0:
            self._plan = [(t, k0, w0, k, w, "ramp")]
        else:
            t1, t2 = t + self.ramp_s, t + 2 * self.ramp_s + self.handle_s
            self._plan = [
                (t, k0, w0, k0, 0.0, "ramp"),
                (t1, k, 0.0, k, 0.0, "handle"),
                (t1 + self.handle_s, k, 0.0, k, w, "ramp"),
                (t2, k, w, k, w, "steady"),
            ]
        self.k, self.w = k, w

    def _state(self, t):
        """(orientation, ω, handled) at device times t (arrays)."""
        t = np.atleast_1d(np.asarray(t, float))
        k = np.full(len(t), self._plan[0][3], dtype=int)
        w = np.full(len(t), self._plan[0][4], dtype=float)
        handled = np.zeros(len(t), dtype=bool)
        for t0, k0, w0, k1, w1, kind in self._plan:  # noqa: B007
            on = t >= t0
            k[on] = k1
            if kind == "ramp":
                x = np.clip((t[on] - t0) / self.ramp_s, 0.0, 1.0)
                w[on] = w0 + (w1 - w0) * x
            else:
                w[on] = w1
            handled[on] = kind == "handle"
        return k, w, handled

    def read(self, n: int) -> dict:
        from solvers.models import accel as accel_model

        t = (self._i + np.arange(n)) / self.rate_hz
        self._i += n
        k, w, handled = self._state(t)
        f = np.empty((n, 3))
        g = np.empty((n, 3))
        for kk in np.unique(k):
            sel = k == kk
            C_t_b = self.orients[kk - 1]
            ws = w[sel]
            f_t = np.column_stack([-ws * ws * self.radius_m / self.g_mps2, np.zeros_like(ws), np.ones_like(ws)])
            f[sel] = f_t @ C_t_b  # rows of C_t_bᵀ f_t
            g[sel] = np.column_stack([np.zeros_like(ws), np.zeros_like(ws), ws]) @ C_t_b
        shake = np.where(handled[:, None], self.rng.normal(scale=0.3, size=(n, 3)), 0.0)
        y = accel_model.forward(f + shake, self.params) + self.rng.normal(scale=self.noise_g, size=(n, 3))
        g = g + self.rng.normal(scale=1e-3, size=(n, 3))
        nan = np.full(n, np.nan)
        return {
            "t_s": t,
            "ax": y[:, 0],
            "ay": y[:, 1],
            "az": y[:, 2],
            "gx": g[:, 0],
            "gy": g[:, 1],
            "gz": g[:, 2],
            "mx": nan,
            "my": nan,
            "mz": nan,
            "temp_c": np.full(n, 25.0),
        }


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
        procedure: str = "accel-tabletop",
    ):
        from solvers.simulate import LiveImu

        if procedure == "accel-centrifuge":
            self.imu = CentrifugeImu(seed=seed, rate_hz=rate_hz)
        elif procedure == "ldv":  # the vehicle with INS/DGPS and the LDV, 10 Hz
            from solvers.simulate import LiveVehicle

            rate_hz = 10.0
            self.imu = LiveVehicle(seed=seed, rate_hz=rate_hz)
        else:  # the gyro noise (Allan) run holds the unit still like P4; mode A adds the reference
            self.imu = LiveImu(
                procedure="gyro-drift" if procedure in ("gyro-noise", "gyro-reference") else procedure,
                seed=seed,
                rate_hz=rate_hz,
                hold_s=1e9,
                reference=procedure == "gyro-reference",
            )
        self.procedure = procedure
        self.positions = list(self.imu.positions)
        self.rate_hz = float(rate_hz)
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
    def device_id_for(seed: int, procedure: str = "accel-tabletop") -> str:
        """The id the simulated device reports (as solvers.simulate.LiveImu names it)."""
        if procedure == "accel-centrifuge":
            return f"SIM-CFG-{seed:04d}"  # CentrifugeImu, simulate_centrifuge's triad
        if procedure in ("gyro-noise", "gyro-reference"):
            procedure = "gyro-drift"
        return f"SIM-{procedure.upper()[:3]}-{seed:04d}"

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
        )

    def place(self, name: str) -> None:
        self.reader.command("ORIENT", name)

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
