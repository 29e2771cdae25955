"""Live detectors shared by the TUI: reader batches in, small status values out.

- Stillness: `solvers.stillness.StillnessTracker` (noise-adaptive, the batch detector run
  incrementally) fed from `Batch`es; NaN rows count as motion.
- Orientation check: the measured specific-force direction against the one the position
  asks for (`solvers.positions.P1_POSITIONS`), the angle between them in degrees and
  `wrong_face_up` when it exceeds 90°.
- Compass sphere coverage: `solvers.detectors.FieldCoverage`, the measure the compass
  calibration refuses on (`solvers.compass.coverage`: share of the sphere within 30° of a
  visited field direction about the midrange centre, need 40 %).

The orientation check and the coverage are `solvers.detectors`, shared with the guides
(`station/procedures/tabletop_guide.py`, `compass_guide.py`).

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

from solvers.detectors import FieldCoverage, OrientationCheck, orientation_check  # noqa: F401 - re-exported
from solvers.models import accel as accel_model
from solvers.positions import P1_POSITIONS
from solvers.stillness import StillnessTracker, TrackerState
from solvers.units import si_factor
from station.device.reader import Batch
from station.errors import UnsupportedError

# ------------------------------------------------------------------ orientation
# One orientation check for the guides and this module: solvers.detectors.


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
        return accel_model.p1_apply(raw, self.B, self.M).reshape(np.shape(raw))  # one sample or rows


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
        self.mag_center = None if mag_center is None else np.asarray(mag_center, dtype=float)
        self.coverage = FieldCoverage(sample_rate_hz, center=self.mag_center)
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
        return LiveStatus(
            self._last_t if self._samples else math.nan,
            self._samples,
            self._state,
            self._orientation(),
            self.coverage.fraction if self._has_mag else None,
        )

    @property
    def _has_mag(self) -> bool:
        return bool(self.units.get("mag_unit")) or self.coverage.n_kept > 0

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
            self.coverage.update(m)

    def _orientation(self) -> OrientationCheck | None:
        if self.expected is None or self._to_f is None:
            return None
        s = self._state
        raw = (
            s.accel_mean
            if (s is not None and s.accel_mean is not None)
            else (self._recent_a.mean(axis=0) if len(self._recent_a) else None)
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
