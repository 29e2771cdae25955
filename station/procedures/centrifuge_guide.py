"""The guided P2 (centrifuge, Wang & Li 2021) run as a UI-free state machine.

A step list: for each mounting orientation ``k`` (default the 20 attitudes of
``solvers.simulate.centrifuge_orientations``) and each speed (default 2π, 4π, 6π rad/s),
"mount in orientation k, spin at ω rad/s". Each step is filled either

- **live**: the station averages the accelerometer stream once its output is steady
  (``solvers.stillness.StillnessTracker`` on the accelerometer alone: on a centrifuge
  "still" means a constant output, the turning gyro is left out) **and** the table rate
  the gyro measures is within ``speed_tol`` of the asked speed (a stopped or wrongly set
  centrifuge is never a row). The row's speed is the set point the gyro confirmed (a
  centrifuge's controller holds it far better than a MEMS gyro measures it: 1e-3 rad/s of
  noise per sample would add more scatter to ``|f|`` than the accelerometer's own); the
  gyro's mean over the average is kept beside it (``rate_gyro_rad_s``). After each capture
  the output must change (the operator remounts or changes speed: the detector sees
  motion) before the next step can be captured, so one steady run is never taken twice (the same holds for the first step after the initial
  rest: the stopped centrifuge is not a row). Without a gyro in a known unit the rate
  cannot be checked: live rows then carry the asked speed, and the capture says so
  (``speed_source: set point``); or
- **manual**: the operator types the three averaged outputs and the measured speed
  (:func:`parse_manual`: decimal numbers only, a speed > 0; one clear message otherwise).

Phases: ``noise`` (initial rest, the centrifuge stopped: the detector learns the noise),
``change`` (waiting for the output to change after a capture), ``place`` (waiting for a
steady output), ``settle``, ``average`` (countdown), ``done``, ``aborted``. ``skip``,
``redo(index)``, ``select(index)``, ``abort``. Times are the samples' own ``t_s``.

Rows that disagree are named at once: a row whose speed is off the asked one by more
than ``speed_tol``, and, from ``MIN_FIT_ROWS`` rows on, every row the model's robust screen
(``solvers.centrifuge.screen_rows``, the one the P2 fit uses) sets apart from the others
(event ``disagree``; :attr:`CentrifugeGuide.disagreeing` maps step index to why).

At the end (or earlier, ``MIN_FIT_ROWS`` rows) :meth:`CentrifugeGuide.capture` is the P2
table of averages (``position, speed_rad_s, ax, ay, az`` and, when every row was averaged
live, ``n, ax_std, ay_std, az_std``; metadata ``procedure: accel-centrifuge``,
``radius_m``, ``g_mps2`` (as the operator entered them), ``accel_unit``,
``speed_source``) for ``station.calibrate.calibrate_capture``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from station.procedures.guide_base import GuideBase, started_utc, stillness_tracker

PHASES = ("noise", "change", "place", "settle", "average", "done", "aborted")
STATUSES = ("pending", "captured", "skipped")
DEFAULT_SPEEDS_RAD_S = (2 * math.pi, 4 * math.pi, 6 * math.pi)  # Wang & Li: 1, 2, 3 rev/s
MIN_FIT_ROWS = 10  # the exact fit has 9 coefficients (S, b, D) and needs more rows than that
_NUMBER = re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?")


class ManualEntryError(ValueError):
    """A manual entry that is not four numbers (one line for the operator)."""


def parse_manual(ax: str, ay: str, az: str, speed_rad_s: str) -> tuple[float, float, float, float]:
    """Four typed fields → (ax, ay, az, speed_rad_s). Decimal numbers only (``1.5``,
    ``-0.2e-3``); the speed must be > 0. Raises ManualEntryError naming the first bad field."""
    out = []
    for name, text in (("ax", ax), ("ay", ay), ("az", az), ("speed", speed_rad_s)):
        s = (text or "").strip()
        if not s:
            raise ManualEntryError(f"{name}: empty; type the averaged value")
        if not _NUMBER.fullmatch(s):
            raise ManualEntryError(f"{name}: {s!r} is not a number (digits, '.', '-', 'e' only)")
        v = float(s)
        if not math.isfinite(v):
            raise ManualEntryError(f"{name}: {s!r} is out of range")
        out.append(v)
    if out[3] <= 0:
        raise ManualEntryError(f"speed: {speed_rad_s.strip()} rad/s; the centrifuge speed must be > 0")
    return out[0], out[1], out[2], out[3]


def parse_positive(text: str, name: str) -> float:
    """A typed radius or local g: a decimal number > 0 (ManualEntryError otherwise)."""
    t = (text or "").strip()
    if not _NUMBER.fullmatch(t) or not math.isfinite(float(t)) or float(t) <= 0:
        raise ManualEntryError(f"{name}: {t!r} is not a positive number")
    return float(t)


@dataclass
class CentrifugeConfig:
    """speeds_rad_s: the speeds asked at each orientation [rad/s]. n_orientations: mounting
    attitudes (the paper's 20). radius_m: centrifuge radius to the triad [m]. g_mps2:
    local gravity [m/s²]. average_s / settle_s: averaging time and steady time before it
    [s]. init_rest_s / window_s: the stillness detector's initial rest and window [s].
    speed_tol: largest relative difference between the measured table rate and the asked
    speed for a row (default 2 %)."""

    speeds_rad_s: tuple[float, ...] = DEFAULT_SPEEDS_RAD_S
    n_orientations: int = 20
    radius_m: float = 1.0
    g_mps2: float = 9.8
    average_s: float = 60.0
    settle_s: float = 2.0
    init_rest_s: float = 2.0
    window_s: float = 0.5
    speed_tol: float = 0.02

    def __post_init__(self) -> None:
        self.speeds_rad_s = tuple(float(w) for w in self.speeds_rad_s)
        if not self.speeds_rad_s or not all(math.isfinite(w) and w > 0 for w in self.speeds_rad_s):
            raise ValueError(f"speeds_rad_s must be positive numbers, got {self.speeds_rad_s!r}")
        if not (isinstance(self.n_orientations, int) and self.n_orientations >= 1):
            raise ValueError(f"n_orientations must be a positive integer, got {self.n_orientations!r}")
        for name in ("radius_m", "g_mps2", "average_s", "init_rest_s", "window_s", "speed_tol"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {getattr(self, name)!r}")
        if not (math.isfinite(float(self.settle_s)) and self.settle_s >= 0):
            raise ValueError(f"settle_s must be >= 0, got {self.settle_s!r}")


@dataclass
class CentrifugeStep:
    """One row to fill: orientation ``k`` (1-based) at ``speed_rad_s`` (asked)."""

    orientation: int
    speed_rad_s: float
    status: str = "pending"
    how: str = ""  # "live" or "manual" once captured
    values: list[float] | None = None  # averaged ax, ay, az (raw accel unit)
    speed_measured_rad_s: float = math.nan  # the row's speed: the confirmed set point, or as typed
    rate_gyro_rad_s: float = math.nan  # live rows: the gyro's mean table rate over the average
    std: list[float] | None = None
    n: int = 0

    @property
    def label(self) -> str:
        return f"{self.orientation:2d} @ {self.speed_rad_s:5.2f} rad/s"

    @property
    def name(self) -> str:
        """Short, for the step list: orientation @ speed."""
        return f"{self.orientation:2d} @ {self.speed_rad_s:5.2f}"

    @property
    def prompt(self) -> str:
        return (
            f"Mount in orientation {self.orientation}, spin at {self.speed_rad_s:.2f} rad/s "
            f"({self.speed_rad_s / (2 * math.pi):.3g} rev/s)"
        )


def centrifuge_steps(config: CentrifugeConfig) -> list[CentrifugeStep]:
    """Orientation by orientation (a remount is slow), every speed at each."""
    return [CentrifugeStep(k, w) for k in range(1, config.n_orientations + 1) for w in config.speeds_rad_s]


@dataclass(frozen=True)
class CentrifugeStatus:
    phase: str
    index: int | None
    calibrating: bool
    is_still: bool
    still_for_s: float
    level: float
    settle_left_s: float
    countdown_s: float
    progress: float
    raw: tuple[float, float, float]  # recent accelerometer mean (raw unit)
    table_rate_rad_s: float  # |gyro| in rad/s when the gyro unit is known, else NaN
    at_speed: bool  # the measured rate is within speed_tol of the asked speed (True when unknown)
    n_captured: int
    n_skipped: int
    t_s: float
    message: str


_GYRO_RAD_S = {"rad/s": 1.0, "deg/s": math.pi / 180.0}


class CentrifugeGuide(GuideBase):
    procedure = "accel-centrifuge"

    def __init__(
        self,
        *,
        sample_rate_hz: float,
        units: dict,
        device_id: str = "",
        config: CentrifugeConfig | None = None,
        steps: list[CentrifugeStep] | None = None,
    ):
        self.config = config or CentrifugeConfig()
        self.sample_rate_hz = float(sample_rate_hz)
        self.units = dict(units)
        self.device_id = device_id
        self.steps = steps if steps is not None else centrifuge_steps(self.config)
        self.started = started_utc()
        self.tracker = stillness_tracker(self.config, self.sample_rate_hz)
        self.phase = "noise"
        self.index: int | None = 0
        self._need_change = True  # the rest is the stopped centrifuge: spin up first
        self.disagreeing: dict[int, str] = {}  # step index -> why the row disagrees
        self._rate_known = _GYRO_RAD_S.get(self.units.get("gyro_unit") or "") is not None
        self._events: list[tuple[str, str]] = []
        self._message = "Centrifuge stopped: hold still while the noise is measured"
        self._last = None
        self._avg_reset()

    # ------------------------------------------------------------ bookkeeping

    def _avg_reset(self) -> None:
        self._sum = np.zeros(3)
        self._sq = np.zeros(3)
        self._n = 0
        self._rate_sum = 0.0
        self._rate_n = 0
        self._t0 = math.nan
        self._t1 = math.nan

    @property
    def step(self) -> CentrifugeStep | None:
        return None if self.index is None else self.steps[self.index]

    @property
    def n_captured(self) -> int:
        return sum(s.status == "captured" for s in self.steps)

    @property
    def can_fit(self) -> bool:
        return self.n_captured >= MIN_FIT_ROWS

    # ------------------------------------------------------------ live stream

    def update(self, t_s, accel, gyro=None, temp_c=None) -> CentrifugeStatus:
        t_s = np.asarray(t_s, float)
        if len(t_s) == 0 or self.phase in ("done", "aborted"):
            return self.status()
        accel = np.asarray(accel, float).reshape(-1, 3)
        gyro = None if gyro is None else np.asarray(gyro, float).reshape(-1, 3)
        f = _GYRO_RAD_S.get(self.units.get("gyro_unit") or "")
        if gyro is None or f is None or not np.isfinite(gyro).any():
            rates = np.full(len(t_s), np.nan)  # no rate measured (the set point is trusted)
        else:
            rates = np.linalg.norm(gyro, axis=1) * f
        step = max(1, int(self.sample_rate_hz * 0.1))
        st = None
        for a in range(0, len(t_s), step):
            sl = slice(a, a + step)
            st = self.tracker.update(t_s[sl], accel[sl], None)
            self._advance(st, t_s[sl], accel[sl], rates[sl])
            if self.phase in ("done", "aborted"):
                break
        k = min(len(t_s), step)
        raw = np.nanmean(accel[-k:], axis=0)
        rate = math.nan
        if gyro is not None and f is not None and np.isfinite(gyro[-k:]).any():
            rate = float(np.linalg.norm(np.nanmean(gyro[-k:], axis=0))) * f
        self._last = (raw, rate, float(t_s[-1]), st)
        return self.status()

    def _off_speed(self, rate: float) -> bool:
        """True when the measured table rate is known and not the asked speed."""
        s = self.step
        if s is None or not math.isfinite(rate):
            return False
        return abs(rate - s.speed_rad_s) > self.config.speed_tol * s.speed_rad_s

    def _advance(self, st, t, a, rates) -> None:
        c = self.config
        if self.index is None:
            return
        if st.calibrating:
            self.phase = "noise"
            return
        if self._need_change:
            if st.is_still:
                self.phase = "change"
                self._message = f"{self.step.prompt}: waiting for the change"
                return
            self._need_change = False
        ok = np.isfinite(rates)
        rate = float(np.mean(rates[ok])) if ok.any() else math.nan
        off = self._off_speed(rate)
        if self.phase == "average":
            if not st.is_still or off:
                self._avg_reset()
                self.phase = "place"
                self._message = (
                    "The output changed during the average: it starts again when steady"
                    if not off
                    else f"The table rate left the asked speed ({rate:.3f} rad/s): the average starts again at speed"
                )
                self._events.append(("restarted", self.step.label))
                return
            self._avg_add(t, a, rates)
            if self._t1 - self._t0 >= c.average_s:
                self._capture_live()
            return
        if off:
            self.phase = "place"
            self._message = (
                f"{self.step.prompt}; the table turns at {rate:.3f} rad/s: not at speed yet"
                if st.is_still
                else f"{self.step.prompt}; waiting for the speed"
            )
            return
        if st.is_still and st.still_for_s >= c.settle_s:
            self.phase = "average"
            self._avg_reset()
            self._message = f"{self.step.prompt}: averaging, keep the speed steady"
            self._avg_add(t, a, rates)
        elif st.is_still:
            self.phase = "settle"
            self._message = f"{self.step.prompt}: steady, averaging starts shortly"
        else:
            self.phase = "place"
            self._message = f"{self.step.prompt}; waiting for a steady output"

    def _avg_add(self, t, a, rates) -> None:
        ok = np.all(np.isfinite(a), axis=1)
        r = rates[ok & np.isfinite(rates)]
        self._rate_sum += float(r.sum())
        self._rate_n += len(r)
        a = a[ok]
        if not len(a):
            return
        if not math.isfinite(self._t0):
            self._t0 = float(t[ok][0])
        self._t1 = float(t[ok][-1])
        self._sum += a.sum(axis=0)
        self._sq += (a * a).sum(axis=0)
        self._n += len(a)

    def _capture_live(self) -> None:
        s = self.step
        mean = self._sum / self._n
        var = np.maximum(self._sq / self._n - mean**2, 0.0) * self._n / max(self._n - 1, 1)
        s.values, s.std, s.n = [float(x) for x in mean], [float(x) for x in np.sqrt(var)], int(self._n)
        measured = self._rate_sum / self._rate_n if self._rate_n else math.nan
        s.speed_measured_rad_s, s.rate_gyro_rad_s = s.speed_rad_s, measured
        s.status, s.how = "captured", "live" if math.isfinite(measured) else "live-set-point"
        self._events.append(("captured", s.label))
        self._after_capture(f"Captured {s.label.strip()}")

    def _after_capture(self, said: str) -> None:
        self._avg_reset()
        self._need_change = True
        self._check_rows()
        bad = self.disagreeing.get(self.index) if self.index is not None else None
        self._next_pending(said)
        if bad:
            self._message = f"{said}: DISAGREES ({bad}); r redoes it. " + self._message.split(". ", 1)[-1]

    def _check_rows(self) -> None:
        """Name the rows that disagree (module docstring); events for newly named ones."""
        from solvers.centrifuge import norm_target, screen_rows
        from solvers.errors import SolverError

        c = self.config
        found: dict[int, str] = {}
        idx = [i for i, s in enumerate(self.steps) if s.status == "captured"]
        for i in idx:
            s = self.steps[i]
            seen = s.rate_gyro_rad_s if math.isfinite(s.rate_gyro_rad_s) else s.speed_measured_rad_s
            if abs(seen - s.speed_rad_s) > c.speed_tol * s.speed_rad_s:
                found[i] = f"speed {seen:.4g} rad/s, asked {s.speed_rad_s:.4g}"
        if len(idx) >= MIN_FIT_ROWS:
            N = np.array([self.steps[i].values for i in idx], float)
            w = np.array([self.steps[i].speed_measured_rad_s for i in idx], float)
            try:
                with np.errstate(all="ignore"):  # few rows: the first fits can be wild
                    scr = screen_rows(N, norm_target(w, c.radius_m, c.g_mps2))
            except (SolverError, np.linalg.LinAlgError, ValueError):
                scr = None
            if scr is not None:
                for j in np.flatnonzero(~scr.used):
                    i = idx[int(j)]
                    found.setdefault(
                        i,
                        f"|f| off the model by {scr.residuals[j]:+.3g} g, "
                        f"{abs(scr.residuals[j]) / max(scr.scale, 1e-300):.0f}x the others' spread"
                        + (f"; {scr.hints[int(j)]}" if int(j) in scr.hints else ""),
                    )
        for i, why in found.items():
            if i not in self.disagreeing:
                self._events.append(("disagree", f"{self.steps[i].label.strip()}: {why}"))
        self.disagreeing = found

    def _next_pending(self, said: str) -> None:
        n = len(self.steps)
        start = 0 if self.index is None else self.index
        for j in list(range(start + 1, n)) + list(range(0, start + 1)):
            if self.steps[j].status == "pending":
                self.index = j
                self.phase = "change" if self._need_change else "place"
                self._message = f"{said}. Next: {self.steps[j].prompt}"
                return
        self.index = None
        self.phase = "done"
        self._message = f"{said}. All steps done: {self.n_captured} captured"
        self._events.append(("done", ""))

    # ------------------------------------------------------------ operator

    def enter_manual(self, ax: str, ay: str, az: str, speed_rad_s: str) -> CentrifugeStep:
        """The operator's own averages for the current step (strings as typed).
        Raises ManualEntryError (nothing changes) on bad input."""
        if self.index is None or self.phase in ("done", "aborted"):
            raise ManualEntryError("no step to fill: the run is over")
        v = parse_manual(ax, ay, az, speed_rad_s)
        s = self.step
        s.values, s.speed_measured_rad_s, s.std, s.n = list(v[:3]), v[3], None, 0
        s.status, s.how = "captured", "manual"
        self._events.append(("captured", s.label + " (typed)"))
        self._after_capture(f"Entered {s.label.strip()}")
        return s

    def skip(self) -> None:
        if self.index is None or self.phase in ("done", "aborted"):
            return
        s = self.step
        s.status = "skipped"
        self._events.append(("skipped", s.label))
        self._avg_reset()
        self._next_pending(f"Skipped {s.label.strip()}")

    def redo(self, index: int | None = None) -> None:
        """Clear a step (default: the last captured or skipped one) and make it current; the
        output need not change first (the operator chose it)."""
        if self.phase == "aborted":
            return
        if index is None:
            done = [i for i, s in enumerate(self.steps) if s.status != "pending"]
            if not done:
                return
            index = done[-1] if self.index is None else max((i for i in done if i < self.index), default=done[-1])
        s = self.steps[index]
        s.status, s.how, s.values, s.std, s.n, s.speed_measured_rad_s = "pending", "", None, None, 0, math.nan
        s.rate_gyro_rad_s = math.nan
        self._check_rows()
        self.select(index)
        self._message = f"Redo: {s.prompt}"

    def select(self, index: int) -> None:
        if self.phase == "aborted" or not 0 <= index < len(self.steps):
            return
        if self.steps[index].status != "pending":
            self.redo(index)
            return
        self.index = index
        self._need_change = False
        self._avg_reset()
        st = self.tracker.state
        self.phase = "noise" if st.calibrating else "place"
        self._message = self.steps[index].prompt

    def finish(self) -> bool:
        """End now with what is captured (at least MIN_FIT_ROWS rows)."""
        if not self.can_fit or self.phase == "aborted":
            return False
        self.index = None
        self.phase = "done"
        self._message = f"Finished early: {self.n_captured} captured"
        self._events.append(("done", "early"))
        return True

    # ------------------------------------------------------------ read-outs

    def status(self) -> CentrifugeStatus:
        c = self.config
        raw, rate, t, st = self._last if self._last else (np.full(3, np.nan), math.nan, math.nan, None)
        st = st if st is not None else self.tracker.state
        rec = (self._t1 - self._t0) if self.phase == "average" and math.isfinite(self._t0) else 0.0
        return CentrifugeStatus(
            phase=self.phase,
            index=self.index,
            calibrating=st.calibrating,
            is_still=st.is_still,
            still_for_s=float(st.still_for_s),
            level=float(st.level),
            settle_left_s=max(c.settle_s - st.still_for_s, 0.0) if self.phase == "settle" else math.nan,
            countdown_s=max(c.average_s - rec, 0.0) if self.phase == "average" else math.nan,
            progress=min(rec / c.average_s, 1.0) if self.phase == "average" else 0.0,
            raw=tuple(float(x) for x in raw),
            table_rate_rad_s=rate,
            at_speed=not self._off_speed(rate),
            n_captured=self.n_captured,
            n_skipped=sum(s.status == "skipped" for s in self.steps),
            t_s=t,
            message=self._message,
        )

    def capture(self, extra_meta: dict | None = None):
        """The captured rows as a P2 table of averages (``station.capture.Capture``)."""
        from station.capture import Capture

        rows = [s for s in self.steps if s.status == "captured"]
        v = np.array([s.values for s in rows], float).reshape(-1, 3)
        cols = {
            "position": np.array([str(s.orientation) for s in rows], dtype=object),
            "speed_rad_s": np.array([s.speed_measured_rad_s for s in rows], float),
            "ax": v[:, 0],
            "ay": v[:, 1],
            "az": v[:, 2],
        }
        if any(math.isfinite(s.rate_gyro_rad_s) for s in rows):
            cols["rate_gyro_rad_s"] = np.array([s.rate_gyro_rad_s for s in rows], float)
        if rows and all(s.how.startswith("live") and s.n > 1 for s in rows):
            sd = np.array([s.std for s in rows], float)
            cols.update(
                {"n": np.array([s.n for s in rows], float), "ax_std": sd[:, 0], "ay_std": sd[:, 1], "az_std": sd[:, 2]}
            )
        c = self.config
        meta = {
            "station-capture": "1",
            "procedure": self.procedure,
            "device": self.device_id or "unknown",
            "accel_unit": self.units.get("accel_unit") or "raw",
            "radius_m": repr(float(c.radius_m)),
            "g_mps2": repr(float(c.g_mps2)),
            "date": self.started[:10],
        }
        if any(s.how == "manual" for s in rows):
            meta["manual_rows"] = str(sum(s.how == "manual" for s in rows))
        hows = {s.how for s in rows}
        meta["speed_source"] = (
            "; ".join(
                text
                for how, text in (
                    (
                        "live",
                        f"set point, confirmed by the gyro on the table within "
                        f"{100 * self.config.speed_tol:g} % (its mean in rate_gyro_rad_s)",
                    ),
                    ("live-set-point", "set point (no rate measured)"),
                    ("manual", "typed by the operator"),
                )
                if how in hows
            )
            or "none"
        )
        if self.disagreeing:
            meta["rows_disagreeing"] = ", ".join(self.steps[i].label.strip() for i in sorted(self.disagreeing))
        meta.update({k: str(x) for k, x in (extra_meta or {}).items()})
        return Capture(meta=meta, columns=cols)


@dataclass
class CentrifugeOperator:
    """The demo's operator: when the guide asks for a step, mounts and spins the simulated
    centrifuge to it (``place("k@ω")``), after ``reaction_s`` of the samples' clock."""

    place: object
    reaction_s: float = 0.5
    _asked: tuple | None = field(default=None)
    _at: float = -math.inf

    def step(self, guide: CentrifugeGuide, t_s: float) -> str | None:
        s = guide.step
        if s is None or guide.phase in ("noise", "done", "aborted") or not math.isfinite(t_s):
            return None
        key = (s.orientation, s.speed_rad_s)
        if key != self._asked:
            self._asked, self._at = key, t_s + self.reaction_s
            return None
        if self._at is not None and t_s >= self._at:
            self._at = None
            name = f"{s.orientation}@{s.speed_rad_s!r}"
            self.place(name)
            return name
        return None


def mounting_axes(k: int, n_orientations: int = 20) -> np.ndarray:
    """Orientation ``k`` (1-based) of the station's mounting set
    (``solvers.simulate.centrifuge_orientations``): rows are the triad's x, y, z input axes
    in the table frame (radial outward, tangential along the turn, up)."""
    from solvers.simulate import centrifuge_orientations

    return centrifuge_orientations(n_orientations)[k - 1].T


def mounting_drawing(k: int, n_orientations: int = 20) -> list[str]:
    """What "orientation k" means: the triad's axes seen from above and from the side of
    the arm, and each axis's direction cosines (out along the arm, along the turn, up).

    In each view the centre ``o`` is the triad, the arm runs to the right (to the rim);
    an axis letter sits where the axis points, capital when it points toward the viewer
    (up in the top view, against the turn in the side view). Five lines."""
    axes = mounting_axes(k, n_orientations)

    def view(i: int, j: int, toward: int, sign: float) -> list[str]:
        grid = [[" "] * 9 for _ in range(3)]
        grid[1] = list("····o····")
        for a in range(3):
            col = 4 + int(round(4 * axes[a, i]))
            row = 1 - int(round(1 * axes[a, j] * 1.4))
            row = min(max(row, 0), 2)
            name = "xyz"[a]
            ch = name.upper() if sign * axes[a, toward] > 0 else name
            while grid[row][col] not in (" ", "·") and col < 8:
                col += 1
            grid[row][col] = ch
        return ["".join(r) for r in grid]

    top = view(0, 1, 2, 1.0)  # from above: right = out, up-screen = along the turn
    side = view(0, 2, 1, -1.0)  # from behind the turn: right = out, up-screen = up
    cos = [f" {'xyz'[a]}  {axes[a, 0]:+.2f} {axes[a, 1]:+.2f} {axes[a, 2]:+.2f}" for a in range(3)]
    return [
        f"{'above ↑turn':<12}{'side ↑up':<12}axis  out  turn   up",
        f"{top[0]:<12}{side[0]:<12}{cos[0]}",
        f"{top[1] + '→':<12}{side[1] + '→':<12}{cos[1]}",
        f"{top[2]:<12}{side[2]:<12}{cos[2]}",
        "o the triad, → the arm to the rim, CAPITAL toward you",
    ]


# ---------------------------------------------------------------- the simulated bench


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
    in the table frame (radial out, tangential, up) is ``(−ω²R/g, 0, 1)`` g
    (``solvers.models.accel.centrifuge_specific_force_g``, as the simulator's); the forward
    model is ``solvers.models.accel.forward``. The gyro reads the
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
        self._i = 0  # samples produced
        self._anchor_i, self._anchor_t_s = 0, 0.0  # sample _anchor_i is at device time _anchor_t_s
        self.rate_hz, self.radius_m, self.g_mps2 = float(rate_hz), float(radius_m), float(g_mps2)
        self.noise_g, self.ramp_s, self.handle_s = noise_g, ramp_s, handle_s
        self.speed_error = 1e-8
        self.rng = np.random.default_rng(seed + 1)
        self.device_id = f"SIM-CFG-{seed:04d}"
        self.units = {"accel_unit": "g", "gyro_unit": "rad/s"}
        self.site: dict = {}
        self.positions = [f"{k}@0" for k in range(1, 21)]
        self._plan = [(-math.inf, 1, 0.0, 1, 0.0, "steady")]  # (t0, k0, w0, k1, w1, kind)
        self.k, self.w = 1, 0.0

    @property
    def rate_hz(self) -> float:
        return self._rate_hz

    @rate_hz.setter
    def rate_hz(self, hz: float) -> None:
        # `$STC,RATE` changes the sample period, not the device's clock: the next sample comes
        # one new period after the last (before, sample i was stamped i / rate, and the clock
        # jumped on by the rates' ratio, or back, which a reader takes for a restart)
        if self._i:
            self._anchor_t_s = self._t_of(self._i - 1) + 1.0 / float(hz)
            self._anchor_i = self._i
        self._rate_hz = float(hz)

    def _t_of(self, i):
        """Device time (s) of sample(s) i."""
        return self._anchor_t_s + (np.asarray(i, float) - self._anchor_i) / self._rate_hz

    def truth(self) -> dict:
        return {k: v.tolist() for k, v in self.params.items()}

    def set_orientation(self, name: str) -> None:
        k_s, _, w_s = str(name).partition("@")
        try:
            k, w = int(k_s), float(w_s or 0.0)
        except ValueError:
            k, w = 0, math.nan  # said below, as any setting out of range
        if not 1 <= k <= len(self.orients) or not (math.isfinite(w) and w >= 0):
            shown = str(name) if len(str(name)) <= 24 else str(name)[:21] + "..."
            raise ValueError(
                f"unknown centrifuge setting {shown!r}: 'k@omega', mounting k in 1..{len(self.orients)} at omega rad/s "
                "(e.g. 3@12.5; 3 alone stands still)"
            )
        t = float(self._t_of(self._i))
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

        t = self._t_of(self._i + np.arange(n))
        self._i += n
        k, w, handled = self._state(t)
        f = np.empty((n, 3))
        g = np.empty((n, 3))
        for kk in np.unique(k):
            sel = k == kk
            C_t_b = self.orients[kk - 1]
            ws = w[sel]
            f_t = accel_model.centrifuge_specific_force_g(ws, self.radius_m, self.g_mps2)
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


def live_device(*, seed: int, rate_hz: float, reference: bool = False) -> CentrifugeImu:
    """The simulated P2 bench (``station.sources.SimSource``'s device for this procedure)."""
    return CentrifugeImu(seed=seed, rate_hz=rate_hz)
