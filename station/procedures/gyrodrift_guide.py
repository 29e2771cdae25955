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

import math
from dataclasses import dataclass

import numpy as np

from station.procedures.guide_base import GuideBase, site_meta, started_utc, stillness_tracker

# `station demo`: P4 averages 180 s at the least (the drift is not resolved in less)
DEMO_MIN_AVERAGE_S = 180.0


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
    gyro_mean: tuple[float, float, float]  # running mean of the recording (raw gyro unit, capture axes)
    n_samples: int
    temp_c: float
    t_s: float
    message: str
    # the same mean in the axes of the result's drift (P4's body frame; see ``axes``)
    gyro_mean_body: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    axes: str = ""  # what gyro_mean_body's x, y, z are


class HoldGuide(GuideBase):
    procedure = "gyro-drift"

    def __init__(
        self,
        *,
        sample_rate_hz: float,
        units: dict,
        device_id: str = "",
        site: dict | None = None,
        config: HoldConfig | None = None,
    ):
        self.config = config or HoldConfig()
        self.sample_rate_hz = float(sample_rate_hz)
        self.units = dict(units)
        self.device_id = device_id
        self.site = dict(site or {})
        self.started = started_utc()
        self.tracker = stillness_tracker(self.config, self.sample_rate_hz)
        self.phase = "noise"
        self._events: list[tuple[str, str]] = []
        self._message = "Place the unit level, forward axis at the set heading; keep it still"
        self._last = None
        self._axes = _body_axes(self)
        self._reset()

    def _reset(self) -> None:
        self._chunks: list[tuple[np.ndarray, ...]] = []
        self._n = 0
        self._sum = np.zeros(3)
        self._t0 = math.nan
        self._t1 = math.nan

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
        self._last = (
            st,
            float(np.nanmean(temp[-step:])) if np.isfinite(temp[-step:]).any() else math.nan,
            float(t_s[-1]),
        )
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
            phase=self.phase,
            calibrating=st.calibrating,
            is_still=st.is_still,
            still_for_s=float(st.still_for_s),
            level=float(st.level),
            settle_left_s=max(c.settle_s - st.still_for_s, 0.0) if self.phase == "settle" else math.nan,
            countdown_s=max(c.duration_s - rec, 0.0) if self.phase == "average" else math.nan,
            progress=min(rec / c.duration_s, 1.0) if self.phase in ("average", "done") else 0.0,
            gyro_mean=tuple(float(x) for x in mean),
            n_samples=self._n,
            temp_c=temp,
            t_s=t,
            message=self._message,
            gyro_mean_body=tuple(float(x) for x in _to_body(self._axes, mean)),
            axes=self._axes[2],
        )

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
        meta = _capture_meta(
            self, {"gyro_mode": "static", "heading_deg": repr(float(self.config.heading_deg))}, extra_meta
        )
        return Capture(meta=meta, columns=cols)


# ---------------------------------------------------------------- P4 mode A


@dataclass
class ReferenceConfig:
    """P4 mode A (a reference IMU rigidly mounted with the unit, both moving). duration_s:
    recording length [s] (P4: >= 180). reference_drift_deg_h: the reference IMU's own drift
    (1σ, from its data sheet; the source's fibre-optic example: 1 °/h). frame: the unit's
    axes in words for the capture. min_motion_rad_s: the reference rate's spread that
    makes the mounting check meaningful."""

    duration_s: float = 180.0
    reference_drift_deg_h: float = 1.0
    frame: str = ""
    min_motion_rad_s: float = 0.02

    def __post_init__(self) -> None:
        for name in ("duration_s", "reference_drift_deg_h", "min_motion_rad_s"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class ReferenceStatus:
    phase: str  # wait (no reference yet) | average (recording) | done | aborted
    countdown_s: float
    progress: float
    drift: tuple[float, float, float]  # running mean of unit minus reference (raw gyro unit)
    drift_se: tuple[float, float, float]  # its white-noise standard error (raw gyro unit)
    motion: float  # RMS spread of the reference rate so far (raw gyro unit)
    coupling_max: float  # largest |M| of d = ε + M Ω so far (rad/rad), NaN before motion
    coupling_bias: float  # largest |M · mean Ω| (raw gyro unit): the drift's bias from it
    mounting_ok: bool
    n_samples: int
    t_s: float
    message: str
    # drift and drift_se in the axes of the result's drift (P4's body frame; see ``axes``)
    drift_body: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    drift_se_body: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    axes: str = ""
    # HoldStatus look-alike fields, so the P1 widgets draw the countdown
    is_still: bool = True
    still_for_s: float = 0.0
    calibrating: bool = False
    level: float = math.nan
    settle_left_s: float = math.nan


class ReferenceGuide(GuideBase):
    """P4 mode A live: record the unit's gyro and the reference IMU's side by side for
    ``duration_s`` while the rate table turns both. Live, the procedure's own numbers:
    the running drift ``ε = mean(ω − ω_ref)`` ± its white-noise standard error, how much
    the reference moved, and the mounting check of ``solvers.gyrodrift.drift_reference``
    (regress ``ω − ω_ref`` on the reference rate: a misaligned or scale-wrong mounting
    grows with the rate and biases ε by ``M · mean Ω``), from running sums. The final
    numbers come from the P4 calibration of the capture (``gyro_mode: reference``)."""

    procedure = "gyro-drift"

    def __init__(
        self,
        *,
        sample_rate_hz: float,
        units: dict,
        device_id: str = "",
        site: dict | None = None,
        config: ReferenceConfig | None = None,
    ):
        self.config = config or ReferenceConfig()
        self.sample_rate_hz = float(sample_rate_hz)
        self.units = dict(units)
        self.device_id = device_id
        self.site = dict(site or {})
        self.started = started_utc()
        self.phase = "wait"
        self._events: list[tuple[str, str]] = []
        self._message = "Waiting for the reference IMU"
        self._axes = _body_axes(self)
        self._reset()

    def _reset(self) -> None:
        self._chunks: list[tuple[np.ndarray, ...]] = []
        self._n = 0
        self._sd = np.zeros(3)  # Σ d
        self._sdd = np.zeros(3)  # Σ d²
        self._sr = np.zeros(3)  # Σ Ω
        self._srr = np.zeros((3, 3))  # Σ Ω Ωᵀ
        self._srd = np.zeros((3, 3))  # Σ Ω dᵀ
        self._t0 = math.nan
        self._t1 = math.nan

    def update(self, t_s, accel, gyro, ref, temp_c=None) -> ReferenceStatus:
        """t_s (n,), accel (n, 3) raw, gyro (n, 3) in the gyro unit, ref (n, 3) in rad/s (the
        capture format's unit of ``ref_g*``), temp_c (n,)."""
        t_s = np.asarray(t_s, float)
        if len(t_s) == 0 or self.phase in ("done", "aborted"):
            return self.status()
        accel, gyro = (np.asarray(x, float).reshape(-1, 3) for x in (accel, gyro))
        ref = np.full((len(t_s), 3), np.nan) if ref is None else np.asarray(ref, float).reshape(-1, 3)
        temp = np.full(len(t_s), np.nan) if temp_c is None else np.asarray(temp_c, float)
        ok = np.all(np.isfinite(gyro), axis=1) & np.all(np.isfinite(ref), axis=1)
        if not ok.any():
            self._message = (
                "No reference IMU signal: connect the reference (ref_gx ref_gy ref_gz) or use P4 on a static base"
            )
            return self.status()
        if self.phase == "wait":
            self.phase = "average"
            self._t0 = float(t_s[ok][0])
            self._message = "Recording the unit and the reference: run the rate table"
        self._chunks.append((t_s, accel, gyro, ref, temp))
        g, r = gyro[ok], ref[ok] * self._unit_per_rad_s()
        d = g - r
        self._n += len(d)
        self._sd += d.sum(axis=0)
        self._sdd += (d * d).sum(axis=0)
        self._sr += r.sum(axis=0)
        self._srr += r.T @ r
        self._srd += r.T @ d
        self._t1 = float(t_s[-1])
        if self._t1 - self._t0 >= self.config.duration_s:
            self.phase = "done"
            self._message = f"Recorded {self._t1 - self._t0:.0f} s"
            self._events.append(("done", ""))
        return self.status()

    def _checks(self):
        """(ε, se, motion, M or None) from the running sums."""
        n = self._n
        if n < 2:
            nan3 = np.full(3, np.nan)
            return nan3, nan3, math.nan, None
        eps = self._sd / n
        var = np.maximum(self._sdd / n - eps * eps, 0.0) * n / (n - 1)
        r_mean = self._sr / n
        cov_r = self._srr / n - np.outer(r_mean, r_mean)
        motion = float(math.sqrt(max(np.trace(cov_r), 0.0)))
        M = None
        if motion >= self.config.min_motion_rad_s * self._unit_per_rad_s() and np.linalg.cond(cov_r) < 1e8:
            cov_rd = self._srd / n - np.outer(r_mean, eps)
            M = np.linalg.solve(cov_r, cov_rd).T  # d − ε = M (Ω − mean Ω)
        return eps, np.sqrt(var / n), motion, M

    def _unit_per_rad_s(self) -> float:
        from solvers.units import si_factor

        f = si_factor("gyro", self.units.get("gyro_unit") or "rad/s")
        return 1.0 / f if f else 1.0

    def status(self) -> ReferenceStatus:
        c = self.config
        eps, se, motion, M = self._checks()
        r_mean = self._sr / self._n if self._n else np.full(3, np.nan)
        rec = (self._t1 - self._t0) if math.isfinite(self._t0) else 0.0
        cmax = cbias = math.nan
        ok = True
        msg = self._message
        if M is not None:
            bias = M @ (self._sr / self._n)
            cmax, cbias = float(np.max(np.abs(M))), float(np.max(np.abs(bias)))
            sigma_ref = c.reference_drift_deg_h * math.radians(1.0) / 3600.0 * self._unit_per_rad_s()
            ok = bool(np.all(np.abs(bias) <= 0.5 * np.sqrt(se**2 + sigma_ref**2)))
            if not ok and self.phase == "average":
                msg = (
                    f"Unit minus reference grows with the rate (|M| up to {cmax:.3g}): check the mounting "
                    "(misaligned or not rigid)"
                )
        elif self.phase == "average" and rec > 10 and not (motion >= c.min_motion_rad_s * self._unit_per_rad_s()):
            msg = "The reference hardly moves: run the rate table so the mounting can be checked"
        return ReferenceStatus(
            phase=self.phase,
            countdown_s=max(c.duration_s - rec, 0.0) if self.phase == "average" else math.nan,
            progress=min(rec / c.duration_s, 1.0) if self.phase in ("average", "done") else 0.0,
            drift=tuple(float(x) for x in eps),
            drift_se=tuple(float(x) for x in se),
            motion=motion,
            coupling_max=cmax,
            coupling_bias=cbias,
            mounting_ok=ok,
            n_samples=self._n,
            t_s=self._t1,
            message=msg,
            # ε = mean(ω) − mean(Ω): the unit's gyro turned (and flipped) as P4 turns it, the
            # reference (capture format: already right-handed) only turned
            drift_body=tuple(float(x) for x in _to_body(self._axes, eps + r_mean) - _to_body(self._axes, r_mean, 1)),
            drift_se_body=tuple(float(x) for x in _to_body(self._axes, se, 1, magnitude=True)),
            axes=self._axes[2],
        )

    def restart(self) -> None:
        if self.phase in ("average", "done"):
            self._reset()
            self.phase = "wait"
            self._message = "Recording restarted"

    def capture(self, extra_meta: dict | None = None):
        from station.capture import Capture

        ch = self._chunks
        cat = [
            np.concatenate([c[i] for c in ch]) if ch else np.zeros((0, 3) if i in (1, 2, 3) else 0) for i in range(5)
        ]
        t, a, g, r, temp = cat
        cols = {
            "t": t,
            "ax": a[:, 0],
            "ay": a[:, 1],
            "az": a[:, 2],
            "gx": g[:, 0],
            "gy": g[:, 1],
            "gz": g[:, 2],
            "ref_gx": r[:, 0],
            "ref_gy": r[:, 1],
            "ref_gz": r[:, 2],
        }
        if np.isfinite(temp).any():
            cols["temp_c"] = temp
        mode = {"gyro_mode": "reference", "reference_drift_deg_h": repr(float(self.config.reference_drift_deg_h))}
        return Capture(meta=_capture_meta(self, mode, extra_meta), columns=cols)


def _body_axes(guide) -> tuple[np.ndarray | None, np.ndarray | None, str]:
    """``(C_fur_cap, gyro_flips, what the axes are)`` from the metadata the guide's capture
    will carry, read by P4 itself (``gyrodrift.body_axes``): the live numbers are then in
    the axes of the result's drift. A frame P4 cannot read (the calibration will refuse it)
    leaves the device's own axes, said so."""
    from station.errors import InputError
    from station.procedures import gyrodrift

    try:
        C, flips = gyrodrift.body_axes(_capture_meta(guide, {}, None))
    except InputError:
        return None, None, "the device's axes (frame not understood)"
    return C, flips, f"P4 body axes: {gyrodrift.BODY_AXES}"


def _to_body(axes, v, flips=None, magnitude=False) -> np.ndarray:
    """``v`` (3,) in the capture's axes → P4's body frame by ``axes`` (:func:`_body_axes`);
    ``flips=1``: no gyro sign flips (the reference); ``magnitude``: a spread, not a vector
    (C is a signed permutation, so a spread only moves to its axis)."""
    C, f = axes[0], axes[1]
    v = np.asarray(v, float)
    if C is None:
        return v
    if magnitude:
        return np.abs(C) @ v
    return C @ (v * (f if flips is None else flips))


def _capture_meta(guide, mode: dict[str, str], extra_meta: dict | None) -> dict[str, str]:
    """A P4 guide's capture metadata, in the file's order: format, procedure, device, the
    mode's keys, date, rate, frame, units, site, then ``extra_meta``."""
    meta = {
        "station-capture": "1",
        "procedure": guide.procedure,
        "device": guide.device_id or "unknown",
        **mode,
        "date": guide.started[:10],
        "sample_rate_hz": repr(guide.sample_rate_hz),
    }
    if guide.config.frame:
        meta["frame"] = guide.config.frame
    for k in ("accel_unit", "gyro_unit"):
        if guide.units.get(k):
            meta[k] = guide.units[k]
    meta.update(site_meta(guide.site))
    meta.update({k: str(v) for k, v in (extra_meta or {}).items()})
    return meta


def live_device(*, seed: int, rate_hz: float, reference: bool = False):
    """The simulated bench device for this procedure (``station.sources.SimSource``'s): the
    unit held where the operator puts it (``solvers.simulate.LiveImu``)."""
    from solvers.simulate import LiveImu

    return LiveImu(procedure="gyro-drift", seed=seed, rate_hz=rate_hz, hold_s=1e9, reference=reference)
