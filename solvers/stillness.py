"""Static-interval (stillness) detection for IMU time series, batch and incremental.

The detector follows Tedaldi, Pretto and Menegatti, "A Robust and Easy to Implement
Method for IMU Calibration without External Equipments", ICRA 2014, and its code
`imu_tk::staticIntervalsDetector` (src/filters.cpp): for every sample t, the variance of
each accelerometer axis in a window of w samples centred on t gives the *variance
magnitude*

    varsigma(t) = || (var_w(a_x), var_w(a_y), var_w(a_z)) ||          (paper Eq. 17)

and the window is static when varsigma(t) < k * varsigma_init, where varsigma_init
comes from an initial rest of T_init seconds. imu_tk takes varsigma_init as the variance
of the whole initial rest and tries k = 2..10. Differences here, each for a reason:

- **Noise reference.** varsigma_init = || median over the reference windows of the
  per-axis windowed variance ||. Taking windows of the same length as the test keeps slow
  drift during a long rest out of the threshold, and it lets the same formula serve when
  there is no initial rest: the reference windows are then the quietest ones of the
  recording (``noise_source='robust'``, see `detect_static_intervals`). Both routes give
  the per-sample noise variance of each axis, `NoiseFloor.accel_var`.
- **One default k.** ``threshold_factor=5`` (on the variance, i.e. about 2.2x the noise
  standard deviation). With w = 101 the windowed variance of white noise stays within
  +-50 % of its mean with probability 1 - 1e-3, so a rest is never split, and any motion
  that raises the standard deviation more than 2.2x is seen.
- **Gyro.** When rates are given, a window is also required to have a mean rate close to
  the rest rate (the bias): || mean_w(omega) - b_omega || < gyro_rate_factor * sigma_omega,
  with sigma_omega = sqrt(sum of the per-axis rest variances). This catches what the
  accelerometer cannot see (a steady turn about the gravity vector, at constant |a| and
  constant axes). The rate *variance* is deliberately not tested: hand tremor while an
  operator holds a pose raises it 10-400x (MPU-6050 set) without changing the orientation.
- **Edges.** A sample is covered when some static window contains it; each run of
  covered samples is trimmed by ``margin_s`` (default half a window) at every end that
  borders motion, so that interval means are not contaminated. Ends at the first or last
  sample of the recording are not trimmed.

Units: any raw units (counts, V, g, m/s^2, deg/s, rad/s). Every threshold is a multiple of
noise measured in the same data, so units cancel. Index conventions: intervals are
``[start, stop)`` sample indices (0-based, stop exclusive) into the arrays given.

Numerics: windowed sums come from cumulative sums that restart every `block` samples
(aligned on absolute sample indices), so values stay bounded on long recordings and the
batch detector and `StillnessTracker` compute bit-identical statistics whatever the
batch sizes. No Python loop runs over samples.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from solvers import linalg
from solvers.errors import NotIdentifiable, SolverError, TooFewPositions

__all__ = [
    "NOISE_SOURCES",
    "NoiseFloor",
    "OrientationClusters",
    "StaticInterval",
    "StillnessConfig",
    "StillnessInputError",
    "StillnessResult",
    "StillnessTracker",
    "Thresholds",
    "TrackerState",
    "cluster_orientations",
    "detect_static_intervals",
]

NOISE_SOURCES = ("initial_rest", "robust", "first_differences")

# Median of a chi-square variable with one degree of freedom: median(z^2), z ~ N(0, 1).
_CHI2_1_MEDIAN = 0.454936423119572
# Robust floor rejected when its variance exceeds this many times the first-difference
# noise: the quietest windows then hold motion, not rest (see `_robust_noise`).
_FLOOR_TO_DIFF_MAX = 10.0
_TINY = np.finfo(float).tiny
_BATCH_CHUNK = 1 << 16


class StillnessInputError(SolverError, ValueError):
    """Input the detector cannot use: shape, length, NaN, time order, parameter range.

    `row` is the 0-based data row to blame, when there is one.
    """

    def __init__(self, message: str, row: int | None = None):
        super().__init__(message)
        self.row = row


# --------------------------------------------------------------------------- results


@dataclass(frozen=True)
class StillnessConfig:
    """Detector settings shared by the batch detector and the tracker.

    sample_rate_hz: nominal sample rate [Hz]; converts the durations below to samples.
    window_s: length of the centred variance window [s] (odd number of samples, >= 5).
    threshold_factor: k, static when ||var_w(a)|| < k * ||accel noise variance||.
    gyro_rate_factor: static also needs ||mean_w(omega) - bias|| < this * sigma_omega;
        None disables the gyro test even when rates are given.
    min_duration_s: shorter intervals (after trimming) are dropped [s].
    margin_s: trimmed from each end of a run that borders motion [s]; None = window_s/2.
    """

    sample_rate_hz: float
    window_s: float = 1.0
    threshold_factor: float = 5.0
    gyro_rate_factor: float | None = 10.0
    min_duration_s: float = 1.0
    margin_s: float | None = None

    def __post_init__(self) -> None:
        checks = [
            ("sample_rate_hz", self.sample_rate_hz, False),
            ("window_s", self.window_s, False),
            ("threshold_factor", self.threshold_factor, False),
            ("min_duration_s", self.min_duration_s, True),
        ]
        if self.gyro_rate_factor is not None:
            checks.append(("gyro_rate_factor", self.gyro_rate_factor, False))
        if self.margin_s is not None:
            checks.append(("margin_s", self.margin_s, True))
        for name, value, zero_ok in checks:
            v = float(value)
            if not math.isfinite(v) or v < 0 or (v == 0 and not zero_ok):
                bound = ">= 0" if zero_ok else "> 0"
                raise StillnessInputError(f"{name} must be a finite number {bound}, got {value!r}")

    @property
    def window_n(self) -> int:
        """Window length in samples (odd, at least 5)."""
        w = max(5, int(round(self.window_s * self.sample_rate_hz)))
        return w if w % 2 else w + 1

    @property
    def half_n(self) -> int:
        return self.window_n // 2

    @property
    def margin_n(self) -> int:
        if self.margin_s is None:
            return self.half_n
        return int(round(self.margin_s * self.sample_rate_hz))

    @property
    def min_n(self) -> int:
        return max(1, int(round(self.min_duration_s * self.sample_rate_hz)))

    @property
    def block_n(self) -> int:
        """Restart period of the cumulative sums (a power of two >= 2 windows)."""
        return max(4096, 1 << (2 * self.window_n - 1).bit_length())


@dataclass(frozen=True)
class NoiseFloor:
    """Rest noise, in the data's own units.

    accel_var: (3,) per-axis variance of one accelerometer sample at rest [unit^2]
        (median windowed variance over the reference windows, floored at LSB^2/12).
    gyro_var: (3,) the same for the rates [unit^2], None without gyro.
    gyro_bias: (3,) rest rate [unit]: median windowed mean over the reference windows.
    source: 'initial_rest' (windows inside the operator's initial rest), 'robust' (the
        quietest windows of the recording) or 'first_differences' (no rest found: noise
        of the sample-to-sample differences, see `detect_static_intervals`).
    n_windows: number of reference windows used.
    """

    accel_var: np.ndarray
    gyro_var: np.ndarray | None
    gyro_bias: np.ndarray | None
    source: str
    n_windows: int

    @property
    def accel_std(self) -> np.ndarray:
        return np.sqrt(self.accel_var)

    @property
    def gyro_std(self) -> np.ndarray | None:
        return None if self.gyro_var is None else np.sqrt(self.gyro_var)


@dataclass(frozen=True)
class Thresholds:
    """Thresholds actually applied, in the data's units.

    accel_var_norm: a window is static only if ||var_w(a)|| < this [accel unit^2];
        = threshold_factor * ||NoiseFloor.accel_var||.
    gyro_rate: ... and ||mean_w(omega) - gyro_bias|| < this [gyro unit];
        = gyro_rate_factor * sqrt(sum NoiseFloor.gyro_var); None when not tested.
    """

    accel_var_norm: float
    gyro_rate: float | None
    threshold_factor: float
    gyro_rate_factor: float | None


@dataclass(frozen=True)
class StaticInterval:
    """One static interval: samples ``start .. stop-1``.

    t_start_s, t_stop_s: times of the first and the last sample inside [s].
    accel_mean, accel_std: (3,) mean and sample standard deviation (ddof=1) of the
        accelerometer over the interval [accel unit]; gyro_mean, gyro_std likewise or None.
    """

    start: int
    stop: int
    t_start_s: float
    t_stop_s: float
    n: int
    accel_mean: np.ndarray
    accel_std: np.ndarray
    gyro_mean: np.ndarray | None = None
    gyro_std: np.ndarray | None = None

    @property
    def duration_s(self) -> float:
        return self.t_stop_s - self.t_start_s


@dataclass
class StillnessResult:
    """What `detect_static_intervals` found, with the numbers a UI or a report needs.

    intervals: static intervals in time order.
    noise, thresholds, config: how the decision was made.
    level: (N,) the decision statistic of the window centred on each sample, as a ratio
        to its threshold: max(||var_w(a)|| / thr_a, ||mean_w(omega) - b|| / thr_omega).
        < 1 is static. NaN for the first and last window_n//2 samples (no full window),
        +inf for windows that contain a NaN row (nan_policy='omit').
    accel_var_norm: (N,) ||var_w(a)|| [accel unit^2], NaN where level is NaN or inf.
    gyro_rate: (N,) ||mean_w(omega) - b|| [gyro unit], or None without gyro test.
    warnings: human-readable remarks (suspicious initial rest, no rest found, ...).
    """

    intervals: list[StaticInterval]
    noise: NoiseFloor
    thresholds: Thresholds
    config: StillnessConfig
    level: np.ndarray
    accel_var_norm: np.ndarray
    gyro_rate: np.ndarray | None
    n_samples: int
    warnings: list[str] = field(default_factory=list)

    @property
    def noise_source(self) -> str:
        return self.noise.source

    @property
    def still_mask(self) -> np.ndarray:
        """(N,) bool, True on samples inside a reported interval."""
        mask = np.zeros(self.n_samples, dtype=bool)
        for iv in self.intervals:
            mask[iv.start : iv.stop] = True
        return mask


# ------------------------------------------------------------------ windowed sums


class _RowStore:
    """Rows at absolute indices [start, start + len), appended in pieces.

    Rows older than the newest `keep` may be dropped when the buffer is full
    (keep=None: keep everything). Appending costs O(rows appended), amortised.
    """

    def __init__(self, n_cols: int, keep: int | None):
        self.keep = keep
        self.buf = np.empty((1024 if keep is None else max(1024, 4 * keep), n_cols))
        self.len = 0
        self.start = 0

    @property
    def end(self) -> int:
        return self.start + self.len

    def append(self, x: np.ndarray) -> None:
        self.extend(len(x))[:] = x

    def extend(self, m: int) -> np.ndarray:
        """Make room for m more rows and return them (uninitialised) to be filled."""
        if self.len + m > len(self.buf):
            k = self.len if self.keep is None else min(self.len, self.keep)
            old = self.buf[self.len - k : self.len]
            # a store of the newest `keep` rows grows only when they and the new rows do not fit
            # (to twice that): doubling whenever half was used kept it at four times a piece
            if (k + m > len(self.buf) // 2) if self.keep is None else (k + m > len(self.buf)):
                size = max(k + m, 2 * len(self.buf)) if self.keep is None else 2 * (k + m)
                grown = np.empty((size, self.buf.shape[1]))
                grown[:k] = old
                self.buf = grown
            else:
                self.buf[:k] = old.copy()
            self.start += self.len - k
            self.len = k
        self.len += m
        return self.buf[self.len - m : self.len]

    def rows(self, i0: int, i1: int) -> np.ndarray:
        """Rows with absolute indices i0 .. i1-1 (a view)."""
        if i0 < self.start:
            raise RuntimeError(f"row {i0} was dropped (oldest kept: {self.start})")
        return self.buf[i0 - self.start : i1 - self.start]


class _WindowSums:
    """Sums over every complete window of w consecutive rows, fed in pieces of any size.

    Prefix sums restart at absolute indices that are multiples of `block`; a window
    spans at most two blocks. Each prefix value is built by the same sequence of float
    additions whatever the piece sizes (np.cumsum is sequential), so the window sums are
    bit-identical between one call on the whole array and many calls on pieces.
    """

    def __init__(self, w: int, block: int, n_channels: int):
        if block < w:
            raise ValueError("block must be >= window")
        self.w, self.block, self.c = w, block, n_channels
        self.n = 0
        self._q_last = np.zeros(n_channels)
        self._q = _RowStore(n_channels, keep=w)

    def _prefix(self, x: np.ndarray) -> np.ndarray:
        m, b = len(x), self.block
        q = np.empty_like(x)
        i = 0
        off = self.n % b
        if off and m:  # continue the current block: q_last + x0, (q_last + x0) + x1, ...
            i = min(m, b - off)
            q[:i] = x[:i]
            q[0] += self._q_last
            np.cumsum(q[:i], axis=0, out=q[:i])
        n_full = (m - i) // b
        if n_full:
            j = i + n_full * b
            q[i:j] = np.cumsum(x[i:j].reshape(n_full, b, self.c), axis=1).reshape(j - i, self.c)
            i = j
        if i < m:
            q[i:] = np.cumsum(x[i:], axis=0)
        return q

    def push(self, x: np.ndarray) -> np.ndarray:
        """Add rows x (m, C); return the sums of the windows completed by them, in order.

        Window [f, l] (l = f + w - 1): Q[l] - E(f) inside one block, where E(f) = Q[f-1],
        or 0 when f starts a block; (Q[kb-1] - E(f)) + Q[l] when it crosses the block
        boundary kb.
        """
        m = len(x)
        w, b = self.w, self.block
        lo = max(w - 1, self.n)  # last row of the first window completed here
        hi = self.n + m  # one past the last row of the last window
        if m:
            q_new = self._prefix(x)
            self._q.append(q_new)
            self._q_last = q_new[-1].copy()
            self.n += m
        if hi <= lo:
            return np.zeros((0, self.c))
        qc, base = self._q.buf, self._q.start
        f0 = lo - w + 1  # first row of the first window
        q_l = qc[lo - base : hi - base]
        if f0 == 0:
            e = np.vstack([np.zeros((1, self.c)), qc[f0 - base : hi - w - base]])
        else:
            e = qc[f0 - 1 - base : hi - w - base].copy()
        for kb in range(-(-f0 // b) * b, hi - w + 1, b):  # windows starting a block
            e[kb - f0] = 0.0
        out = q_l - e
        for kb in range((f0 // b + 1) * b, hi, b):  # windows crossing boundary kb
            i0, i1 = max(kb - w + 1, f0) - f0, min(kb - 1, hi - w) - f0 + 1
            if i1 > i0:
                out[i0:i1] = (qc[kb - 1 - base] - e[i0:i1]) + q_l[i0:i1]
        return out


def _norm3(v: np.ndarray, minus: np.ndarray | None = None) -> np.ndarray:
    """Row norms of an (n, 3) array (of ``v - minus``), written out so every row is summed in
    one order: (x² + y²) + z². Column by column, so the temporaries are (n,), not (n, 3)."""

    def square(k: int) -> np.ndarray:
        c = v[:, k] if minus is None else v[:, k] - minus[k]
        return np.multiply(c, c, out=c if minus is not None else None)

    r = square(0)
    r += square(1)
    r += square(2)
    return np.sqrt(r, out=r)


@dataclass
class _Stats:
    """Per-window statistics (one row per window, in window order)."""

    accel_var: np.ndarray  # (k, 3)
    gyro_var: np.ndarray | None  # (k, 3)
    gyro_mean: np.ndarray | None  # (k, 3) absolute
    has_nan: np.ndarray  # (k,) bool

    @staticmethod
    def from_sums(s: np.ndarray, w: int, has_gyro: bool, gyro_ref: np.ndarray | None) -> _Stats:
        d = 6 if has_gyro else 3
        s1 = s[:, :d]
        var = (s[:, d : 2 * d] - s1 * s1 / w) / (w - 1)
        np.maximum(var, 0.0, out=var)
        gyro_mean = s[:, 3:6] / w + gyro_ref if has_gyro else None
        return _Stats(var[:, 0:3], var[:, 3:6] if has_gyro else None, gyro_mean, s[:, -1] > 0.5)

    @staticmethod
    def concat(parts: list[_Stats]) -> _Stats:
        def cat(name):
            vals = [getattr(p, name) for p in parts]
            return None if vals[0] is None else np.concatenate(vals)

        return _Stats(cat("accel_var"), cat("gyro_var"), cat("gyro_mean"), cat("has_nan"))

    @staticmethod
    def empty(k: int, has_gyro: bool) -> _Stats:
        return _Stats(
            np.empty((k, 3)),
            np.empty((k, 3)) if has_gyro else None,
            np.empty((k, 3)) if has_gyro else None,
            np.empty(k, dtype=bool),
        )

    def put(self, i: int, part: _Stats) -> None:
        """Copy `part` into rows i .. i+len(part)-1."""
        j = i + len(part)
        self.accel_var[i:j] = part.accel_var
        if self.gyro_var is not None:
            self.gyro_var[i:j] = part.gyro_var
            self.gyro_mean[i:j] = part.gyro_mean
        self.has_nan[i:j] = part.has_nan

    def where(self, mask: np.ndarray) -> _Stats:
        """The rows where mask is True (no copy when it is True everywhere)."""
        if mask.all():
            return self
        return self.take(np.flatnonzero(mask))

    def take(self, idx) -> _Stats:
        if isinstance(idx, np.ndarray) and idx.dtype != bool:

            def pick(x):
                return None if x is None else np.take(x, idx, axis=0)

            return _Stats(pick(self.accel_var), pick(self.gyro_var), pick(self.gyro_mean), self.has_nan[idx])
        return _Stats(
            self.accel_var[idx],
            None if self.gyro_var is None else self.gyro_var[idx],
            None if self.gyro_mean is None else self.gyro_mean[idx],
            self.has_nan[idx],
        )

    def __len__(self) -> int:
        return len(self.accel_var)


def _channels(
    accel: np.ndarray, gyro: np.ndarray | None, bad: np.ndarray, ref_a: np.ndarray, ref_g: np.ndarray | None
) -> np.ndarray:
    """Rows [a-ref, g-ref, (a-ref)^2, (g-ref)^2, nan flag]; NaN rows are zero but flagged."""
    d = 3 if gyro is None else 6
    x = np.empty((len(accel), 2 * d + 1))
    np.subtract(accel, ref_a, out=x[:, 0:3])
    if gyro is not None:
        np.subtract(gyro, ref_g, out=x[:, 3:6])
    np.multiply(x[:, :d], x[:, :d], out=x[:, d : 2 * d])
    x[:, -1] = bad
    if bad.any():
        x[bad, :-1] = 0.0
    return x


def _levels(stats: _Stats, noise: NoiseFloor, thr: Thresholds) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(level, ||var_w(a)||, ||mean_w(omega) - b||) for each window."""
    a_norm = _norm3(stats.accel_var)
    level = a_norm / max(thr.accel_var_norm, _TINY)
    g_dev = None
    if thr.gyro_rate is not None and stats.gyro_mean is not None:
        g_dev = _norm3(stats.gyro_mean, minus=noise.gyro_bias)
        level = np.maximum(level, g_dev / max(thr.gyro_rate, _TINY))
    bad = stats.has_nan
    if bad.any():
        level = level.copy()
        level[bad] = np.inf
        a_norm = a_norm.copy()
        a_norm[bad] = np.nan
        if g_dev is not None:
            g_dev = g_dev.copy()
            g_dev[bad] = np.nan
    return level, a_norm, g_dev


def _median_square(d: np.ndarray) -> np.ndarray:
    """Per column, the median of ``d``'s squares; ``d`` (a scratch array) is overwritten. The
    same values as ``np.median(d * d, axis=0)`` without its two (N, 3) copies."""
    np.square(d, out=d)
    return np.median(d, axis=0, overwrite_input=True)


def _valid_diffs(x: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """Differences of consecutive rows that are both valid."""
    d = np.diff(x, axis=0)
    if not bad.any():
        return d
    return np.take(d, np.flatnonzero(~(bad[1:] | bad[:-1])), axis=0)


def _lsb(x: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """Per axis, the smallest non-zero step between consecutive valid rows (0 if none)."""
    keep = None if not bad.any() else np.flatnonzero(~(bad[1:] | bad[:-1]))
    out = np.empty(x.shape[1])
    for k in range(x.shape[1]):  # column by column: (N,) temporaries, not (N, 3)
        d = np.diff(x[:, k])
        if keep is not None:
            d = d[keep]
        np.abs(d, out=d)
        out[k] = np.min(d, where=d > 0, initial=np.inf)
    return np.where(np.isfinite(out), out, 0.0)


def _noise_from_windows(ref: _Stats, lsb_a: np.ndarray, lsb_g: np.ndarray | None, source: str) -> NoiseFloor:
    accel_var = np.maximum(np.median(ref.accel_var, axis=0), lsb_a * lsb_a / 12.0)
    gyro_var = gyro_bias = None
    if ref.gyro_var is not None:
        gyro_var = np.maximum(np.median(ref.gyro_var, axis=0), lsb_g * lsb_g / 12.0)
        gyro_bias = np.median(ref.gyro_mean, axis=0)
    return NoiseFloor(accel_var, gyro_var, gyro_bias, source, len(ref))


def _thresholds(noise: NoiseFloor, cfg: StillnessConfig, has_gyro: bool) -> Thresholds:
    thr_a = cfg.threshold_factor * float(_norm3(noise.accel_var[None, :])[0])
    thr_g = None
    if has_gyro and cfg.gyro_rate_factor is not None:
        thr_g = cfg.gyro_rate_factor * math.sqrt(float(np.sum(noise.gyro_var)))
    return Thresholds(thr_a, thr_g, cfg.threshold_factor, cfg.gyro_rate_factor if thr_g is not None else None)


def _scale(x: np.ndarray) -> float:
    for v in (np.median(x), np.mean(x)):
        if v > 0:
            return float(v)
    return 1.0


def _robust_noise(
    stats: _Stats, accel: np.ndarray, gyro: np.ndarray | None, bad: np.ndarray, quantile: float
) -> tuple[NoiseFloor, list[str]]:
    """Noise floor without an initial rest.

    Score each valid window by its accelerometer (and rate) variance magnitude, each
    divided by its median; the reference windows are those scoring at most twice the
    `quantile` quantile of the scores. If at least that fraction of the windows is at
    rest, the quantile lies among rest windows (about 0.8x the rest level for w ~ 100),
    and twice it takes in nearly every rest window and few moving ones; their median
    is the rest noise. Cross-check: the variance of first differences / 2 is the white
    noise of a moving signal too (smooth motion barely changes from one sample to the
    next); when the floor exceeds it more than 10x, the quietest windows are not at rest
    and the first-difference noise is used instead (`source='first_differences'`).
    """
    valid = ~stats.has_nan
    if not valid.any():
        raise StillnessInputError("every window contains a NaN row: nothing to measure noise on")
    v = stats.where(valid)
    score = _norm3(v.accel_var) / _scale(_norm3(v.accel_var))
    if v.gyro_var is not None:
        g = _norm3(v.gyro_var)
        score = score + g / _scale(g)
    q = np.quantile(score, quantile)
    ref = v.where(score <= 2.0 * q)
    lsb_a = _lsb(accel, bad)
    lsb_g = None if gyro is None else _lsb(gyro, bad)
    noise = _noise_from_windows(ref, lsb_a, lsb_g, "robust")

    d = _valid_diffs(accel, bad)  # a new array: squared and partitioned in place (two copies of (N, 3) fewer)
    diff_var_a = _median_square(d) / (2.0 * _CHI2_1_MEDIAN) if len(d) else np.zeros(3)
    floor = float(_norm3(noise.accel_var[None, :])[0])
    diff = float(_norm3(diff_var_a[None, :])[0])
    warnings: list[str] = []
    if diff > 0 and floor > _FLOOR_TO_DIFF_MAX * diff:
        gyro_var = gyro_bias = None
        if gyro is not None:
            dg = _valid_diffs(gyro, bad)
            gyro_var = np.maximum(_median_square(dg) / (2.0 * _CHI2_1_MEDIAN), lsb_g * lsb_g / 12.0)
            gyro_bias = np.median(gyro[~bad], axis=0)
        noise = NoiseFloor(np.maximum(diff_var_a, lsb_a * lsb_a / 12.0), gyro_var, gyro_bias, "first_differences", 0)
        warnings.append(
            f"no rest found: the quietest {quantile:.0%} of windows vary {floor / diff:.0f}x more "
            "than sample-to-sample noise; thresholds use the first-difference noise"
        )
    return noise, warnings


# ------------------------------------------------------------------ input checks


def _as_rows(name: str, x, n: int | None) -> np.ndarray:
    try:
        a = np.ascontiguousarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise StillnessInputError(f"{name} is not numeric: {exc}") from None
    if a.ndim != 2 or a.shape[1] != 3:
        raise StillnessInputError(f"{name} must have shape (N, 3), got {a.shape}")
    if n is not None and len(a) != n:
        raise StillnessInputError(f"{name} has {len(a)} rows but t_s has {n}")
    return a


def _check_inputs(t_s, accel, gyro, nan_policy: str, row0: int = 0, t_prev: float | None = None):
    if nan_policy not in ("raise", "omit"):
        raise StillnessInputError(f"nan_policy must be 'raise' or 'omit', got {nan_policy!r}")
    t = np.ascontiguousarray(t_s, dtype=float)
    if t.ndim != 1:
        raise StillnessInputError(f"t_s must be one-dimensional, got shape {t.shape}")
    a = _as_rows("accel", accel, len(t))
    g = None if gyro is None else _as_rows("gyro", gyro, len(t))
    if len(t):
        if not np.isfinite(t).all():
            r = row0 + int(np.flatnonzero(~np.isfinite(t))[0])
            raise StillnessInputError(f"row {r}: t_s is not a finite number", r)
        if t_prev is not None and not t[0] > t_prev:
            raise StillnessInputError(f"row {row0}: t_s does not increase", row0)
        if len(t) > 1 and not (t[1:] > t[:-1]).all():
            r = row0 + 1 + int(np.flatnonzero(t[1:] <= t[:-1])[0])
            raise StillnessInputError(f"row {r}: t_s does not increase", r)
    if np.isfinite(a).all() and (g is None or np.isfinite(g).all()):
        return t, a, g, np.zeros(len(t), dtype=bool)
    fin = np.isfinite(a).all(axis=1)
    if g is not None:
        fin &= np.isfinite(g).all(axis=1)
    bad = ~fin
    if nan_policy == "raise" and bad.any():
        r = row0 + int(np.flatnonzero(bad)[0])
        raise StillnessInputError(
            f"row {r}: NaN or infinite value in accel/gyro (pass nan_policy='omit' to treat such rows as motion)", r
        )
    return t, a, g, bad


# ------------------------------------------------------------------ batch detector


def _interval(t, a, g, start, stop) -> StaticInterval:
    n = stop - start
    seg = a[start:stop]
    std = seg.std(axis=0, ddof=1) if n > 1 else np.full(3, np.nan)
    gm = gs = None
    if g is not None:
        gseg = g[start:stop]
        gm = gseg.mean(axis=0)
        gs = gseg.std(axis=0, ddof=1) if n > 1 else np.full(3, np.nan)
    return StaticInterval(
        int(start), int(stop), float(t[start]), float(t[stop - 1]), int(n), seg.mean(axis=0), std, gm, gs
    )


def detect_static_intervals(
    t_s,
    accel,
    gyro=None,
    *,
    init_rest_s: float | None = None,
    sample_rate_hz: float | None = None,
    window_s: float = 1.0,
    threshold_factor: float = 5.0,
    gyro_rate_factor: float | None = 10.0,
    min_duration_s: float = 1.0,
    margin_s: float | None = None,
    robust_quantile: float = 0.1,
    nan_policy: str = "raise",
    gyro_std_floor: float | None = None,
) -> StillnessResult:
    """Find the static intervals of a recording.

    t_s: (N,) sample times [s], strictly increasing.
    accel: (N, 3) accelerometer, any units. gyro: (N, 3) rates, any units, or None.
    init_rest_s: length of the operator's initial rest [s]. The noise reference is then the
        windows that lie inside the first round(init_rest_s * rate) samples
        (source 'initial_rest'). None or 0: estimated from the data (source 'robust',
        which needs at least `robust_quantile` of the windows to be at rest; when the
        quietest windows are plainly moving, 'first_differences').
    sample_rate_hz: None = 1 / median(diff(t_s)).
    window_s, threshold_factor, gyro_rate_factor, min_duration_s, margin_s: see
        `StillnessConfig`.
    nan_policy: 'raise' (StillnessInputError naming the first bad row) or 'omit' (windows
        containing a non-finite row are motion; indices keep referring to the input rows).
    gyro_std_floor: the smallest per-axis noise (standard deviation of one sample) the rates
        are taken to have [gyro unit], or None. Noise-free (simulated) rates measure a noise of
        ~0 (their rounding), and the rate test then calls any change of the bias a turn: a
        noise-free P4 record whose bias drifted 2e-7 rad/s per s kept 6.6 s of its 300.

    Raises StillnessInputError (a ValueError and a SolverError) on bad input: mismatched
    lengths, wrong shapes, non-increasing or NaN times, too few samples for one window,
    an initial rest longer than the data or shorter than one window.
    """
    t, a, g, bad = _check_inputs(t_s, accel, gyro, nan_policy)
    n = len(t)
    if n < 2:
        raise StillnessInputError(f"{n} samples: too few to detect anything")
    if sample_rate_hz is None:
        sample_rate_hz = 1.0 / float(np.median(np.diff(t)))
    cfg = StillnessConfig(sample_rate_hz, window_s, threshold_factor, gyro_rate_factor, min_duration_s, margin_s)
    if not 0 < robust_quantile < 1:
        raise StillnessInputError(f"robust_quantile must be in (0, 1), got {robust_quantile!r}")
    w, h = cfg.window_n, cfg.half_n
    if n < w:
        raise StillnessInputError(
            f"{n} samples is shorter than one {w}-sample window ({cfg.window_s:g} s at {cfg.sample_rate_hz:g} Hz)"
        )
    has_gyro = g is not None
    if bad.all():
        raise StillnessInputError("every row contains NaN: nothing to detect")
    first_ok = int(np.flatnonzero(~bad)[0])
    ref_a = a[first_ok].copy()
    ref_g = g[first_ok].copy() if has_gyro else None

    # windowed statistics, the same engine as the tracker, fed in chunks to bound memory
    engine = _WindowSums(w, cfg.block_n, 13 if has_gyro else 7)
    stats = _Stats.empty(n - w + 1, has_gyro)
    k = 0
    for i in range(0, n, _BATCH_CHUNK):
        j = min(n, i + _BATCH_CHUNK)
        sums = engine.push(_channels(a[i:j], None if g is None else g[i:j], bad[i:j], ref_a, ref_g))
        stats.put(k, _Stats.from_sums(sums, w, has_gyro, ref_g))
        k += len(sums)
    del engine, sums

    warnings: list[str] = []
    if init_rest_s:
        n_init = int(round(float(init_rest_s) * cfg.sample_rate_hz))
        if n_init > n:
            raise StillnessInputError(f"init_rest_s={init_rest_s:g} s needs {n_init} samples, the data has {n}")
        if n_init < w:
            raise StillnessInputError(
                f"init_rest_s={init_rest_s:g} s ({n_init} samples) is shorter than one {w}-sample window"
            )
        noise = _initial_rest_noise(stats, a, g, bad, n_init, w)
        robust, _ = _robust_noise(stats, a, g, bad, robust_quantile)
        ratio = float(_norm3(noise.accel_var[None, :])[0] / _norm3(robust.accel_var[None, :])[0])
        if ratio > 4.0:
            warnings.append(
                f"the initial rest is {ratio:.1f}x noisier than the quietest windows of the "
                "recording: was the unit moving during it?"
            )
    else:
        noise, warnings = _robust_noise(stats, a, g, bad, robust_quantile)

    if gyro_std_floor is not None and noise.gyro_var is not None:
        noise = dataclasses.replace(noise, gyro_var=np.maximum(noise.gyro_var, float(gyro_std_floor) ** 2))
    thr = _thresholds(noise, cfg, has_gyro)
    lev_w, a_norm_w, g_dev_w = _levels(stats, noise, thr)
    del stats  # nine values per window, no longer needed: freed before the intervals' statistics

    # each per-sample series holds its window values (kept as views: one copy of each, not two)
    level = np.full(n, np.nan)
    level[h : n - h] = lev_w
    lev_w = level[h : n - h]
    a_norm = np.full(n, np.nan)
    a_norm[h : n - h] = a_norm_w
    del a_norm_w
    g_dev = None
    if g_dev_w is not None:
        g_dev = np.full(n, np.nan)
        g_dev[h : n - h] = g_dev_w
        del g_dev_w

    # runs of static window centres -> trimmed intervals
    still = lev_w < 1.0
    edges = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    run_first = np.flatnonzero(edges == 1) + h  # centre sample of the first static window
    run_last = np.flatnonzero(edges == -1) - 1 + h
    m = cfg.margin_n
    starts = np.where(run_first == h, 0, run_first - h + m)
    stops = np.where(run_last == n - 1 - h, n, run_last + h - m + 1)
    keep = (stops - starts) >= cfg.min_n
    intervals = [_interval(t, a, g, s, e) for s, e in zip(starts[keep], stops[keep])]
    return StillnessResult(intervals, noise, thr, cfg, level, a_norm, g_dev, n, warnings)


def _initial_rest_noise(stats: _Stats, a, g, bad, n_init: int, w: int) -> NoiseFloor:
    """Noise from the windows lying wholly inside rows [0, n_init)."""
    ref = stats.take(slice(0, n_init - w + 1))
    ref = ref.where(~ref.has_nan)
    if len(ref) == 0:
        raise StillnessInputError("every window of the initial rest contains a NaN row")
    lsb_a = _lsb(a[:n_init], bad[:n_init])
    lsb_g = None if g is None else _lsb(g[:n_init], bad[:n_init])
    return _noise_from_windows(ref, lsb_a, lsb_g, "initial_rest")


# ------------------------------------------------------------------ incremental tracker


class _Moments:
    """Running count, mean and sum of squared deviations (Chan et al. pairwise update)."""

    def __init__(self, d: int):
        self.n = 0
        self.mean = np.zeros(d)
        self.m2 = np.zeros(d)

    def add(self, x: np.ndarray) -> None:
        nb = len(x)
        if nb == 0:
            return
        if nb == 1:
            mb, m2b = x[0], 0.0
        else:
            mb = x.mean(axis=0)
            d = x - mb
            m2b = (d * d).sum(axis=0)
        if self.n == 0:
            self.n, self.mean, self.m2 = nb, np.array(mb, dtype=float), m2b + np.zeros(len(self.mean))
            return
        n = self.n + nb
        delta = mb - self.mean
        self.mean = self.mean + delta * (nb / n)
        self.m2 = self.m2 + m2b + delta * delta * (self.n * nb / n)
        self.n = n

    @property
    def std(self) -> np.ndarray:
        if self.n < 2:
            return np.full(len(self.mean), np.nan)
        return np.sqrt(self.m2 / (self.n - 1))


@dataclass(frozen=True)
class TrackerState:
    """What a live display needs after each `StillnessTracker.update`.

    n_samples: rows received so far. t_s: time of the newest row [s] (NaN before any).
    calibrating: True while the initial rest is still being recorded (no decision yet).
    level: decision statistic / threshold for the newest complete window (see
        `StillnessResult.level`); NaN before the first decision. Draw it as a bar; < 1 is
        static. It refers to the window centred window_s/2 before the newest row.
    is_still: the newest window is static. still_for_s: time from the first row of the
        current static run to the newest row [s] (0 when moving).
    accel_mean, accel_std, gyro_mean, gyro_std: running statistics of the rows of the
        current interval confirmed so far (None when moving or none confirmed yet).
    n_intervals: intervals completed so far. new_intervals: those completed by this update.
    """

    n_samples: int
    t_s: float
    calibrating: bool
    level: float
    is_still: bool
    still_for_s: float
    accel_mean: np.ndarray | None
    accel_std: np.ndarray | None
    gyro_mean: np.ndarray | None
    gyro_std: np.ndarray | None
    n_intervals: int
    new_intervals: tuple[StaticInterval, ...] = ()


# columns of the tracker's row store
_T, _BAD, _A, _G = 0, 1, slice(2, 5), slice(5, 8)


class StillnessTracker:
    """Incremental stillness detector for live streams (batches of any size, O(batch)).

    Give either ``init_rest_s`` (the first seconds of the stream are a rest: the noise is
    measured on them, as the batch detector does with the same argument) or ``noise``
    (e.g. ``result.noise`` of an earlier batch run; see `from_result`). Fed the same rows,
    in any split into batches, it reports the same intervals as `detect_static_intervals`
    with the same settings (`finish` closes a run still open at the end); interval means
    and standard deviations agree to rounding (they are accumulated, not recomputed).

    The decision for a row needs the window centred on it, so it lags the newest row by
    window_s/2. Memory is bounded (a few windows of rows) once the noise is known.
    """

    def __init__(
        self,
        sample_rate_hz: float,
        *,
        init_rest_s: float | None = None,
        noise: NoiseFloor | None = None,
        window_s: float = 1.0,
        threshold_factor: float = 5.0,
        gyro_rate_factor: float | None = 10.0,
        min_duration_s: float = 1.0,
        margin_s: float | None = None,
        nan_policy: str = "raise",
    ):
        self.config = StillnessConfig(
            float(sample_rate_hz), window_s, threshold_factor, gyro_rate_factor, min_duration_s, margin_s
        )
        if (noise is None) == (not init_rest_s):
            raise StillnessInputError("give exactly one of init_rest_s (> 0) or noise")
        if nan_policy not in ("raise", "omit"):
            raise StillnessInputError(f"nan_policy must be 'raise' or 'omit', got {nan_policy!r}")
        self.nan_policy = nan_policy
        cfg = self.config
        self._w, self._h, self._m = cfg.window_n, cfg.half_n, cfg.margin_n
        self._n_init = 0
        if init_rest_s:
            self._n_init = int(round(float(init_rest_s) * cfg.sample_rate_hz))
            if self._n_init < self._w:
                raise StillnessInputError(
                    f"init_rest_s={init_rest_s:g} s ({self._n_init} samples) is shorter than "
                    f"one {self._w}-sample window"
                )
        self.noise: NoiseFloor | None = noise
        self.thresholds: Thresholds | None = None
        self.intervals: list[StaticInterval] = []
        self._has_gyro: bool | None = None
        self._engine: _WindowSums | None = None
        self._ref_a = self._ref_g = None
        self._n_windows = 0  # windows decided
        self._pending: list[_Stats] = []  # windows waiting for the noise estimate
        # rows [t, bad, a, g]: all of them until the noise is known, then a few windows
        self._keep = self._w + max(self._m, 0) + 2
        self._rows = _RowStore(8, keep=self._keep if noise is not None else None)
        self._run_open = False
        self._run_start = -1  # first row of the (trimmed) interval
        self._run_t0 = math.nan  # time of the first row covered by the run
        self._run_t_start = math.nan  # time of the interval's first row
        self._acc_next = 0  # next row to add to the moments
        self._mom_a = _Moments(3)
        self._mom_g = _Moments(3)
        self._level = math.nan
        self._t_last = math.nan
        self._finished = False
        self._new: list[StaticInterval] = []

    @classmethod
    def from_result(cls, result: StillnessResult, *, nan_policy: str = "raise") -> StillnessTracker:
        """A tracker with the settings and the noise floor of a batch result."""
        c = result.config
        return cls(
            c.sample_rate_hz,
            noise=result.noise,
            window_s=c.window_s,
            threshold_factor=c.threshold_factor,
            gyro_rate_factor=c.gyro_rate_factor,
            min_duration_s=c.min_duration_s,
            margin_s=c.margin_s,
            nan_policy=nan_policy,
        )

    # -- public

    @property
    def n_samples(self) -> int:
        return self._rows.end

    @property
    def state(self) -> TrackerState:
        still = self._run_open
        have = still and self._mom_a.n > 0
        return TrackerState(
            n_samples=self._rows.end,
            t_s=self._t_last,
            calibrating=self.thresholds is None,
            level=self._level,
            is_still=still,
            still_for_s=(self._t_last - self._run_t0) if still else 0.0,
            accel_mean=self._mom_a.mean.copy() if have else None,
            accel_std=self._mom_a.std if have else None,
            gyro_mean=self._mom_g.mean.copy() if have and self._has_gyro else None,
            gyro_std=self._mom_g.std if have and self._has_gyro else None,
            n_intervals=len(self.intervals),
            new_intervals=tuple(self._new),
        )

    def update(self, t_s, accel, gyro=None) -> TrackerState:
        """Add rows (t_s (m,), accel (m, 3), gyro (m, 3) or None); return the new state."""
        if self._finished:
            raise StillnessInputError("the tracker is finished; make a new one")
        n0 = self._rows.end
        t, a, g, bad = _check_inputs(t_s, accel, gyro, self.nan_policy, n0, None if n0 == 0 else self._t_last)
        if self._has_gyro is None:
            if self.noise is not None and g is not None and self.noise.gyro_var is None:
                raise StillnessInputError("the noise floor given has no gyro part, but gyro rows are")
            self._has_gyro = g is not None
            self._engine = _WindowSums(self._w, self.config.block_n, 13 if self._has_gyro else 7)
        elif self._has_gyro != (g is not None):
            raise StillnessInputError("gyro must be given in every update or in none")
        self._new = []
        m = len(t)
        if m == 0:
            return self.state
        if self._ref_a is None and not bad.all():
            k = int(np.flatnonzero(~bad)[0])
            self._ref_a = a[k].copy()
            self._ref_g = g[k].copy() if g is not None else None
        ref_a = self._ref_a if self._ref_a is not None else np.zeros(3)
        ref_g = None
        if g is not None:
            ref_g = self._ref_g if self._ref_g is not None else np.zeros(3)

        sums = self._engine.push(_channels(a, g, bad, ref_a, ref_g))
        stats = _Stats.from_sums(sums, self._w, g is not None, ref_g)
        rows = self._rows.extend(m)
        rows[:, _T] = t
        rows[:, _BAD] = bad
        rows[:, _A] = a
        if g is not None:
            rows[:, _G] = g
        self._t_last = float(t[-1])

        if self.thresholds is None:
            if self.noise is None:
                self._pending.append(stats)
                if self._rows.end < self._n_init:
                    return self.state
                stats = _Stats.concat(self._pending)
                self._pending = []
                init = self._rows.rows(0, self._n_init)
                ig = init[:, _G] if self._has_gyro else None
                self.noise = _initial_rest_noise(stats, init[:, _A], ig, init[:, _BAD] > 0.5, self._n_init, self._w)
                self._rows.keep = self._keep
            self.thresholds = _thresholds(self.noise, self.config, self._has_gyro)

        if len(stats):
            level, _, _ = _levels(stats, self.noise, self.thresholds)
            self._decide(level < 1.0)
            self._level = float(level[-1])
        return self.state

    def finish(self) -> list[StaticInterval]:
        """End of stream: close a run reaching the last row; return all intervals."""
        if not self._finished:
            self._finished = True
            self._new = []
            if self._run_open:
                self._add_rows(self._acc_next, self._rows.end - 1)
                self._close(self._rows.end)
        return list(self.intervals)

    # -- internals

    def _decide(self, still: np.ndarray) -> None:
        """Advance the run state over newly decided windows (centres c0 .. c0+k-1)."""
        h, mg = self._h, self._m
        c0 = self._n_windows + h
        k = len(still)
        self._n_windows += k
        if self._run_open and still.all():  # the run goes on
            self._add_rows(self._acc_next, c0 + k - 1 + h - mg)
            return
        if not self._run_open and not still.any():  # still moving
            return
        edges = np.diff(np.concatenate([[1 if self._run_open else 0], still.astype(np.int8), [0]]))
        firsts = np.flatnonzero(edges == 1)
        lasts = np.flatnonzero(edges == -1) - 1
        if self._run_open:
            firsts = np.concatenate([[-1], firsts])  # -1: the open run continues
        for f, l in zip(firsts, lasts):
            if f >= 0:
                cs = c0 + int(f)
                self._run_open = True
                self._run_start = 0 if cs == h else cs - h + mg
                self._run_t0 = float(self._rows.rows(cs - h, cs - h + 1)[0, _T])
                self._run_t_start = math.nan
                self._acc_next = self._run_start
                self._mom_a = _Moments(3)
                self._mom_g = _Moments(3)
            ce = c0 + int(l)
            self._add_rows(self._acc_next, ce + h - mg)
            if l < k - 1:  # the window after ce is not static: the run ends
                self._close(ce + h - mg + 1)

    def _add_rows(self, i0: int, i1: int) -> None:
        """Add rows i0..i1 (absolute, inclusive) to the running moments."""
        i0 = max(i0, self._run_start)
        i1 = min(i1, self._rows.end - 1)
        if i1 < i0:
            return
        r = self._rows.rows(i0, i1 + 1)
        if i0 == self._run_start:
            self._run_t_start = float(r[0, _T])
        self._mom_a.add(r[:, _A])
        if self._has_gyro:
            self._mom_g.add(r[:, _G])
        self._acc_next = i1 + 1

    def _close(self, stop: int) -> None:
        start = self._run_start
        self._run_open = False
        if stop - start < self.config.min_n:
            return
        if self._mom_a.n != stop - start:  # every row start..stop-1 must have been added
            raise RuntimeError(f"stillness tracker lost rows of interval [{start}, {stop})")
        iv = StaticInterval(
            start,
            stop,
            self._run_t_start,
            float(self._rows.rows(stop - 1, stop)[0, _T]),
            stop - start,
            self._mom_a.mean.copy(),
            self._mom_a.std,
            self._mom_g.mean.copy() if self._has_gyro else None,
            self._mom_g.std if self._has_gyro else None,
        )
        self.intervals.append(iv)
        self._new.append(iv)


# ------------------------------------------------------------------ orientations


@dataclass(frozen=True)
class OrientationClusters:
    """Static intervals grouped by the direction of their mean specific force.

    labels: (k,) cluster index of each interval; clusters are numbered in the order in
        which they first occur in time.
    n_orientations: number of distinct orientations.
    directions: (n_orientations, 3) unit mean direction of each cluster (duration-weighted).
    spread_deg: (n_orientations,) largest angle between a member and its cluster direction.
    offset: (3,) zero-g reading subtracted before taking directions [accel unit].
    """

    labels: np.ndarray
    n_orientations: int
    directions: np.ndarray
    spread_deg: np.ndarray
    offset: np.ndarray


def _fit_sphere_centre(means: np.ndarray) -> np.ndarray:
    """Centre o of the sphere through the points: |m|^2 = 2 m.o + c, linear least squares."""
    if len(means) < 4:
        raise TooFewPositions(
            f"{len(means)} static intervals: fitting the zero-g offset needs at least 4 "
            "orientations that are not all in one plane"
        )
    a = np.hstack([2.0 * means, np.ones((len(means), 1))])
    b = np.sum(means * means, axis=1)
    sv = linalg.svd(a, compute_uv=False)
    if sv[-1] <= 1e-9 * sv[0]:
        raise NotIdentifiable(
            "the interval means lie in one plane: the zero-g offset cannot be fitted; pass offset= explicitly"
        )
    sol, *_ = linalg.lstsq(a, b, rcond=None)
    return sol[:3]


def cluster_orientations(
    intervals: Sequence[StaticInterval] | np.ndarray, max_angle_deg: float = 5.0, *, offset=None
) -> OrientationClusters:
    """Group static intervals whose mean gravity directions agree within max_angle_deg.

    intervals: StaticInterval objects (weighted by their sample count) or a (k, 3) array of
        mean accelerometer readings (equal weights).
    offset: the reading at zero specific force, subtracted before taking directions:
        None = zero (signed data: m/s^2, g, signed counts), a (3,) array, or 'sphere' to
        fit the centre of the sphere through the means (unsigned ADC counts such as the
        Xsens set centred near 32768; needs 4 or more non-coplanar orientations).

    Leader clustering: intervals are taken longest first; each joins the cluster whose
    current direction is nearest if within max_angle_deg, else starts a new one; finally
    each interval is assigned to its nearest cluster direction.
    """
    if isinstance(intervals, np.ndarray):
        means = np.asarray(intervals, dtype=float).reshape(-1, 3)
        weights = np.ones(len(means))
    else:
        means = np.array([iv.accel_mean for iv in intervals], dtype=float).reshape(-1, 3)
        weights = np.array([iv.n for iv in intervals], dtype=float)
    if not (0 < max_angle_deg < 180):
        raise StillnessInputError(f"max_angle_deg must be in (0, 180), got {max_angle_deg!r}")
    if len(means) == 0:
        return OrientationClusters(np.zeros(0, int), 0, np.zeros((0, 3)), np.zeros(0), np.zeros(3))
    if isinstance(offset, str):
        if offset != "sphere":
            raise StillnessInputError(f"offset must be None, a (3,) array or 'sphere', got {offset!r}")
        off = _fit_sphere_centre(means)
    else:
        off = np.zeros(3) if offset is None else np.asarray(offset, dtype=float).reshape(3)
    v = means - off
    norms = np.linalg.norm(v, axis=1)
    if np.any(norms <= 0) or not np.all(np.isfinite(norms)):
        raise StillnessInputError("an interval mean is zero or not finite after removing the offset")
    u = v / norms[:, None]
    cos_max = math.cos(math.radians(max_angle_deg))

    sums: list[np.ndarray] = []
    for i in np.argsort(-weights, kind="stable"):
        if sums:
            d = np.array([s / np.linalg.norm(s) for s in sums])
            c = d @ u[i]
            j = int(np.argmax(c))
            if c[j] >= cos_max:
                sums[j] = sums[j] + weights[i] * u[i]
                continue
        sums.append(weights[i] * u[i])
    d = np.array([s / np.linalg.norm(s) for s in sums])
    raw = np.argmax(u @ d.T, axis=1)
    # renumber by first occurrence in time, dropping clusters left empty
    order: list[int] = []
    for r in raw:
        if r not in order:
            order.append(int(r))
    labels = np.array([order.index(int(r)) for r in raw], dtype=int)
    dirs, spread = [], []
    for k in range(len(order)):
        members = labels == k
        s = (weights[members, None] * u[members]).sum(axis=0)
        dk = s / np.linalg.norm(s)
        dirs.append(dk)
        spread.append(float(np.degrees(np.arccos(np.clip(u[members] @ dk, -1.0, 1.0))).max()))
    return OrientationClusters(labels, len(order), np.array(dirs), np.array(spread), off)
