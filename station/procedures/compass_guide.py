"""The guided P3 (compass) sweep as a UI-free state machine.

The operator turns the unit slowly through every orientation while the station records
the time series (t, accelerometer, gyro, magnetometer, temperature). Progress is the
**sphere coverage the calibration checks**: ``solvers.detectors.FieldCoverage``, i.e.
``solvers.compass.coverage`` (share of the sphere within 30° of a visited field direction,
about the midrange centre) — the number ``solvers.compass.check_orientations`` refuses
below 40 %. :meth:`CompassGuide.coverage_map` draws the same measure on ``n_bands`` bands
uniform in z times ``n_sectors`` sectors in azimuth (filled where the cell lies within 30°
of a visited direction, half-filled where partly).

Phases: ``sweep`` (recording) → ``done`` when coverage ≥ ``target_coverage`` and at least
``min_s`` have been recorded (or the operator finishes early), ``aborted``. The recording
becomes a time-series :class:`station.capture.Capture` for ``calibrate_capture``
(``station/procedures/compass.py``). Times are the samples' own ``t_s``.

Live tilt and heading (what a bench engineer checks first: level reads 0°, heading follows
the turn): pitch and roll from the last 0.2 s of the accelerometer through its front end
(``station.procedures.accel_frontend``: the device's P1 calibration, else its declared
zero and scale; a raw unit with neither shows none), the tilt-compensated magnetic heading
of body x (``solvers.compass.heading_deg``; body x forward, y right, z down) from the field
corrected by the device's last compass calibration if given, else by the sweep's own
midrange centre (hard iron only) once every axis has been turned over, else uncorrected.
The front end goes into the capture's metadata, so the fit's per-position headings use it.
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass

import numpy as np

from solvers import compass as C
from solvers.compass import MIN_COVERAGE
from solvers.detectors import FieldCoverage
from solvers.frames import G_STANDARD_MPS2
from solvers.units import si_factor
from station.procedures.guide_base import GuideBase, recorded_columns, site_meta, started_utc

PHASES = ("sweep", "done", "aborted")


@dataclass
class CompassConfig:
    """target_coverage: coverage (``solvers.compass.coverage``, 0..1) that ends the sweep; at
    least the calibration's ``MIN_COVERAGE`` (0.40). min_s / max_s: recording length bounds
    [s]. n_bands x n_sectors: the drawn map."""

    target_coverage: float = 0.8
    min_s: float = 60.0
    max_s: float = 900.0
    n_bands: int = 6
    n_sectors: int = 12

    def __post_init__(self) -> None:
        if not MIN_COVERAGE <= self.target_coverage <= 1:
            raise ValueError(
                f"target_coverage must be in [{MIN_COVERAGE}, 1] (the calibration refuses "
                f"below {100 * MIN_COVERAGE:.0f} %), got {self.target_coverage!r}"
            )
        if not (self.min_s >= 0 and self.max_s > 0 and self.max_s >= self.min_s):
            raise ValueError("min_s and max_s must satisfy 0 <= min_s <= max_s, max_s > 0")
        if self.n_bands < 2 or self.n_sectors < 3:
            raise ValueError("need at least 2 bands and 3 sectors")


@dataclass(frozen=True)
class CompassStatus:
    phase: str
    coverage: float  # solvers.compass.coverage of the directions so far
    target: float
    enough: bool  # coverage >= the calibration's MIN_COVERAGE
    recorded_s: float
    n_samples: int
    field_raw: tuple[float, float, float]
    field_norm_raw: float
    turn_rate: float  # |gyro| in the gyro's raw unit
    t_s: float
    message: str
    pitch_deg: float = math.nan  # live tilt (NaN: no accelerometer front end)
    roll_deg: float = math.nan
    heading_deg: float = math.nan  # magnetic heading of body x (NaN: no tilt, or |pitch| too large)
    tilt_from: str = ""  # where the accelerometer's zero and scale came from ('' none)
    heading_from: str = ""  # the field correction in use


class CompassGuide(GuideBase):
    procedure = "compass"

    def __init__(
        self,
        *,
        sample_rate_hz: float,
        units: dict,
        device_id: str = "",
        site: dict | None = None,
        config: CompassConfig | None = None,
        accel_frontend=None,
        mag_calibration: dict | None = None,
    ):
        """accel_frontend: a ``station.procedures.accel_frontend.Frontend`` for a raw
        accelerometer (None: physical units, or no tilt). mag_calibration: the device's last
        accepted compass calibration record (``params.hard_iron``, ``soft_iron``) for the
        live heading (None: the sweep's midrange centre)."""
        self.config = config or CompassConfig()
        self.sample_rate_hz = float(sample_rate_hz)
        self.units = dict(units)
        self.frontend = accel_frontend
        if self.frontend is None:
            k = si_factor("accel", self.units.get("accel_unit"))
            if k is not None:
                from station.procedures.accel_frontend import Frontend

                self.frontend = Frontend(np.zeros(3), k * np.eye(3), f"{self.units['accel_unit']} (physical unit)")
        self.mag_cal = None
        if mag_calibration is not None:
            p = mag_calibration["params"]
            self.mag_cal = (
                np.asarray(p["soft_iron"], float),
                np.asarray(p["hard_iron"], float),
                f"compass calibration #{mag_calibration.get('id')}",
            )
        self.device_id = device_id
        self.site = dict(site or {})
        self.started = started_utc()
        self.phase = "sweep"
        self._events: list[tuple[str, str]] = []
        self._reset()

    def _reset(self) -> None:
        c = self.config  # noqa: F841
        self.field = FieldCoverage(self.sample_rate_hz)
        self._chunks: list[dict[str, np.ndarray]] = []
        self._n = 0
        self._t0 = math.nan
        self._t1 = math.nan
        self._last = None
        self._attitude = (math.nan, math.nan, math.nan, "", "")
        self._message = "Turn the unit slowly through every orientation (all faces up, all headings)"

    # ------------------------------------------------------------ cells

    @property
    def coverage(self) -> float:
        """``solvers.compass.coverage`` of the field directions so far (0..1)."""
        return self.field.fraction

    def coverage_map(self) -> list[str]:
        """Rows from +z (top) to -z: '█' the cell lies within 30° of a visited direction,
        '▒' partly, '·' not yet (the measure the percentage counts, drawn)."""
        c = self.config
        return [
            "".join("█" if x >= 0.75 else "▒" if x > 0 else "·" for x in row)
            for row in self.field.grid(c.n_bands, c.n_sectors)[::-1]
        ]

    # ------------------------------------------------------------ feeding

    def update(self, t_s, accel, gyro, mag, temp_c=None) -> CompassStatus:
        t_s = np.asarray(t_s, float)
        if len(t_s) == 0 or self.phase != "sweep":
            return self.status()
        accel, gyro, mag = (np.asarray(x, float).reshape(-1, 3) for x in (accel, gyro, mag))
        temp = np.full(len(t_s), np.nan) if temp_c is None else np.asarray(temp_c, float)
        self._chunks.append({"t": t_s, "a": accel, "g": gyro, "m": mag, "temp": temp})
        self._n += len(t_s)
        if not math.isfinite(self._t0):
            self._t0 = float(t_s[0])
        self._t1 = float(t_s[-1])
        self.field.update(mag)
        k = min(len(t_s), max(1, int(self.sample_rate_hz * 0.1)))
        self._last = (mag[-k:].mean(axis=0), float(np.linalg.norm(np.nanmean(gyro[-k:], axis=0))), self._t1)
        k2 = min(len(t_s), max(1, int(self.sample_rate_hz * 0.2)))
        self._attitude = self._tilt_heading(np.nanmean(accel[-k2:], axis=0), np.nanmean(mag[-k2:], axis=0))
        c = self.config
        rec = self._t1 - self._t0
        if self.coverage >= c.target_coverage and rec >= c.min_s:
            self._finish(f"coverage {100 * self.coverage:.0f} % after {rec:.0f} s")
        elif rec >= c.max_s:
            self._finish(f"time limit {c.max_s:.0f} s reached at coverage {100 * self.coverage:.0f} %")
        elif self.coverage >= c.target_coverage:
            self._message = f"Coverage reached: keep turning for {c.min_s - rec:.0f} s more"
        else:
            self._message = "Turn the unit slowly through every orientation (all faces up, all headings)"
        return self.status()

    def _tilt_heading(self, a_raw: np.ndarray, m_raw: np.ndarray) -> tuple:
        """(pitch°, roll°, magnetic heading°, tilt source, heading source) of one mean sample."""
        nan = (math.nan, math.nan, math.nan, "", "")
        if self.frontend is None or not np.isfinite(a_raw).all():
            return nan
        f = self.frontend(a_raw) / G_STANDARD_MPS2
        if not np.linalg.norm(f) > 0:
            return nan
        pitch, roll = C.pitch_roll_from_accel(f)
        head, source = math.nan, ""
        if np.isfinite(m_raw).all():
            if self.mag_cal is not None:
                W, h, source = self.mag_cal
                m = C.calibrated(m_raw[None, :], W, h)
            elif self.field.turned_over():
                m, source = (m_raw - self.field.midrange_centre())[None, :], "sweep midrange (hard iron only)"
            else:
                m, source = m_raw[None, :], "uncorrected (turn every axis over)"
            head = float(C.heading_deg(m, pitch, roll)[0][0])
        return (math.degrees(pitch[0]), math.degrees(roll[0]), head, self.frontend.source, source)

    def finish(self) -> None:
        """The operator ends the recording now."""
        if self.phase == "sweep":
            self._finish(f"finished by the operator at coverage {100 * self.coverage:.0f} %")

    def restart(self) -> None:
        self.phase = "sweep"
        self._reset()
        self._events.append(("restarted", "recording restarted"))

    def status(self) -> CompassStatus:
        m, rate, t = self._last if self._last is not None else (np.full(3, np.nan), math.nan, math.nan)
        rec = (self._t1 - self._t0) if math.isfinite(self._t0) else 0.0
        cov = self.coverage
        return CompassStatus(
            self.phase,
            cov,
            self.config.target_coverage,
            cov >= MIN_COVERAGE,
            rec,
            self._n,
            tuple(float(x) for x in m),
            float(np.linalg.norm(m)),
            rate,
            t,
            self._message,
            *self._attitude,
        )

    # ------------------------------------------------------------ the capture

    def capture(self, extra_meta: dict | None = None):
        """The recording as a P3 time-series capture."""
        from station.capture import Capture

        blocks = (("a", ("ax", "ay", "az")), ("g", ("gx", "gy", "gz")), ("m", ("mx", "my", "mz")))
        cols = recorded_columns(self._chunks, blocks)
        meta = {
            "station-capture": "1",
            "procedure": self.procedure,
            "device": self.device_id or "unknown",
            "date": self.started[:10],
            "sample_rate_hz": repr(self.sample_rate_hz),
        }
        for k in ("accel_unit", "gyro_unit", "mag_unit"):
            if self.units.get(k):
                meta[k] = self.units[k]
        if self.frontend is not None and si_factor("accel", self.units.get("accel_unit")) is None:
            meta.update(self.frontend.meta())  # the fit's tilt and headings use the same front end
        meta.update(site_meta(self.site))
        if "date" in self.site:
            meta["date"] = str(self.site["date"])
        meta.update({k: str(v) for k, v in (extra_meta or {}).items()})
        return Capture(meta=meta, columns=cols)


def sweep_positions(positions: list[str]) -> list[str]:
    """The demo operator's tour: the simulator's sphere positions, then the P1 faces."""
    from solvers.positions import P1_POSITIONS

    return list(positions) + [p for p in P1_POSITIONS if p not in positions]


class SweepOperator:
    """The demo's operator for P3: visits the simulated device's sphere positions
    (``s1``..``s12``) in turn, ``hold_s`` at each, until the guide is done."""

    def __init__(self, place, positions: list[str], hold_s: float = 2.0):
        self.place = place
        self.positions = list(positions)
        self.hold_s = hold_s
        self._k = -1
        self._next = -math.inf

    def step(self, guide: CompassGuide, t_s: float) -> str | None:
        if guide.phase != "sweep" or not math.isfinite(t_s) or t_s < self._next:
            return None
        self._k = (self._k + 1) % len(self.positions)
        self.place(self.positions[self._k])
        self._next = t_s + self.hold_s + 2.5  # the simulated move takes 2.5 s
        return self.positions[self._k]


def live_device(*, seed: int, rate_hz: float, reference: bool = False):
    """The simulated bench device for this procedure (``station.sources.SimSource``'s): the
    unit held where the operator puts it (``solvers.simulate.LiveImu``), in today's field (UTC
    date): the capture takes its ``date`` from the bench's site, and a calibration is stored at
    its capture's date, so a bench at the simulator's fixed date filed a sweep made today days
    (later years) in the past, already overdue."""
    from solvers.simulate import LiveImu

    today = _dt.datetime.now(_dt.UTC).date().isoformat()
    return LiveImu(
        procedure="compass", seed=seed, rate_hz=rate_hz, hold_s=1e9, reference=reference, site={"date": today}
    )


def headless_demo(src, now: list, *, average_s: float, out, max_device_s: float = 900.0) -> CompassGuide:
    """``station demo --headless --procedure compass``: the scripted operator visits the
    sphere positions on the started simulated device ``src`` (clock ``now[0]``, advanced
    here); coverage lines go to ``out``. Returns the guide when the sweep is over."""
    from station.procedures.accel_frontend import for_device

    guide = CompassGuide(
        sample_rate_hz=src.rate_hz,
        units=src.units,
        device_id=src.device_id,
        site=src.site,
        config=CompassConfig(min_s=30.0),
        # the TUI's compass screen's front end: the simulated unit's data-sheet zero and sensitivity
        accel_frontend=for_device([], src.units.get("accel_unit"), getattr(src, "nominal", None)),
    )
    operator = SweepOperator(src.place, sweep_positions(src.positions), hold_s=1.0)
    shown = -1
    while guide.phase == "sweep" and now[0] < max_device_s:
        now[0] += 0.05
        b = src.drain()
        if b is None:
            continue
        st = guide.update(b.t_s, b.accel, b.gyro, b.mag, b.temp_c)
        operator.step(guide, st.t_s)
        if int(st.coverage * 10) != shown:
            shown = int(st.coverage * 10)
            print(f"{st.t_s:7.1f} s  coverage {100 * st.coverage:3.0f} %", file=out)
    return guide
