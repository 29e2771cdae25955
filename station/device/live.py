"""Live detectors shared by the TUI: reader batches in, small status values out.

- Stillness: `solvers.stillness.StillnessTracker` (noise-adaptive, the batch detector run
  incrementally) fed from `Batch`es; NaN rows count as motion.
- Orientation check: the measured specific-force direction against the one the position
  asks for (`solvers.positions.P1_POSITIONS`), the angle between them in degrees and
  `wrong_face_up` when it exceeds 90°.
- Compass sphere coverage: the share of equal-area cells of the unit sphere (Leopardi's
  recursive zonal equal-area partition, EQ(2, N)) that the magnetic field direction has
  visited in the body frame.

Raw accelerometer units: the direction of gravity needs outputs that are roughly
proportional to specific force. Physical units (g, m/s^2, ...) are used as they are; raw
units (V, mV, counts) need a rough calibration `A = B + M V` (e.g. the device's last
one, or a nominal front end), given as `accel_B`, `accel_M`; without one the check is
refused with a clear message rather than guessed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from solvers.positions import P1_POSITIONS
from solvers.stillness import StillnessTracker, TrackerState
from solvers.units import si_factor
from station.device.reader import Batch
from station.errors import UnsupportedError

# ------------------------------------------------------------------ orientation


@dataclass(frozen=True)
class OrientationCheck:
    """Measured vs expected specific-force direction (unit vectors, body frame)."""

    expected: np.ndarray
    measured: np.ndarray
    angle_deg: float
    wrong_face_up: bool  # angle > 90°: the unit is the other way up
    ok: bool  # angle <= tolerance_deg


def orientation_check(f_body, expected, tolerance_deg: float = 10.0) -> OrientationCheck:
    """Compare a specific force (any units proportional to it) with an expected direction.

    `expected`: a unit vector, or a position name of P1 (`x_up`, `xy_45`, ...).
    """
    e = np.asarray(P1_POSITIONS[expected] if isinstance(expected, str) else expected, dtype=float)
    f = np.asarray(f_body, dtype=float)
    nf, ne = np.linalg.norm(f), np.linalg.norm(e)
    if not (nf > 0 and ne > 0 and np.isfinite(nf)):
        raise ValueError("orientation check needs a finite, non-zero measured and expected vector")
    m, e = f / nf, e / ne
    angle = math.degrees(math.atan2(np.linalg.norm(np.cross(m, e)), float(m @ e)))
    return OrientationCheck(e, m, angle, angle > 90.0, angle <= tolerance_deg)


class AccelToSpecificForce:
    """Raw accelerometer rows -> specific force in m/s^2, roughly, for direction checks."""

    def __init__(self, accel_unit: str | None, B=None, M=None) -> None:
        self.unit = accel_unit
        if B is not None and M is not None:
            self.B = np.asarray(B, dtype=float).reshape(3)
            self.M = np.asarray(M, dtype=float).reshape(3, 3)
            return
        k = si_factor("accel", accel_unit)
        if k is None:
            raise UnsupportedError(
                f"accelerometer in {accel_unit or 'unknown units'}: the orientation check needs a rough "
                "calibration (B, M) for raw outputs"
            )
        self.B = np.zeros(3)
        self.M = np.eye(3) * k

    def __call__(self, raw: np.ndarray) -> np.ndarray:
        return raw @ self.M.T + self.B


# ------------------------------------------------------------------ sphere coverage


def _cap_area(theta: float) -> float:
    return 4.0 * math.pi * math.sin(theta / 2.0) ** 2


def _cap_angle(area: float) -> float:
    return 2.0 * math.asin(math.sqrt(min(1.0, area / (4.0 * math.pi))))


def eq_partition(n: int) -> tuple[np.ndarray, list[int]]:
    """Leopardi's EQ(2, n): polar-angle boundaries of the zones and the cells per zone.

    Returns (theta_edges (k+1,), cells per zone (k,)): zone j spans polar angles
    theta_edges[j]..theta_edges[j+1] and is cut into that many equal longitude sectors.
    Every cell has area 4*pi/n. Zone 0 and the last zone are the polar caps (1 cell).
    """
    if n < 1:
        raise ValueError("n must be >= 1")
    if n == 1:
        return np.array([0.0, math.pi]), [1]
    if n == 2:
        return np.array([0.0, math.pi / 2, math.pi]), [1, 1]
    area = 4.0 * math.pi / n
    theta_c = _cap_angle(area)
    delta = math.sqrt(area)  # ideal collar height
    n_collars = max(1, round((math.pi - 2.0 * theta_c) / delta))
    fitting = (math.pi - 2.0 * theta_c) / n_collars
    ideal = [
        (_cap_area(theta_c + (i + 1) * fitting) - _cap_area(theta_c + i * fitting)) / area
        for i in range(n_collars)
    ]
    counts, carry = [], 0.0
    for x in ideal:  # round while keeping the running total honest
        c = round(x + carry)
        carry += x - c
        counts.append(int(c))
    edges = [0.0, theta_c]
    total = 1
    for c in counts:
        total += c
        edges.append(_cap_angle(total * area))
    edges[-1] = math.pi - theta_c
    edges.append(math.pi)
    return np.array(edges), [1, *counts, 1]


class SphereCoverage:
    """Which equal-area cells of the unit sphere the direction of a vector has visited."""

    def __init__(self, n_cells: int = 100) -> None:
        self.edges, self.per_zone = eq_partition(n_cells)
        self.offsets = np.concatenate([[0], np.cumsum(self.per_zone)[:-1]])
        self.n_cells = int(sum(self.per_zone))
        self.visited = np.zeros(self.n_cells, dtype=bool)
        self.counts = np.zeros(self.n_cells, dtype=np.int64)

    def cells(self, v) -> np.ndarray:
        """Cell index of each row's direction (rows with a zero or non-finite vector: -1)."""
        v = np.atleast_2d(np.asarray(v, dtype=float))
        norm = np.linalg.norm(v, axis=1)
        good = np.isfinite(norm) & (norm > 0)
        out = np.full(len(v), -1, dtype=np.int64)
        if not good.any():
            return out
        u = v[good] / norm[good, None]
        theta = np.arccos(np.clip(u[:, 2], -1.0, 1.0))
        phi = np.mod(np.arctan2(u[:, 1], u[:, 0]), 2 * math.pi)
        zone = np.clip(np.searchsorted(self.edges, theta, side="right") - 1, 0, len(self.per_zone) - 1)
        per = np.asarray(self.per_zone)[zone]
        sector = np.minimum((phi / (2 * math.pi) * per).astype(np.int64), per - 1)
        out[good] = self.offsets[zone] + sector
        return out

    def update(self, v) -> float:
        c = self.cells(v)
        c = c[c >= 0]
        np.add.at(self.counts, c, 1)
        self.visited[c] = True
        return self.fraction

    @property
    def fraction(self) -> float:
        return float(self.visited.mean())


# ------------------------------------------------------------------ glue


@dataclass(frozen=True)
class LiveStatus:
    """One update's worth of what the operator screen shows."""

    t_s: float
    samples: int
    stillness: TrackerState | None
    orientation: OrientationCheck | None
    coverage: float | None


class LiveDetectors:
    """Feed reader batches; read `LiveStatus`. Not thread-safe: use from one thread.

    sample_rate_hz: the stream's rate (the stillness windows are counted in samples).
    init_rest_s: the first seconds are a rest on which the noise is measured (the
        operator is asked to hold still), as `StillnessTracker` documents.
    units: the device's units (`accel_unit`, ...); accel_B/accel_M: a rough calibration
        for raw accelerometer units (see the module docstring).
    orientation_window_s: the measured direction is the mean of this much recent data,
        or of the current static interval when the stillness detector has one.
    """

    def __init__(
        self,
        sample_rate_hz: float,
        *,
        units: dict[str, str] | None = None,
        init_rest_s: float = 2.0,
        accel_B=None,
        accel_M=None,
        tolerance_deg: float = 10.0,
        orientation_window_s: float = 0.5,
        coverage_cells: int = 100,
        mag_center=None,
        use_gyro: bool = True,
    ) -> None:
        self.units = dict(units or {})
        self.tracker = StillnessTracker(sample_rate_hz, init_rest_s=init_rest_s, nan_policy="omit")
        self.tolerance_deg = tolerance_deg
        self.expected: np.ndarray | None = None
        self.expected_name: str | None = None
        self._to_f: AccelToSpecificForce | None = None
        self._to_f_error: str | None = None
        try:
            self._to_f = AccelToSpecificForce(self.units.get("accel_unit"), accel_B, accel_M)
        except UnsupportedError as exc:
            self._to_f_error = str(exc)
        self.coverage = SphereCoverage(coverage_cells)
        self.mag_center = None if mag_center is None else np.asarray(mag_center, dtype=float)
        self._recent = max(1, int(round(orientation_window_s * sample_rate_hz)))
        self._recent_a = np.empty((0, 3))
        self._use_gyro = use_gyro
        self._gyro: bool | None = None
        self._last_t = -math.inf
        self._samples = 0
        self._state: TrackerState | None = None

    def expect(self, position) -> None:
        """The position asked for now: a P1 name or a unit vector (None: no check)."""
        if position is None:
            self.expected = self.expected_name = None
            return
        if isinstance(position, str):
            if position not in P1_POSITIONS:
                raise ValueError(f"unknown position {position!r}")
            self.expected_name, self.expected = position, P1_POSITIONS[position]
        else:
            self.expected_name, self.expected = None, np.asarray(position, dtype=float)

    def update(self, batch: Batch | None) -> LiveStatus:
        if batch is not None and len(batch):
            self._feed(batch)
        return LiveStatus(self._last_t if self._samples else math.nan, self._samples, self._state,
                          self._orientation(), self.coverage.fraction if self._has_mag else None)

    @property
    def _has_mag(self) -> bool:
        return bool(self.units.get("mag_unit")) or self.coverage.visited.any()

    def _feed(self, b: Batch) -> None:
        keep = b.t_s > self._last_t  # the tracker needs strictly increasing time
        if keep.all():
            keep = np.flatnonzero(np.r_[True, np.diff(b.t_s) > 0])
        else:
            idx = np.flatnonzero(keep)
            keep = idx[np.r_[True, np.diff(b.t_s[idx]) > 0]] if len(idx) else idx
        if not len(keep):
            return
        t = b.t_s[keep]
        a = b.values[keep][:, 0:3]
        g = b.values[keep][:, 3:6]
        if self._gyro is None:
            self._gyro = self._use_gyro and bool(np.isfinite(g).any())
        self._state = self.tracker.update(t, a, g if self._gyro else None)
        self._last_t = float(t[-1])
        self._samples += len(t)
        fin = np.isfinite(a).all(axis=1)
        self._recent_a = np.vstack([self._recent_a, a[fin]])[-self._recent :]
        m = b.values[keep][:, 6:9]
        m = m[np.isfinite(m).all(axis=1)]
        if len(m):
            self.coverage.update(m - self.mag_center if self.mag_center is not None else m)

    def _orientation(self) -> OrientationCheck | None:
        if self.expected is None or self._to_f is None:
            return None
        s = self._state
        raw = s.accel_mean if (s is not None and s.accel_mean is not None) else (
            self._recent_a.mean(axis=0) if len(self._recent_a) else None
        )
        if raw is None:
            return None
        try:
            return orientation_check(self._to_f(raw), self.expected, self.tolerance_deg)
        except ValueError:
            return None

    @property
    def orientation_unavailable(self) -> str | None:
        """Why no orientation check is possible (raw units without a calibration), or None."""
        return self._to_f_error
