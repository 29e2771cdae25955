"""The guided P1 procedure as a UI-free state machine (the TUI, `station demo --headless`
and the tests drive the same object).

Feed it raw samples with :meth:`P1Guide.update`; it tells where the operator is:

    noise    hold still while the station measures the sensor noise (init_rest_s)
    place    put the unit in the asked position and let go
    settle   still and in position: waiting settle_s before averaging starts
    average  averaging the raw output; countdown = average_s minus time averaged
    done     every step captured or skipped        aborted   the operator gave up

Stillness comes from ``solvers.stillness.StillnessTracker`` (variance of a short window
against the noise of the initial rest). Orientation: the raw accelerometer output is
mapped to specific force with the "calibrated-so-far" model ``f = B + M V`` (the device's
previous calibration if given, else a nominal per-axis zero and scale, refined by least
squares from the positions captured so far) and compared with the asked direction by
``solvers.detectors.orientation_check`` (the one check ``station/device/live.py`` uses);
more than 90° off is "wrong face up".

All times are the samples' own ``t_s`` (device clock), so a replay is deterministic.
The averages become a P1 table-of-averages :class:`station.capture.Capture`
(:meth:`P1Guide.capture`). The state (captured averages, current step, settings) is
saved as a small JSON file after every change so an interrupted run can be resumed.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, fields

import numpy as np

from solvers import frames
from solvers.detectors import orientation_check
from solvers.models import accel as accel_model
from solvers.positions import P1_INSTRUCTIONS, P1_POSITIONS
from station.fileio import atomic_write_json
from station.procedures.guide_base import site_meta, started_utc, stillness_tracker
from station.procedures.state import default_state_path  # noqa: F401 - re-exported

# the guide keeps its captured positions in a resume file (station.procedures.state): an
# aborted run resumes (the TUI says so before it aborts)
RESUMABLE = True

STATE_VERSION = 1
PHASES = ("noise", "place", "settle", "average", "done", "aborted")
STATUSES = ("pending", "captured", "skipped")

# Nominal per-axis zero and sensitivity (raw units per m/s²) when nothing better is known.
NOMINAL_BY_UNIT: dict[str, tuple[float, float]] = {
    "m/s^2": (0.0, 1.0),
    "g": (0.0, 1.0 / frames.G_STANDARD_MPS2),
}


@dataclass
class GuideConfig:
    """Settings of a guided run. Times in seconds of the samples' clock.

    average_s: averaging time per position (the P1 source asks 3–5 minutes).
    settle_s: still and in position this long before averaging starts.
    angle_tol_deg: largest angle from the asked direction accepted as "in position".
    init_rest_s: initial rest used to measure the noise floor of the stillness detector.
    window_s: stillness detector window.
    """

    average_s: float = 180.0
    settle_s: float = 2.0
    angle_tol_deg: float = 12.0
    init_rest_s: float = 2.0
    window_s: float = 0.5

    def __post_init__(self) -> None:
        for name in ("average_s", "settle_s", "angle_tol_deg", "init_rest_s", "window_s"):
            v = float(getattr(self, name))
            if not math.isfinite(v) or v < 0 or (v == 0 and name in ("average_s", "init_rest_s", "window_s")):
                raise ValueError(f"{name} must be a positive number, got {getattr(self, name)!r}")
            setattr(self, name, v)


@dataclass
class Step:
    """One position: what to do, and (once captured) the averages of the raw output."""

    name: str
    instruction: str
    direction: tuple[float, float, float]  # unit specific force, body frame (the "up" axis)
    status: str = "pending"
    mean: list[float] | None = None  # raw accel mean (accel_unit)
    std: list[float] | None = None
    n: int = 0
    temp_c: float | None = None
    t_s: float | None = None  # device time at the end of the average
    t0_s: float | None = None  # device time at the start of the average


@dataclass(frozen=True)
class GuideStatus:
    """A snapshot for a display (replaceable: only the newest matters)."""

    phase: str
    step_index: int
    step_name: str
    instruction: str
    n_steps: int
    n_captured: int
    calibrating: bool
    is_still: bool
    still_for_s: float
    level: float
    angle_deg: float  # NaN when the orientation is not known yet
    in_position: bool
    wrong_face: bool
    settle_left_s: float
    countdown_s: float  # averaging time left; NaN outside "average"
    progress: float  # 0..1 of the current average
    raw: tuple[float, float, float]
    f_mps2: tuple[float, float, float]  # calibrated-so-far specific force (NaN where unknown)
    norm_mps2: float
    gyro: tuple[float, float, float]
    temp_c: float
    t_s: float
    message: str


MAX_RECORD_ROWS = 2_000_000  # ~5.5 h at 100 Hz: beyond, the guide keeps the averages only


def p1_steps(names: list[str] | None = None) -> list[Step]:
    names = list(names or P1_POSITIONS)
    out = []
    for n in names:
        if n not in P1_POSITIONS:
            raise ValueError(f"unknown P1 position {n!r}; known: {', '.join(P1_POSITIONS)}")
        out.append(Step(n, P1_INSTRUCTIONS[n], tuple(float(x) for x in P1_POSITIONS[n])))
    return out


def wrong_face_message(angle_deg: float) -> str:
    """What the operator is told when another face is up, ``angle_deg`` from the asked direction:
    a quarter turn only near 90°, upside down past 135°."""
    if angle_deg > 135.0:
        return "Upside down: turn the unit over"
    if 67.5 <= angle_deg <= 112.5:
        return f"Wrong face up: {angle_deg:.0f}° off, a quarter turn; put the face shown up"
    return f"Wrong face up: {angle_deg:.0f}° off; put the face shown up"


class P1Guide:
    """The P1 (level table) guided run. See the module docstring for the phases.

    sample_rate_hz: nominal rate of the stream (the stillness window in samples).
    accel_unit: raw unit of ax..az (written into the capture).
    nominal: (zero, sensitivity per m/s²) per axis or scalar, for the orientation check
        before any position is captured; default from the unit (g, m/s^2) or unknown.
    previous: a previous P1 result (``params`` with ``B`` and ``M``): used as the
        calibrated-so-far model instead.
    g_mps2: local gravity (default: normal gravity at ``site``).
    """

    procedure = "accel-tabletop"

    def __init__(
        self,
        *,
        sample_rate_hz: float,
        accel_unit: str = "V",
        device_id: str = "",
        config: GuideConfig | None = None,
        positions: list[str] | None = None,
        nominal=None,
        previous: dict | None = None,
        site: dict | None = None,
        g_mps2: float | None = None,
        state_path: str | None = None,
        gyro_unit: str | None = None,
    ):
        self.config = config or GuideConfig()
        self.gyro_unit = gyro_unit
        # the whole stream with the gyro, so that the turns between positions calibrate the gyro
        # triad too (docs/tabletop-gyro.md); dropped when a batch has no gyro or it grows too big
        self._rec: list[tuple] = []
        self._rec_rows = 0
        self._rec_ok = True
        self.sample_rate_hz = float(sample_rate_hz)
        self.accel_unit = accel_unit
        self.device_id = device_id
        self.site = dict(site or {})
        lat = float(self.site.get("latitude_deg", 45.0))
        alt = float(self.site.get("altitude_m", 0.0))
        self.g_mps2 = float(g_mps2) if g_mps2 else frames.normal_gravity_mps2(lat, alt)
        self.steps = p1_steps(positions)
        self.index = 0
        self.phase = "noise"
        self.state_path = state_path
        self.started = started_utc()
        self._events: list[tuple[str, str]] = []
        self._message = "Hold the unit still: measuring the sensor noise"
        self._nominal = self._nominal_from(nominal, accel_unit)
        self._previous = None
        if previous and isinstance(previous.get("params"), dict) and "B" in previous["params"]:
            B = np.asarray(previous["params"]["B"], dtype=float)
            M = np.asarray(previous["params"]["M"], dtype=float)
            if B.shape == (3,) and M.shape == (3, 3) and np.all(np.isfinite(M)):
                self._previous = (B, M)
        self._model = self._build_model()
        self._new_tracker()
        self._avg_reset()
        self._last = None

    # ------------------------------------------------------------ set-up

    @staticmethod
    def _nominal_from(nominal, unit):
        if nominal is None:
            nominal = NOMINAL_BY_UNIT.get(unit)
        if nominal is None:
            return None
        zero, sens = nominal
        zero = np.broadcast_to(np.asarray(zero, dtype=float), (3,)).copy()
        sens = np.broadcast_to(np.asarray(sens, dtype=float), (3,)).copy()
        return zero, sens

    def _new_tracker(self) -> None:
        self.tracker = stillness_tracker(self.config, self.sample_rate_hz)
        self.phase = "noise" if self.phase not in ("done", "aborted") else self.phase

    def _avg_reset(self) -> None:
        self._avg_n = 0
        self._avg_sum = np.zeros(3)
        self._avg_sq = np.zeros(3)
        self._avg_temp = 0.0
        self._avg_temp_n = 0
        self._avg_t0 = math.nan
        self._avg_t = math.nan

    # ------------------------------------------------------------ the model so far

    def _build_model(self):
        """(B, M, known_axes): f = B + M V for the axes known so far."""
        if self._previous is not None:
            B, M = self._previous
            return B, M, np.ones(3, bool)
        zero = np.full(3, np.nan)
        sens = np.full(3, np.nan)
        if self._nominal is not None:
            zero, sens = self._nominal[0].copy(), self._nominal[1].copy()
        caps = [s for s in self.steps if s.status == "captured"]
        for i in range(3):
            d = np.array([s.direction[i] for s in caps])
            v = np.array([s.mean[i] for s in caps])
            if len(caps) >= 2 and np.ptp(d) > 0.5 and np.all(np.isfinite(v)):
                A = np.column_stack([np.ones(len(d)), self.g_mps2 * d])
                (b, k), *_ = np.linalg.lstsq(A, v, rcond=None)
                if abs(k) > 0:
                    zero[i], sens[i] = b, k
            elif caps and math.isfinite(sens[i]):
                j = int(np.argmax(np.abs(d))) if len(d) else 0
                zero[i] = v[j] - sens[i] * self.g_mps2 * d[j] if len(d) else zero[i]
        known = np.isfinite(zero) & np.isfinite(sens) & (sens != 0)
        if not known.all() and known.any():  # a triad: borrow the typical sensitivity
            typical = float(np.median(sens[known]))
            borrow = ~known & np.isfinite(zero)
            sens[borrow] = typical
            known = np.isfinite(zero) & np.isfinite(sens) & (sens != 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            M = np.diag(np.where(known, 1.0 / sens, np.nan))
            B = np.where(known, -zero / sens, np.nan)
        return B, M, known

    def specific_force(self, raw) -> np.ndarray:
        """Calibrated-so-far specific force [m/s²] for raw accel (3,) or (n, 3); NaN where unknown."""
        B, M, known = self._model
        raw = np.asarray(raw, dtype=float)
        Mz = np.where(np.isfinite(M), M, 0.0)
        f = accel_model.p1_apply(raw, np.where(known, B, 0.0), Mz).reshape(raw.shape)
        return np.where(known, f, np.nan)

    # ------------------------------------------------------------ properties

    @property
    def step(self) -> Step | None:
        return self.steps[self.index] if 0 <= self.index < len(self.steps) else None

    @property
    def n_captured(self) -> int:
        return sum(s.status == "captured" for s in self.steps)

    @property
    def complete(self) -> bool:
        return self.phase == "done"

    def take_events(self) -> list[tuple[str, str]]:
        """Events since the last call: ("captured", name), ("restarted", why),
        ("skipped", name), ("done", ""), ("aborted", "")."""
        ev, self._events = self._events, []
        return ev

    # ------------------------------------------------------------ feeding

    def update(self, t_s, accel, gyro=None, temp_c=None) -> GuideStatus:
        """Add samples: t_s (n,), accel (n, 3) raw, gyro (n, 3) or None, temp_c (n,) or None."""
        t_s = np.asarray(t_s, dtype=float)
        accel = np.asarray(accel, dtype=float).reshape(-1, 3)
        if len(t_s) == 0:
            return self.status()
        if gyro is not None:
            gyro = np.asarray(gyro, dtype=float).reshape(-1, 3)
            if not np.isfinite(gyro).any():
                gyro = None
        if self.phase in ("done", "aborted"):
            self._remember(t_s, accel, gyro, temp_c, None)
            return self.status()
        self._record(t_s, accel, gyro, temp_c)
        # Feed the tracker in slices so that a phase change inside a batch lands on the
        # right sample (batches are ~50-100 ms: slices of 0.1 s are plenty).
        step_n = max(1, int(self.sample_rate_hz * 0.1))
        for a in range(0, len(t_s), step_n):
            b = a + step_n
            st = self.tracker.update(t_s[a:b], accel[a:b], None if gyro is None else gyro[a:b])
            tc = None if temp_c is None else np.asarray(temp_c, dtype=float)[a:b]
            self._advance(st, t_s[a:b], accel[a:b], tc)
            if self.phase in ("done", "aborted"):
                break
        self._remember(t_s, accel, gyro, temp_c, st)
        return self.status()

    def _record(self, t_s, accel, gyro, temp_c) -> None:
        if not self._rec_ok:
            return
        if gyro is None or self._rec_rows + len(t_s) > MAX_RECORD_ROWS:
            self._rec_ok, self._rec, self._rec_rows = False, [], 0
            return
        temp = np.full(len(t_s), np.nan) if temp_c is None else np.asarray(temp_c, dtype=float).reshape(-1)
        self._rec.append((t_s.copy(), accel.copy(), gyro.copy(), temp.copy()))
        self._rec_rows += len(t_s)

    def _remember(self, t_s, accel, gyro, temp_c, st) -> None:
        k = min(len(t_s), max(1, int(self.sample_rate_hz * 0.1)))
        raw = accel[-k:].mean(axis=0)
        g = gyro[-k:].mean(axis=0) if gyro is not None else np.full(3, np.nan)
        temp = float(np.nanmean(np.asarray(temp_c, dtype=float)[-k:])) if temp_c is not None else math.nan
        st = st if st is not None else self.tracker.state
        self._last = (raw, g, temp, float(t_s[-1]), st)

    def _orientation(self, raw) -> tuple[float, bool, bool]:
        step = self.step
        if step is None:
            return math.nan, False, False
        f = self.specific_force(raw)
        if not np.all(np.isfinite(f)) or np.linalg.norm(f) == 0:
            return math.nan, False, False
        chk = orientation_check(f, step.direction, self.config.angle_tol_deg)
        return chk.angle_deg, chk.ok, chk.wrong_face_up

    def _advance(self, st, t_s, accel, temp_c) -> None:
        c = self.config
        if st.calibrating:
            self.phase = "noise"
            return
        if self.phase == "noise":
            self.phase = "place"
            self._message = "Place the unit as shown and let go"
        raw = accel[-max(1, len(accel) // 2) :].mean(axis=0)
        angle, ok, wrong = self._orientation(raw)
        known = math.isfinite(angle)
        in_pos = st.is_still and (ok or not known)
        if self.phase == "average":
            if not st.is_still or (known and not ok):
                why = "moved" if not st.is_still else "left the position"
                self._events.append(("restarted", f"{self.step.name}: {why} during the average"))
                self._message = f"The unit {why}: averaging starts again when it is still"
                self._avg_reset()
                self.phase = "place"
                return
            self._avg_add(t_s, accel, temp_c)
            if self._avg_t - self._avg_t0 >= c.average_s:
                self._capture()
            return
        if in_pos and st.still_for_s >= c.settle_s:
            self.phase = "average"
            self._avg_reset()
            self._avg_t0 = float(t_s[0])
            self._message = "Averaging: keep the unit still"
            self._avg_add(t_s, accel, temp_c)
            return
        if in_pos:
            self.phase = "settle"
            self._message = "In position and still: averaging starts shortly"
        else:
            self.phase = "place"
            if wrong:
                self._message = wrong_face_message(angle)
            elif st.is_still and known and not ok:
                self._message = f"Not in position: {angle:.0f}° from the asked direction"
            else:
                self._message = "Place the unit as shown and let go"

    def _avg_add(self, t_s, accel, temp_c) -> None:
        self._avg_n += len(accel)
        self._avg_sum += accel.sum(axis=0)
        self._avg_sq += (accel * accel).sum(axis=0)
        if temp_c is not None:
            tc = temp_c[np.isfinite(temp_c)]
            self._avg_temp += float(tc.sum())
            self._avg_temp_n += len(tc)
        self._avg_t = float(t_s[-1])

    def _capture(self) -> None:
        step = self.step
        n = self._avg_n
        mean = self._avg_sum / n
        var = np.maximum(self._avg_sq / n - mean * mean, 0.0) * n / max(n - 1, 1)
        step.mean = [float(x) for x in mean]
        step.std = [float(x) for x in np.sqrt(var)]
        step.n = int(n)
        step.temp_c = self._avg_temp / self._avg_temp_n if self._avg_temp_n else None
        step.t_s = self._avg_t
        step.t0_s = self._avg_t0
        step.status = "captured"
        self._events.append(("captured", step.name))
        self._avg_reset()
        if self._previous is None:
            self._model = self._build_model()
        self._next_pending(f"{step.name} captured")
        self.save()

    def _next_pending(self, said: str = "") -> None:
        order = list(range(self.index + 1, len(self.steps))) + list(range(0, self.index + 1))
        for i in order:
            if self.steps[i].status == "pending":
                self.index = i
                self.phase = "place"
                nxt = self.steps[i].name
                self._message = f"{said}: now {nxt}" if said else f"Now {nxt}"
                return
        self.phase = "done"
        self._message = f"{said}: all positions done" if said else "All positions done"
        self._events.append(("done", ""))

    # ------------------------------------------------------------ operator actions

    def skip(self) -> None:
        """Skip the current step (it stays out of the fit unless redone)."""
        step = self.step
        if step is None or self.phase in ("done", "aborted"):
            return
        if step.status == "pending":
            step.status = "skipped"
        self._events.append(("skipped", step.name))
        self._avg_reset()
        self._next_pending(f"{step.name} skipped")
        self.save()

    def redo(self, index: int | None = None) -> None:
        """Capture step ``index`` (default: the current one, else the last captured) again."""
        if self.phase == "aborted":
            return
        if index is None:
            index = self.index
            if self.phase == "done" or self.steps[index].status == "pending":
                done = [i for i, s in enumerate(self.steps) if s.status != "pending"]
                if self.phase == "done" and done:
                    index = done[-1]
                elif self.steps[index].status == "pending" and self.phase != "done":
                    self._avg_reset()  # restart the current average
                    self.phase = "place"
                    self._message = f"{self.steps[index].name}: averaging restarted"
                    return
        if not 0 <= index < len(self.steps):
            raise IndexError(f"no step {index}")
        s = self.steps[index]
        s.status, s.mean, s.std, s.n, s.temp_c, s.t_s = "pending", None, None, 0, None, None
        self.index = index
        self.phase = "place"
        self._avg_reset()
        if self._previous is None:
            self._model = self._build_model()
        self._message = f"Redo {s.name}: place the unit as shown"
        self.save()

    def select(self, index: int) -> None:
        """Make step ``index`` current (captured steps are redone)."""
        if self.steps[index].status != "pending":
            self.redo(index)
            return
        if self.steps[index].status == "pending":
            self.index = index
            if self.phase not in ("noise", "aborted"):
                self.phase = "place"
            self._avg_reset()
            self.save()

    def abort(self) -> None:
        self.phase = "aborted"
        self._message = "Aborted: the captured positions are kept in the resume file"
        self._events.append(("aborted", ""))
        self._avg_reset()
        self.save()

    # ------------------------------------------------------------ display

    def status(self) -> GuideStatus:
        step = self.step
        nan3 = (math.nan, math.nan, math.nan)
        if self._last is None:
            raw, gyr, temp, t, st = np.full(3, np.nan), np.full(3, np.nan), math.nan, math.nan, self.tracker.state
        else:
            raw, gyr, temp, t, st = self._last
        f = self.specific_force(raw) if np.all(np.isfinite(raw)) else np.full(3, np.nan)
        angle, ok, wrong = self._orientation(raw) if np.all(np.isfinite(raw)) else (math.nan, False, False)
        c = self.config
        if self.phase == "average":
            done_s = self._avg_t - self._avg_t0
            countdown, progress = max(c.average_s - done_s, 0.0), min(done_s / c.average_s, 1.0)
        else:
            countdown, progress = math.nan, 0.0
        settle_left = max(c.settle_s - st.still_for_s, 0.0) if self.phase == "settle" else math.nan
        return GuideStatus(
            phase=self.phase,
            step_index=self.index,
            step_name=step.name if step else "",
            instruction=step.instruction if step else "",
            n_steps=len(self.steps),
            n_captured=self.n_captured,
            calibrating=st.calibrating,
            is_still=st.is_still,
            still_for_s=float(st.still_for_s),
            level=float(st.level),
            angle_deg=angle,
            in_position=ok,
            wrong_face=wrong,
            settle_left_s=settle_left,
            countdown_s=countdown,
            progress=progress,
            raw=tuple(float(x) for x in raw),
            f_mps2=tuple(float(x) for x in f),
            norm_mps2=float(np.linalg.norm(f)) if np.all(np.isfinite(f)) else math.nan,
            gyro=tuple(float(x) for x in gyr) if gyr is not None else nan3,
            temp_c=temp,
            t_s=t,
            message=self._message,
        )

    # ------------------------------------------------------------ the capture

    def capture(self, extra_meta: dict | None = None, *, rotations: bool = True):
        """The captured positions as a P1 capture (``station.capture.Capture``): the whole time
        series with the gyro and a ``position`` column on each average's samples when the guide
        saw the gyro for the whole session (so the turns between positions calibrate the gyro
        too); otherwise (no gyro, a resumed session) the table of averages."""
        from station.capture import Capture

        caps = [s for s in self.steps if s.status == "captured"]
        series = self._series(caps) if rotations else None
        meta = {
            "station-capture": "1",
            "procedure": self.procedure,
            "device": self.device_id or "unknown",
            "accel_unit": self.accel_unit,
            "date": self.started[:10],
            "g_mps2": repr(float(self.g_mps2)),
        }
        meta.update(site_meta(self.site))
        meta["averaging_s"] = repr(self.config.average_s)
        meta.update({k: str(v) for k, v in (extra_meta or {}).items()})
        if series is not None:
            if self.gyro_unit:
                meta["gyro_unit"] = self.gyro_unit
            meta["sample_rate_hz"] = repr(self.sample_rate_hz)
            return Capture(meta=meta, columns=series)
        cols: dict[str, np.ndarray] = {"position": np.array([s.name for s in caps], dtype=object)}
        for i, ax in enumerate(("ax", "ay", "az")):
            cols[ax] = np.array([s.mean[i] for s in caps], dtype=float)
        for i, ax in enumerate(("ax", "ay", "az")):
            cols[ax + "_std"] = np.array([s.std[i] for s in caps], dtype=float)
        cols["n"] = np.array([float(s.n) for s in caps])
        if any(s.temp_c is not None for s in caps):
            cols["temp_c"] = np.array([s.temp_c if s.temp_c is not None else math.nan for s in caps])
        return Capture(meta=meta, columns=cols)

    def _series(self, caps) -> dict | None:
        """Columns of the recorded stream with each captured average labelled, or None when the
        recording does not cover every captured position (no gyro, resumed, too long)."""
        if not self._rec_ok or not self._rec or len(caps) < 2:
            return None
        t = np.concatenate([r[0] for r in self._rec])
        if any(s.t0_s is None or s.t0_s < t[0] or s.t_s > t[-1] for s in caps):
            return None
        a = np.concatenate([r[1] for r in self._rec])
        g = np.concatenate([r[2] for r in self._rec])
        temp = np.concatenate([r[3] for r in self._rec])
        pos = np.full(len(t), "", dtype=object)
        for s in caps:
            pos[(t >= s.t0_s) & (t <= s.t_s)] = s.name
        cols = {
            "t": t,
            "position": pos,
            "ax": a[:, 0],
            "ay": a[:, 1],
            "az": a[:, 2],
            "gx": g[:, 0],
            "gy": g[:, 1],
            "gz": g[:, 2],
        }
        if np.isfinite(temp).any():
            cols["temp_c"] = temp
        return cols

    # ------------------------------------------------------------ resume

    def to_state(self) -> dict:
        return {
            "version": STATE_VERSION,
            "procedure": self.procedure,
            "device_id": self.device_id,
            "accel_unit": self.accel_unit,
            "sample_rate_hz": self.sample_rate_hz,
            "started": self.started,
            "site": self.site,
            "g_mps2": self.g_mps2,
            "config": asdict(self.config),
            "index": self.index,
            "phase": self.phase if self.phase in ("done", "aborted") else "running",
            "steps": [asdict(s) for s in self.steps],
        }

    def save(self, path: str | None = None) -> None:
        """Write the resume state atomically (no-op without a path)."""
        path = path or self.state_path
        if not path:
            return
        folder = os.path.dirname(os.path.abspath(path))
        os.makedirs(folder, exist_ok=True)
        atomic_write_json(path, self.to_state(), indent=1)

    @classmethod
    def from_state(
        cls,
        state: dict,
        *,
        state_path: str | None = None,
        nominal=None,
        previous: dict | None = None,
        sample_rate_hz: float | None = None,
    ) -> P1Guide:
        """Resume: captured steps are kept; the current step restarts from "noise"."""
        if state.get("version") != STATE_VERSION or state.get("procedure") != cls.procedure:
            raise ValueError("not a P1 guide state (version or procedure differ)")
        _check_state(state)
        steps = [Step(**{**s, "direction": tuple(s["direction"])}) for s in state["steps"]]
        g = cls(
            sample_rate_hz=sample_rate_hz or state["sample_rate_hz"],
            accel_unit=state["accel_unit"],
            device_id=state["device_id"],
            config=GuideConfig(**state["config"]),
            positions=[s.name for s in steps],
            nominal=nominal,
            previous=previous,
            site=state.get("site"),
            g_mps2=state.get("g_mps2"),
            state_path=state_path,
        )
        g.steps = steps
        g.started = state.get("started", g.started)
        g.index = int(state.get("index", 0))
        if g._previous is None:
            g._model = g._build_model()
        if state.get("phase") == "aborted" or all(s.status != "pending" for s in steps):
            # an aborted run resumes where it stopped; a finished one stays finished
            if all(s.status != "pending" for s in steps):
                g.phase = "done"
        if g.step is not None and g.step.status != "pending" and g.phase != "done":
            g._next_pending()
        return g

    @classmethod
    def load(cls, path: str, **kw) -> P1Guide:
        with open(path, encoding="utf-8") as fh:
            state = json.load(fh)
        return cls.from_state(state, state_path=path, **kw)


_STEP_KEYS = {f.name for f in fields(Step)}
_STATUSES = ("pending", "captured", "skipped")


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _check_state(state: dict) -> None:
    """Refuse a resume state that this code did not write (edited, damaged) before any of it
    is used: a ValueError ``resume state: <what>`` naming the field. Left unchecked, an index
    beyond the steps crashed the TUI at its first update and a text mean reached the fit."""

    def bad(what: str):
        raise ValueError(f"resume state: {what} (start anew; the file is replaced)")

    steps = state.get("steps")
    if not isinstance(steps, list) or not steps or not all(isinstance(st, dict) for st in steps):
        bad("steps is not a list of positions")
    for i, st in enumerate(steps, 1):
        unknown, missing = set(st) - _STEP_KEYS, {"name", "instruction", "direction"} - set(st)
        if unknown or missing:
            bad(f"step {i}: unknown keys {sorted(unknown)}, missing {sorted(missing)}")
        vec = st["direction"]
        if not isinstance(st["name"], str) or not (isinstance(vec, list) and len(vec) == 3 and all(map(_finite, vec))):
            bad(f"step {i}: name or direction")
        if st.get("status", "pending") not in _STATUSES:
            bad(f"step {i}: status {st.get('status')!r}")
        for key in ("mean", "std"):
            v = st.get(key)
            needed = key == "mean" and st.get("status") == "captured"
            if (v is None and needed) or (
                v is not None and not (isinstance(v, list) and len(v) == 3 and all(map(_finite, v)))
            ):
                bad(f"step {i}: {key} {v!r}")
        if not isinstance(st.get("n", 0), int) or st.get("n", 0) < 0:
            bad(f"step {i}: n")
        for key in ("temp_c", "t_s", "t0_s"):
            if st.get(key) is not None and not _finite(st[key]):
                bad(f"step {i}: {key}")
    index = state.get("index", 0)
    if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(steps):
        bad(f"index {index!r} (steps 0..{len(steps) - 1})")
    config = state.get("config")
    known = {f.name for f in fields(GuideConfig)}
    if (
        not isinstance(config, dict)
        or not set(config) <= known
        or not all(_finite(v) and v >= 0 for v in config.values())
    ):
        bad(f"config {config!r}")
    rate = state.get("sample_rate_hz")
    if not (_finite(rate) and rate > 0):
        bad(f"sample_rate_hz {rate!r}")
    if not isinstance(state.get("accel_unit"), str) or not isinstance(state.get("device_id"), str):
        bad("accel_unit or device_id")


def position_drawing(direction) -> list[str]:
    """A small ASCII drawing of the unit on the table for an "up" direction (body frame).

    Axis-aligned positions show a box with the up face labelled; 45° positions show the
    unit on its edge with the two raised axes.
    """
    d = np.asarray(direction, dtype=float)
    names = ("X", "Y", "Z")
    big = np.flatnonzero(np.abs(d) > 0.9)
    if len(big) == 1:
        i = int(big[0])
        up = ("+" if d[i] > 0 else "-") + names[i]
        front = "+" + names[(i + 1) % 3]
        return [
            "       up",
            "    +--^-----+",
            f"   /   {up:<3}   /|",
            "  +--------+ |",
            f"  |  {front:<3}   | +",
            "  |  front |/ ",
            "  +--------+  ",
            " ============ table",
        ]
    raised = [k for k in range(3) if abs(d[k]) > 0.3]
    level = [k for k in range(3) if abs(d[k]) <= 0.3]
    a, b = raised[0], raised[1]
    la = ("+" if d[a] > 0 else "-") + names[a]
    lb = ("+" if d[b] > 0 else "-") + names[b]
    lv = names[level[0]] if level else "?"
    return [
        f"  {la:>3} up 45°  {lb} up 45°",
        "        /\\",
        "       /  \\",
        f"      / {lv:^2} \\   {lv} level",
        "      \\    /",
        "       \\  /",
        "        \\/  on its edge",
        " ============ table",
    ]


class ScriptedOperator:
    """The demo's operator: follows the prompts.

    ``reaction_s`` (device time) after a new position is asked, it calls ``place(name)``.
    ``mistakes`` maps an asked position to a wrong one placed first (for ``mistake_s``), so
    a newcomer sees the orientation indicator catch it.
    """

    def __init__(
        self, place, *, reaction_s: float = 1.0, mistakes: dict[str, str] | None = None, mistake_s: float = 4.0
    ):
        self.place = place
        self.reaction_s = reaction_s
        self.mistakes = dict(mistakes or {})
        self.mistake_s = mistake_s
        self._asked: str | None = None
        self._plan: list[tuple[float, str]] = []

    def step(self, guide: P1Guide, t_s: float) -> str | None:
        """Call after each update; returns the position placed now, if any."""
        if guide.phase not in ("place", "settle", "average") or guide.step is None or not math.isfinite(t_s):
            return None
        name = guide.step.name
        if name != self._asked:
            self._asked = name
            wrong = self.mistakes.pop(name, None)
            if wrong:
                self._plan = [(t_s + self.reaction_s, wrong), (t_s + self.reaction_s + self.mistake_s, name)]
            else:
                self._plan = [(t_s + self.reaction_s, name)]
        if self._plan and t_s >= self._plan[0][0]:
            _, where = self._plan.pop(0)
            self.place(where)
            return where
        return None


def live_device(*, seed: int, rate_hz: float, reference: bool = False):
    """The simulated bench device for this procedure (``station.sources.SimSource``'s): the
    unit held where the operator puts it (``solvers.simulate.LiveImu``)."""
    from solvers.simulate import LiveImu

    return LiveImu(procedure="accel-tabletop", seed=seed, rate_hz=rate_hz, hold_s=1e9, reference=reference)


def headless_demo(src, now: list, *, average_s: float, out, max_device_s: float = 900.0) -> P1Guide:
    """``station demo --headless``: the scripted operator (one wrong face on purpose) runs
    P1 on the started simulated device ``src``, whose clock reads ``now[0]`` (advanced here,
    as fast as the CPU allows); event lines go to ``out``. Returns the finished guide."""
    from station.errors import UnsupportedError

    guide = P1Guide(
        sample_rate_hz=src.rate_hz,
        accel_unit=src.units["accel_unit"],
        device_id=src.device_id,
        config=GuideConfig(average_s=average_s, settle_s=1.0),
        nominal=src.nominal,
        site=src.site,
    )
    operator = ScriptedOperator(src.place, reaction_s=1.0, mistakes={"y_down": "y_up"}, mistake_s=6.0)
    last_phase = None
    last_capture_t = 0.0
    while guide.phase not in ("done", "aborted") and now[0] < max_device_s:
        now[0] += 0.05
        b = src.drain()
        if b is None:
            continue
        st = guide.update(b.t_s, b.accel, b.gyro, b.temp_c)
        operator.step(guide, st.t_s)
        for kind, detail in guide.take_events():
            print(f"{st.t_s:7.1f} s  {kind:<9} {detail}", file=out)
            last_capture_t = st.t_s
        # the unit still sits at the previous position right after a capture: not a mistake
        if st.wrong_face and st.is_still and st.t_s - last_capture_t > 4.0 and last_phase != "wrong":
            print(f"{st.t_s:7.1f} s  wrong face up at {st.step_name} ({st.angle_deg:.0f}°)", file=out)
            last_phase = "wrong"
        elif not st.wrong_face and last_phase == "wrong":
            last_phase = None
    if guide.phase != "done":
        raise UnsupportedError(f"demo did not finish within {max_device_s:g} s of device time")
    return guide
