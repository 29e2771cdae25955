"""The guided P4 (gyro drift, static base, mode B) step as a UI-free state machine:
place the unit level at a known heading, keep it still, record ``duration_s`` (P4 asks
for at least 3 minutes); moving restarts the recording.

Phases: ``noise`` (initial rest for the stillness detector), ``place`` (waiting for
stillness), ``settle`` (still, ``settle_s`` before recording), ``average`` (recording,
with a countdown; the name matches the P1 guide so the same widgets draw it), ``done``,
``aborted``. Times are the samples' own ``t_s``. The recording becomes a time-series
capture with ``gyro_mode: static``, ``latitude_deg``, ``heading_deg`` and ``frame``.
"""
from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass

import numpy as np

from solvers.stillness import StillnessTracker


@dataclass
class HoldConfig:
    """duration_s: recording length [s] (P4: >= 180). settle_s: still this long first [s].
    heading_deg: heading of the unit's forward axis from north [deg]. frame: the device's
    axes in words for the capture (e.g. ``x forward, y left, z up``)."""

    duration_s: float = 180.0
    settle_s: float = 2.0
    init_rest_s: float = 2.0
    window_s: float = 0.5
    heading_deg: float = 0.0
    frame: str = ""

    def __post_init__(self) -> None:
        for name in ("duration_s", "init_rest_s", "window_s"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {getattr(self, name)!r}")
        if not (math.isfinite(float(self.settle_s)) and self.settle_s >= 0):
            raise ValueError(f"settle_s must be >= 0, got {self.settle_s!r}")


@dataclass(frozen=True)
class HoldStatus:
    phase: str
    calibrating: bool
    is_still: bool
    still_for_s: float
    level: float
    settle_left_s: float
    countdown_s: float
    progress: float
    gyro_mean: tuple[float, float, float]  # running mean of the recording (raw gyro unit)
    n_samples: int
    temp_c: float
    t_s: float
    message: str


class HoldGuide:
    procedure = "gyro-drift"

    def __init__(self, *, sample_rate_hz: float, units: dict, device_id: str = "", site: dict | None = None,
                 config: HoldConfig | None = None):
        self.config = config or HoldConfig()
        self.sample_rate_hz = float(sample_rate_hz)
        self.units = dict(units)
        self.device_id = device_id
        self.site = dict(site or {})
        self.started = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        c = self.config
        init = max(c.init_rest_s, (2 * int(round(c.window_s * self.sample_rate_hz / 2)) + 3) / self.sample_rate_hz)
        self.tracker = StillnessTracker(self.sample_rate_hz, init_rest_s=init, window_s=c.window_s,
                                        min_duration_s=0.0, margin_s=0.0, nan_policy="omit")
        self.phase = "noise"
        self._events: list[tuple[str, str]] = []
        self._message = "Place the unit level, forward axis at the set heading; keep it still"
        self._last = None
        self._reset()

    def _reset(self) -> None:
        self._chunks: list[tuple[np.ndarray, ...]] = []
        self._n = 0
        self._sum = np.zeros(3)
        self._t0 = math.nan
        self._t1 = math.nan

    def take_events(self) -> list[tuple[str, str]]:
        ev, self._events = self._events, []
        return ev

    def update(self, t_s, accel, gyro, temp_c=None) -> HoldStatus:
        t_s = np.asarray(t_s, float)
        if len(t_s) == 0 or self.phase in ("done", "aborted"):
            return self.status()
        accel = np.asarray(accel, float).reshape(-1, 3)
        gyro = np.asarray(gyro, float).reshape(-1, 3)
        temp = np.full(len(t_s), np.nan) if temp_c is None else np.asarray(temp_c, float)
        step = max(1, int(self.sample_rate_hz * 0.1))
        st = None
        for a in range(0, len(t_s), step):
            sl = slice(a, a + step)
            st = self.tracker.update(t_s[sl], accel[sl], gyro[sl])
            self._advance(st, t_s[sl], accel[sl], gyro[sl], temp[sl])
            if self.phase == "done":
                break
        self._last = (st, float(np.nanmean(temp[-step:])) if np.isfinite(temp[-step:]).any() else math.nan,
                      float(t_s[-1]))
        return self.status()

    def _advance(self, st, t, a, g, temp) -> None:
        c = self.config
        if st.calibrating:
            self.phase = "noise"
            self._message = "Hold still: measuring the sensor noise"
            return
        if self.phase == "average":
            if not st.is_still:
                self._events.append(("restarted", "moved during the recording"))
                self._message = "The unit moved: recording starts again when it is still"
                self._reset()
                self.phase = "place"
                return
            self._add(t, a, g, temp)
            if self._t1 - self._t0 >= c.duration_s:
                self.phase = "done"
                self._message = f"Recorded {self._t1 - self._t0:.0f} s"
                self._events.append(("done", ""))
            return
        if st.is_still and st.still_for_s >= c.settle_s:
            self.phase = "average"
            self._reset()
            self._t0 = float(t[0])
            self._message = "Recording: keep the unit still"
            self._add(t, a, g, temp)
        elif st.is_still:
            self.phase = "settle"
            self._message = "Still: recording starts shortly"
        else:
            self.phase = "place"
            self._message = "Place the unit level, forward axis at the set heading; keep it still"

    def _add(self, t, a, g, temp) -> None:
        self._chunks.append((t, a, g, temp))
        self._n += len(t)
        self._sum += g.sum(axis=0)
        self._t1 = float(t[-1])

    def abort(self) -> None:
        self.phase = "aborted"
        self._message = "Aborted"
        self._events.append(("aborted", ""))

    def restart(self) -> None:
        if self.phase in ("average", "done"):
            self._reset()
            self.phase = "place"
            self._message = "Recording restarted: keep the unit still"

    def status(self) -> HoldStatus:
        c = self.config
        st = self._last[0] if self._last and self._last[0] is not None else self.tracker.state
        temp, t = (self._last[1], self._last[2]) if self._last else (math.nan, math.nan)
        rec = (self._t1 - self._t0) if self.phase in ("average", "done") and math.isfinite(self._t0) else 0.0
        mean = self._sum / self._n if self._n else np.full(3, np.nan)
        return HoldStatus(
            phase=self.phase, calibrating=st.calibrating, is_still=st.is_still, still_for_s=float(st.still_for_s),
            level=float(st.level),
            settle_left_s=max(c.settle_s - st.still_for_s, 0.0) if self.phase == "settle" else math.nan,
            countdown_s=max(c.duration_s - rec, 0.0) if self.phase == "average" else math.nan,
            progress=min(rec / c.duration_s, 1.0) if self.phase in ("average", "done") else 0.0,
            gyro_mean=tuple(float(x) for x in mean), n_samples=self._n, temp_c=temp, t_s=t, message=self._message)

    def capture(self, extra_meta: dict | None = None):
        from station.capture import Capture

        ch = self._chunks
        t = np.concatenate([c[0] for c in ch]) if ch else np.zeros(0)
        a = np.concatenate([c[1] for c in ch]) if ch else np.zeros((0, 3))
        g = np.concatenate([c[2] for c in ch]) if ch else np.zeros((0, 3))
        temp = np.concatenate([c[3] for c in ch]) if ch else np.zeros(0)
        cols = {"t": t, "ax": a[:, 0], "ay": a[:, 1], "az": a[:, 2], "gx": g[:, 0], "gy": g[:, 1], "gz": g[:, 2]}
        if np.isfinite(temp).any():
            cols["temp_c"] = temp
        meta = {"station-capture": "1", "procedure": self.procedure, "device": self.device_id or "unknown",
                "gyro_mode": "static", "heading_deg": repr(float(self.config.heading_deg)),
                "date": self.started[:10], "sample_rate_hz": repr(self.sample_rate_hz)}
        if self.config.frame:
            meta["frame"] = self.config.frame
        for k in ("accel_unit", "gyro_unit"):
            if self.units.get(k):
                meta[k] = self.units[k]
        for key in ("latitude_deg", "longitude_deg", "altitude_m"):
            if key in self.site:
                meta[key] = repr(float(self.site[key]))
        meta.update({k: str(v) for k, v in (extra_meta or {}).items()})
        return Capture(meta=meta, columns=cols)
