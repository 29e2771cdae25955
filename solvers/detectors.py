"""Live detectors shared by the guided procedures (``station/procedures/guide*.py``) and
the device layer (``station/device/live.py``): one orientation check, one sphere coverage.

Pure numerics (no I/O, no UI), so both can import them without pulling in textual.

- :func:`orientation_check`: the measured specific-force direction against the one the
  position asks for; the angle between them [deg], ``wrong_face_up`` beyond 90°, ``ok``
  within the tolerance.
- :class:`FieldCoverage`: the compass sphere coverage **as the calibration measures it**:
  ``solvers.compass.coverage`` (share of the sphere within 30° of a visited field
  direction) of the directions about the midrange centre
  (``solvers.compass.midrange_directions``), the first check of
  ``solvers.compass.check_orientations``, refused below ``MIN_COVERAGE``. The drawable map
  samples the same measure on a latitude/longitude grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from solvers import compass as C
from solvers.positions import P1_POSITIONS


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

    ``expected``: a vector (any length), or a position name of P1 (``x_up``, ``xy_45``, ...).
    Raises ValueError when either vector is zero or not finite.
    """
    e = np.asarray(P1_POSITIONS[expected] if isinstance(expected, str) else expected, dtype=float)
    f = np.asarray(f_body, dtype=float)
    nf, ne = np.linalg.norm(f), np.linalg.norm(e)
    if not (nf > 0 and ne > 0 and np.isfinite(nf) and np.isfinite(ne)):
        raise ValueError("orientation check needs a finite, non-zero measured and expected vector")
    m, e = f / nf, e / ne
    angle = math.degrees(math.atan2(np.linalg.norm(np.cross(m, e)), float(m @ e)))
    return OrientationCheck(e, m, angle, angle > 90.0, angle <= tolerance_deg)


class FieldCoverage:
    """Incremental compass coverage, the number ``solvers.compass.check_orientations``
    refuses on.

    Feed raw magnetometer rows (any unit; NaN rows are ignored). The midrange centre uses
    every row (running min/max, as the calibration's ``midrange_directions`` on the whole
    capture); the directions are a subsample of at most ``keep_hz`` rows per second of
    data (``rate_hz``), enough for a 30° measure at hand-turning speeds.

    Guard: an axis whose range is still under half the field (``median |m|``) has not been
    turned over yet, and its midrange is noise, not hard iron; its centre is 0 until then.
    (A still unit about its midrange would point everywhere and read ~100 %.) Once every
    axis has been turned over, which any sweep that can pass does, the number is exactly
    ``coverage(midrange_directions(rows))`` of the kept rows.

    ``center``: a known hard-iron centre (raw units) to use instead of the midrange.
    ``recentre_frac``: the centre in use follows the midrange once it has moved more than
    this share of the field (default 1 %: directions shift < 0.6°); each move recomputes
    from every kept row, in between the measure is kept incrementally. 0: follow exactly.
    """

    def __init__(self, rate_hz: float = 100.0, keep_hz: float = 10.0, center=None, recentre_frac: float = 0.01) -> None:
        self.recentre_frac = float(recentre_frac)
        self._c_used: np.ndarray | None = None
        self.every = max(1, int(round(float(rate_hz) / keep_hz))) if rate_hz and math.isfinite(rate_hz) else 1
        self.center = None if center is None else np.asarray(center, dtype=float).reshape(3)
        self._lo = np.full(3, np.inf)
        self._hi = np.full(3, -np.inf)
        self._kept: list[np.ndarray] = []
        self._n_kept = 0
        self._phase = 0  # rows seen modulo ``every``
        self._best: dict = {}  # points key -> (centre used, rows done, max dot per point)

    def reset(self) -> None:
        self._lo[:] = np.inf
        self._hi[:] = -np.inf
        self._kept, self._n_kept, self._phase, self._best, self._c_used = [], 0, 0, {}, None

    def update(self, mag) -> None:
        m = np.atleast_2d(np.asarray(mag, dtype=float))
        m = m[np.all(np.isfinite(m), axis=1)]
        if not len(m):
            return
        self._lo = np.minimum(self._lo, m.min(axis=0))
        self._hi = np.maximum(self._hi, m.max(axis=0))
        idx = np.arange((-self._phase) % self.every, len(m), self.every)
        self._phase = (self._phase + len(m)) % self.every
        if len(idx):
            self._kept.append(m[idx])
            self._n_kept += len(idx)

    def centre(self) -> np.ndarray:
        """The centre in use: ``center`` if given, else the midrange (guarded), updated when
        it has moved more than ``recentre_frac`` of the field."""
        if len(self._kept) > 1:
            self._kept = [np.concatenate(self._kept)]
        if self.center is not None:
            return self.center
        c, field = self._midrange()
        if self._c_used is None or np.linalg.norm(c - self._c_used) > self.recentre_frac * field:
            self._c_used = c
        return self._c_used

    def directions(self) -> np.ndarray:
        """Unit field directions about :meth:`centre`, (n, 3)."""
        if not self._n_kept:
            return np.zeros((0, 3))
        c = self.centre()
        d = self._kept[0] - c
        return C.unit_rows(d[np.linalg.norm(d, axis=1) > 0])

    def midrange_centre(self) -> np.ndarray:
        """(max + min) / 2 per axis, 0 on axes not yet turned over (see the class docstring)."""
        return self._midrange()[0]

    def turned_over(self) -> bool:
        """Every axis has been turned over (its range exceeds half the field), so
        :meth:`midrange_centre` is a hard-iron estimate on all three."""
        if not self._n_kept:
            return False
        _, field = self._midrange()
        return bool(np.all(self._hi - self._lo > 0.5 * field))

    def _midrange(self) -> tuple[np.ndarray, float]:
        if not self._n_kept:
            return np.zeros(3), 0.0
        if len(self._kept) > 1:
            self._kept = [np.concatenate(self._kept)]
        field = float(np.median(np.linalg.norm(self._kept[0], axis=1)))
        return np.where(self._hi - self._lo > 0.5 * field, (self._hi + self._lo) / 2.0, 0.0), field

    @property
    def n_kept(self) -> int:
        """Directions kept so far (the subsample the fraction is computed on)."""
        return self._n_kept

    def _max_dot(self, key, points: np.ndarray) -> np.ndarray:
        """Per point, the largest cosine to a kept direction: incremental while the centre
        stays put, recomputed from every kept row when it moves (as the calibration would
        see the whole record about its final centre)."""
        if not self._n_kept:
            return np.full(len(points), -1.0)
        c = self.centre()  # joins the kept blocks
        used, done, best = self._best.get(key, (None, 0, None))
        if used is None or not np.array_equal(used, c):
            done, best = 0, np.full(len(points), -1.0)
        new = self._kept[0][done:] - c
        new = new[np.linalg.norm(new, axis=1) > 0]
        for block in np.array_split(new, max(1, len(new) // 5000 + 1)) if len(new) else []:
            best = np.maximum(best, np.max(C.unit_rows(block) @ points.T, axis=0))
        self._best[key] = (c.copy(), self._n_kept, best)
        return best

    @property
    def fraction(self) -> float:
        """``solvers.compass.coverage`` of the directions so far (0..1): the share of its
        ``COVERAGE_CELLS`` cells within ``COVERAGE_RADIUS_DEG`` of a direction (kept
        incrementally; a test checks it equals ``coverage(directions())``)."""
        if not self._n_kept:
            return 0.0
        best = self._max_dot("cells", C.fibonacci_sphere(C.COVERAGE_CELLS))
        return float(np.mean(best >= math.cos(math.radians(C.COVERAGE_RADIUS_DEG))))

    @property
    def enough(self) -> bool:
        """At least the calibration's minimum (``solvers.compass.MIN_COVERAGE``)."""
        return self.fraction >= C.MIN_COVERAGE

    def grid(self, n_bands: int = 6, n_sectors: int = 12, sub: int = 3) -> np.ndarray:
        """The same measure drawn: (n_bands, n_sectors) shares 0..1, band 0 at -z (bands
        uniform in z, sectors in azimuth from -180°): of ``sub`` x ``sub`` points spread
        over each cell, the share within ``COVERAGE_RADIUS_DEG`` of a visited direction."""
        nb, ns = n_bands * sub, n_sectors * sub
        z = -1.0 + (np.arange(nb) + 0.5) * 2.0 / nb
        az = -math.pi + (np.arange(ns) + 0.5) * 2.0 * math.pi / ns
        r = np.sqrt(1.0 - z**2)
        pts = np.column_stack([np.outer(r, np.cos(az)).ravel(), np.outer(r, np.sin(az)).ravel(), np.repeat(z, ns)])
        best = self._max_dot(("grid", n_bands, n_sectors, sub), pts)
        hit = (best >= math.cos(math.radians(C.COVERAGE_RADIUS_DEG))).reshape(n_bands, sub, n_sectors, sub)
        return hit.mean(axis=(1, 3))
