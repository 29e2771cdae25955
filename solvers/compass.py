"""P3 · electronic compass calibration (source 002, CN102252689A): the numerics.

The chain (procedures.md P3), each step a function here:

1. Low-pass filters (Butterworth, order 2): accelerometer ``ACCEL_CUTOFF_HZ`` = 5 Hz,
   gyro ``GYRO_CUTOFF_HZ`` = 10 Hz, magnetometer ``MAG_CUTOFF_HZ`` = 5 Hz (hand motion of a
   compass being turned lives below ~2 Hz; tremor and sensor noise above). Two forms:
   :func:`lowpass` with ``zero_phase=True`` (``sosfiltfilt``: no delay, for recorded
   captures) and :class:`CausalLowpass` (``sosfilt`` with carried state, for live use; a
   group delay of about 1/(2π f_c)·√2 ≈ 45 ms at 5 Hz). A cut-off at or above Nyquist
   leaves the signal unfiltered.
2. Pitch and roll from the filtered accelerometer (:func:`pitch_roll_from_accel`). Body
   axes x forward, y right, z down (``solvers/frames.py``); the accelerometer reads specific
   force (+g on the up axis). Data that report the gravity direction are flipped by the
   caller, with a warning (:func:`detect_accel_sign`).
3. Two scalar Kalman filters, pitch and roll (:class:`AngleKalman`, :func:`kalman_pitch_roll`):
   state ``[angle, rate bias]``, propagated with the Euler-angle rate computed from the gyro
   (``θ̇ = q cos φ − r sin φ``, ``φ̇ = p + tan θ (q sin φ + r cos φ)``; without a z gyro, r = 0:
   the source's two-axis gyro), corrected by the accelerometer angle. Noise (documented in
   :class:`KalmanConfig`): angle random walk ``q_angle``, bias random walk ``q_bias``,
   accelerometer-angle error density ``r_angle`` inflated while ``|f|`` departs from 1 g (the hand
   accelerates) and, for roll, as ``1/cos²θ`` near ±90° pitch where roll is undefined.
4. Magnetometer: raw → nT by W. The reference magnitude ``F`` is IGRF's total field at the
   capture's place and date (``solvers.geomag``). Model (``solvers.models.mag``, baseline):
   ``m = W (y − h)`` with ``|m| = F``; W upper triangular with a positive diagonal (this
   fixes the rotation the norm cannot see: W is the Cholesky factor of ``F² A``, A the
   ellipsoid matrix).

   - :func:`ellipsoid_fit`: algebraic quadric fit (10 coefficients, smallest singular vector
     on centred, scaled data), centre ``h = −A⁻¹b/2``, ``A_n = A / (hᵀAh − c)`` must be
     positive definite; ``W = F · chol(A_n)ᵀ`` (upper). The source's counts are parameter
     counts: 6 orientations determine the axis-aligned ellipsoid (diagonal W, h: 6
     unknowns), 9 the full upper-triangular W and h. With >= 9 distinct orientations the
     general ellipsoid starts the RLS; with 6–8 only the axis-aligned one is fitted
     (``method='ellipsoid'``; the RLS is refused).
   - :class:`MagRLS`: recursive least squares on all 9 parameters (6 upper elements of W,
     h), started from the ellipsoid values. The measurement ``F = |W(y − h)|`` is
     nonlinear; each sample is linearised at the current estimate (extended RLS):
     ``H = ∂|W(y−h)|/∂θ`` = ``(û_i d_j)`` for W_ij (i ≤ j) and ``−Wᵀû`` for h, with
     ``d = y − h``, ``û = W d / |W d|``; innovation ``F − |W d|``; measurement variance
     ``σ² |Wᵀû|²`` (the raw noise σ projected on the ellipsoid's normal, which is what makes
     the radial residual the maximum-likelihood one). Two linearisations
     (:class:`MagRLS`): ``'running'`` at the current estimate (extended RLS, for live
     streams), and ``'fixed'`` at the pass's starting point (for recorded captures: a pass
     is then exactly one Gauss–Newton step, independent of sample order; with time-ordered
     real data the running form wanders 0.3 σ from the batch optimum, the fixed form
     0.006 σ). Initial covariance: ``RLS_P0_INFLATION`` (1e4) times the Fisher covariance
     at the start, a weak prior (its pull is 1e-4 of the start's distance from the
     optimum). ``RLS_PASSES`` = 1 pass from the ellipsoid values (more passes iterate
     Gauss–Newton). Needs >= 9 distinct orientations. No forgetting by default (λ = 1).
   - :func:`batch_fit`: the same model through ``solvers.fit`` (Gauss–Newton/LM on all
     samples, same weights): the solution the RLS must converge to, and the source of the
     reported uncertainties.
   - Without a place (no IGRF) F is unknown: it is taken as the ellipsoid's mean radius
     times the unit's factor to nT (or 1 for raw units), a normalisation, not a reference.
5. Heading (:func:`heading_deg`): the calibrated field levelled with pitch and roll,
   ``m_l = R_y(θ) R_x(φ) m_b``, magnetic heading ``atan2(−m_l,y, m_l,x)``, true = magnetic +
   declination. Meaningless near ±90° pitch (reported NaN beyond ``HEADING_MAX_TILT_DEG``).

Coverage (:func:`coverage`): share of the sphere within ``COVERAGE_RADIUS_DEG`` = 30° of a
visited field direction (body frame), counted on ``COVERAGE_CELLS`` = 64 near-equal-area
cells (Fibonacci lattice); refused below ``MIN_COVERAGE`` = 40 %. Spread (:func:`spread`):
refused below 0.1 (all directions in one plane). Distinct orientations
(:func:`distinct_directions`): the greedy count of field directions at least
``DISTINCT_SEPARATION_DEG`` = 20° apart.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from solvers import linalg
from solvers.errors import NotIdentifiable, SolverError, TooFewPositions
from solvers.fit import FitResult, fit
from solvers.models import mag as mag_model

ACCEL_CUTOFF_HZ = 5.0
GYRO_CUTOFF_HZ = 10.0
MAG_CUTOFF_HZ = 5.0
FILTER_ORDER = 2

MIN_ELLIPSOID_ORIENTATIONS = 6
MIN_RLS_ORIENTATIONS = 9
DISTINCT_SEPARATION_DEG = 20.0
COVERAGE_CELLS = 64
COVERAGE_RADIUS_DEG = 30.0
MIN_COVERAGE = 0.40
MIN_SPREAD = 0.10
RLS_P0_INFLATION = 1e4
RLS_RUNNING_P0_INFLATION = 100.0  # running form: a firmer prior keeps early samples from dragging it
RLS_PASSES = 1
NOISE_BIAS_CORRECTION = True  # see noise_bias_nT
HEADING_MAX_TILT_DEG = 70.0

UPPER = np.triu_indices(3)  # W's free elements, row-major: 00 01 02 11 12 22
W_FREE = np.triu(np.ones((3, 3), dtype=bool))


class CoverageTooLow(SolverError):
    """The field directions do not cover enough of the sphere."""


# ---------------------------------------------------------------- 1. filters


def _signal():
    from scipy import signal  # imported lazily: scipy.signal takes seconds to load

    return signal


def _sos(cutoff_hz: float, rate_hz: float, order: int):
    signal = _signal()
    wn = cutoff_hz / (rate_hz / 2.0)
    if not (0.0 < wn < 1.0):
        return None
    return signal.butter(order, wn, btype="low", output="sos")


def lowpass(x, cutoff_hz: float, rate_hz: float, *, zero_phase: bool = True, order: int = FILTER_ORDER) -> np.ndarray:
    """Butterworth low-pass along axis 0. ``zero_phase``: forward-backward (``sosfiltfilt``,
    no delay, squared magnitude response) for recorded captures; else causal ``sosfilt``
    started at the first sample's value (live use, see :class:`CausalLowpass`)."""
    x = np.asarray(x, dtype=float)
    sos = _sos(cutoff_hz, rate_hz, order)
    if sos is None or len(x) < 3:
        return x.copy()
    if zero_phase:
        padlen = min(3 * (2 * len(sos) + 1), len(x) - 1)
        return _signal().sosfiltfilt(sos, x, axis=0, padlen=padlen)
    f = CausalLowpass(cutoff_hz, rate_hz, x.shape[1:] if x.ndim > 1 else (), order=order)
    return f.process(x)


class CausalLowpass:
    """Causal Butterworth low-pass for live streams: ``process(block)`` keeps the filter
    state between blocks, so feeding a signal in pieces equals filtering it whole. The
    state starts at steady state for the first sample (no start-up transient)."""

    def __init__(self, cutoff_hz: float, rate_hz: float, shape: tuple = (3,), *, order: int = FILTER_ORDER):
        self.sos = _sos(cutoff_hz, rate_hz, order)
        self.shape = tuple(shape)
        self.zi = None

    def process(self, block) -> np.ndarray:
        x = np.asarray(block, dtype=float)
        if self.sos is None or len(x) == 0:
            return x.copy()
        signal = _signal()
        if self.zi is None:
            zi0 = signal.sosfilt_zi(self.sos)  # (n_sections, 2), unit step steady state
            self.zi = zi0.reshape(zi0.shape + (1,) * x[0].ndim) * x[0]
        y, self.zi = signal.sosfilt(self.sos, x, axis=0, zi=self.zi)
        return y


# ---------------------------------------------------------------- 2. tilt from gravity


def pitch_roll_from_accel(f) -> tuple[np.ndarray, np.ndarray]:
    """Pitch θ and roll φ [rad] from specific force rows (any unit), body x fwd, y right,
    z down: at rest ``f = g (sin θ, −sin φ cos θ, −cos φ cos θ)``."""
    f = np.atleast_2d(np.asarray(f, dtype=float))
    pitch = np.arctan2(f[:, 0], np.hypot(f[:, 1], f[:, 2]))
    roll = np.arctan2(-f[:, 1], -f[:, 2])
    return pitch, roll


# ---------------------------------------------------------------- 3. Kalman filters


@dataclass
class KalmanConfig:
    """Noise of the pitch/roll Kalman filters (per filter; state [angle rad, bias rad/s]).

    q_angle_rad2_s: angle random-walk density of the gyro-propagated angle (1e-6 rad²/s ≈
        0.06°/√s: MEMS angle random walk with margin).
    q_bias_rad2_s3: rate-bias random walk (1e-8 (rad/s)²/s: MEMS bias instability).
    r_angle_rad2_s: density of the accelerometer-angle error at rest (2.5e-7 rad²·s); the
        per-sample variance is ``r / dt``, so the filter behaves the same at any rate; the
        time constant at rest is ``sqrt(r / q_angle)`` = 0.5 s, about 5 s while turning at
        0.5 rad/s.
    accel_dev_g, rate_ref_rad_s: ``r`` is multiplied by
        ``1 + ((|f| − 1 g)/accel_dev_g)² + (|ω|/rate_ref_rad_s)²``: while the hand turns the
        unit (and so accelerates it) the gyro carries the angle; held still, the
        accelerometer pulls it in with the time constant ``sqrt(r / q_angle)``.
    bias0_sigma_rad_s: initial bias uncertainty (0.05 rad/s ≈ 3°/s).
    """

    q_angle_rad2_s: float = 1e-6
    q_bias_rad2_s3: float = 1e-8
    r_angle_rad2_s: float = 2.5e-7
    accel_dev_g: float = 0.02
    rate_ref_rad_s: float = 0.05
    bias0_sigma_rad_s: float = 0.05


class AngleKalman:
    """One scalar-angle Kalman filter: state ``[angle, bias]``,
    ``angle_k+1 = angle_k + dt (rate − bias)``, measurement ``z = angle`` (accelerometer).
    ``wrap``: the angle is circular (roll) and innovations are wrapped to (−π, π]."""

    def __init__(self, angle0: float, config: KalmanConfig, *, wrap: bool = False):
        self.c = config
        self.wrap = wrap
        self.a = float(angle0)
        self.b = 0.0
        self.P = [0.05**2, 0.0, 0.0, config.bias0_sigma_rad_s**2]  # p00 p01 p10 p11

    def step(self, rate: float, z: float, dt: float, r_scale: float = 1.0) -> float:
        c = self.c
        a = self.a + dt * (rate - self.b)
        p00, p01, p10, p11 = self.P
        # P = F P Fᵀ + Q, F = [[1, −dt], [0, 1]]
        p00 = p00 - dt * (p10 + p01) + dt * dt * p11 + c.q_angle_rad2_s * dt
        p01 = p01 - dt * p11
        p10 = p10 - dt * p11
        p11 = p11 + c.q_bias_rad2_s3 * dt
        y = z - a
        if self.wrap:
            y = (y + math.pi) % (2.0 * math.pi) - math.pi
        s = p00 + c.r_angle_rad2_s / max(dt, 1e-6) * r_scale
        k0, k1 = p00 / s, p10 / s
        a += k0 * y
        self.b += k1 * y
        self.P = [p00 - k0 * p00, p01 - k0 * p01, p10 - k1 * p00, p11 - k1 * p01]
        if self.wrap:
            a = (a + math.pi) % (2.0 * math.pi) - math.pi
        self.a = a
        return a


class TiltKalman:
    """The two filters (pitch, roll) as one streaming object: ``process(t_s, f, ω)`` takes
    a block of samples and carries the state to the next block, so a live stream fed in
    pieces gives the same angles as the whole recording at once."""

    def __init__(self, config: KalmanConfig | None = None, g_unit: float = 1.0):
        self.config = config or KalmanConfig()
        self.g_unit = float(g_unit)
        self.kp: AngleKalman | None = None
        self.kr: AngleKalman | None = None
        self.t_last: float | None = None

    def process(self, t_s, f, omega_rad_s) -> tuple[np.ndarray, np.ndarray]:
        config = self.config
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        f = np.atleast_2d(np.asarray(f, dtype=float))
        w = np.atleast_2d(np.asarray(omega_rad_s, dtype=float)).copy()
        if w.shape[1] < 3:
            w = np.hstack([w, np.zeros((len(w), 3 - w.shape[1]))])
        w[~np.isfinite(w)] = 0.0
        n = len(t)
        pitch, roll = np.empty(n), np.empty(n)
        if n == 0:
            return pitch, roll
        th_acc, ph_acc = pitch_roll_from_accel(f)
        dev = (np.linalg.norm(f, axis=1) / self.g_unit - 1.0) / config.accel_dev_g
        turn = np.linalg.norm(w, axis=1) / config.rate_ref_rad_s
        r_scale = 1.0 + dev * dev + turn * turn
        k0 = 0
        if self.kp is None:
            self.kp = AngleKalman(th_acc[0], config)
            self.kr = AngleKalman(ph_acc[0], config, wrap=True)
            pitch[0], roll[0] = th_acc[0], ph_acc[0]
            self.t_last = float(t[0])
            k0 = 1
        kp, kr = self.kp, self.kr
        dts = np.diff(t, prepend=self.t_last)
        lim = math.radians(85.0)
        wl, thl, phl, rsl, dtl = w.tolist(), th_acc.tolist(), ph_acc.tolist(), r_scale.tolist(), dts.tolist()
        for k in range(k0, n):
            p_, q_, r_ = wl[k]
            th, ph = kp.a, kr.a
            sph, cph = math.sin(ph), math.cos(ph)
            thc = min(max(th, -lim), lim)
            th_dot = q_ * cph - r_ * sph
            ph_dot = p_ + math.tan(thc) * (q_ * sph + r_ * cph)
            dt = dtl[k]
            rs = rsl[k]
            cth = math.cos(thl[k])
            pitch[k] = kp.step(th_dot, thl[k], dt, rs)
            roll[k] = kr.step(ph_dot, phl[k], dt, rs / max(cth * cth, 1e-4))
        self.t_last = float(t[-1])
        return pitch, roll


def kalman_pitch_roll(
    t_s, f, omega_rad_s, config: KalmanConfig | None = None, g_unit: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Pitch and roll [rad] per sample from specific force ``f`` (rows, in units where 1 g =
    ``g_unit``) and body rates ``omega_rad_s`` (rows p, q, r; r may be NaN/absent → 0)."""
    return TiltKalman(config, g_unit).process(t_s, f, omega_rad_s)


class LiveCompass:
    """The whole chain for a live stream: causal low-pass filters (accelerometer, gyro,
    magnetometer), the tilt Kalman filters, the calibration ``m = W (y − h)`` and the
    tilt-compensated heading. ``update(t_s, accel_g, gyro_rad_s, mag_raw)`` takes a block
    (rows) and returns ``(pitch_rad, roll_rad, heading_magnetic_deg, heading_true_deg)``
    per row. The accelerometer must read specific force in g (flip a gravity-direction
    sensor before)."""

    def __init__(self, rate_hz: float, W, h, declination_deg: float = 0.0, config: KalmanConfig | None = None):
        self.W, self.h = np.asarray(W, float), np.asarray(h, float)
        self.declination_deg = float(declination_deg)
        self.f_acc = CausalLowpass(ACCEL_CUTOFF_HZ, rate_hz)
        self.f_gyr = CausalLowpass(GYRO_CUTOFF_HZ, rate_hz)
        self.f_mag = CausalLowpass(MAG_CUTOFF_HZ, rate_hz)
        self.tilt = TiltKalman(config)

    def update(self, t_s, accel_g, gyro_rad_s, mag_raw):
        f = self.f_acc.process(np.atleast_2d(accel_g))
        w = self.f_gyr.process(np.atleast_2d(gyro_rad_s))
        y = self.f_mag.process(np.atleast_2d(mag_raw))
        pitch, roll = self.tilt.process(t_s, f, w)
        mag, true = heading_deg(calibrated(y, self.W, self.h), pitch, roll, self.declination_deg)
        return pitch, roll, mag, true


# ---------------------------------------------------------------- coverage


def fibonacci_sphere(n: int) -> np.ndarray:
    """``n`` near-uniform unit vectors (their Voronoi cells are near equal-area)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    r = np.sqrt(1.0 - z * z)
    phi = math.pi * (3.0 - math.sqrt(5.0)) * np.arange(n)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def unit_rows(v) -> np.ndarray:
    v = np.atleast_2d(np.asarray(v, dtype=float))
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def coverage(directions, n_cells: int = COVERAGE_CELLS, radius_deg: float = COVERAGE_RADIUS_DEG) -> float:
    """Share of the sphere within ``radius_deg`` of a visited direction: the share of
    ``n_cells`` near-equal-area cells whose centre lies that close to some direction
    (rows). The radius lets a few held orientations count for their neighbourhood as a
    continuous sweep does: a full sweep or 24 spread orientations 1.0, 12 spread 0.77, 9
    spread 0.59, a hemisphere 0.73, a single great circle 0.50."""
    u = unit_rows(directions)
    u = u[np.all(np.isfinite(u), axis=1)]
    if len(u) == 0:
        return 0.0
    cmin = math.cos(math.radians(radius_deg))
    best = np.full(n_cells, -1.0)
    cells = fibonacci_sphere(n_cells)
    for block in np.array_split(u, max(1, len(u) // 20000 + 1)):
        best = np.maximum(best, np.max(block @ cells.T, axis=0))
    return float(np.mean(best >= cmin))


def spread(directions) -> float:
    """3 × the smallest eigenvalue of the directions' scatter matrix ``mean(u uᵀ)``: 1 for
    directions spread evenly in 3-D, 0 when they all lie in one plane (a unit turned about
    one axis only, seen about the midrange centre)."""
    u = unit_rows(directions)
    u = u[np.all(np.isfinite(u), axis=1)]
    if len(u) < 3:
        return 0.0
    return float(3.0 * np.linalg.eigvalsh(u.T @ u / len(u))[0])


def distinct_directions(directions, min_sep_deg: float = DISTINCT_SEPARATION_DEG) -> int:
    """Greedy count of directions pairwise at least ``min_sep_deg`` apart."""
    u = unit_rows(directions)
    u = u[np.all(np.isfinite(u), axis=1)]
    cmax = math.cos(math.radians(min_sep_deg))
    kept = np.zeros((0, 3))
    for v in u:
        if len(kept) == 0 or np.max(kept @ v) < cmax:
            kept = np.vstack([kept, v])
    return len(kept)


def midrange_directions(y) -> np.ndarray:
    """Directions of raw vectors about the midrange centre (a crude hard-iron removal that
    needs no fit; for counting orientations before fitting)."""
    y = np.asarray(y, dtype=float)
    c = (np.nanmax(y, axis=0) + np.nanmin(y, axis=0)) / 2.0
    return unit_rows(y - c)


# ---------------------------------------------------------------- 4. magnetometer


def ellipsoid_fit(
    y, field_nT: float | None = None, *, axis_aligned: bool = False
) -> tuple[np.ndarray, np.ndarray, float]:
    """Algebraic ellipsoid fit of raw vectors ``y`` (N, 3); ``axis_aligned``: the ellipsoid's
    axes along the sensor axes (W diagonal: 3 scales + 3 centre = the source's 6 unknowns,
    identifiable from 6 orientations), else general (9 unknowns).

    Returns ``(W, h, radius)``: W upper-triangular (positive diagonal) with
    ``|W (y − h)| ≈ field_nT``, h the centre [raw], radius the ellipsoid's geometric-mean
    radius [raw]. ``field_nT=None`` scales W to a unit field. Raises NotIdentifiable when
    the quadric is not an ellipsoid (too little of the sphere visited)."""
    y = np.asarray(y, dtype=float)
    if len(y) < 10:
        raise TooFewPositions(f"{len(y)} magnetometer samples: an ellipsoid needs at least 10")
    mu = y.mean(axis=0)
    s = float(np.sqrt(np.mean(np.sum((y - mu) ** 2, axis=1)))) or 1.0
    x = (y - mu) / s
    X, Y, Z = x.T
    one = np.ones(len(x))
    if axis_aligned:
        D = np.column_stack([X * X, Y * Y, Z * Z, 2 * X, 2 * Y, 2 * Z, one])
    else:
        D = np.column_stack([X * X, Y * Y, Z * Z, 2 * X * Y, 2 * X * Z, 2 * Y * Z, 2 * X, 2 * Y, 2 * Z, one])
    _, sv, Vt = linalg.svd(D, full_matrices=False)
    if sv[-2] <= 1e-9 * sv[0]:
        raise NotIdentifiable(
            "the magnetometer vectors do not determine an ellipsoid "
            "(they lie on a plane or a cone: turn the unit through more orientations)"
        )
    v = Vt[-1]
    if axis_aligned:
        v = np.concatenate([v[:3], [0.0, 0.0, 0.0], v[3:]])
    A = np.array([[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]])
    b = v[6:9]
    if np.linalg.det(A) < 0 or np.trace(A) < 0:
        A, b, c = -A, -b, -v[9]
    else:
        c = v[9]
    try:
        hx = -np.linalg.solve(A, b)
    except np.linalg.LinAlgError:
        raise NotIdentifiable("the ellipsoid fit is singular: turn the unit through more orientations") from None
    k = float(hx @ A @ hx - c)
    An = A / k if k != 0 else A * np.nan
    ev = np.linalg.eigvalsh(An) if np.all(np.isfinite(An)) else np.array([-1.0])
    if np.any(ev <= 0):
        raise NotIdentifiable(
            "the magnetometer data do not fit an ellipsoid (the quadric is not "
            "closed): turn the unit through more orientations"
        )
    An_raw = An / (s * s)  # in raw units
    h = mu + s * hx
    U = np.linalg.cholesky(An_raw).T  # upper, An = Uᵀ U
    radius = float(np.linalg.det(An_raw) ** (-1.0 / 6.0))
    F = 1.0 if field_nT is None else float(field_nT)
    return F * U, h, radius


def calibrated(y, W, h) -> np.ndarray:
    """``m = W (y − h)`` [nT] through the magnetometer model (solvers.models.mag.inverse)."""
    return mag_model.inverse(y, {"W": np.asarray(W, float), "h": np.asarray(h, float)})


def magnitude_jacobian(y, W, h) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """|W(y−h)| per row, its Jacobian (N, 9) over [W upper row-major, h], and ``|Wᵀû|``
    (the raw-noise → radial-residual gain, per row)."""
    d = np.asarray(y, float) - h
    u = d @ W.T
    n = np.linalg.norm(u, axis=1)
    uh = u / n[:, None]
    J = np.empty((len(d), 9))
    for k, (i, j) in enumerate(zip(*UPPER)):
        J[:, k] = uh[:, i] * d[:, j]
    g = uh @ W  # rows of Wᵀû
    J[:, 6:] = -g
    return n, J, np.linalg.norm(g, axis=1)


def theta_of(W, h) -> np.ndarray:
    return np.concatenate([np.asarray(W, float)[UPPER], np.asarray(h, float)])


def W_h_of(theta) -> tuple[np.ndarray, np.ndarray]:
    W = np.zeros((3, 3))
    W[UPPER] = theta[:6]
    return W, np.asarray(theta[6:9], float).copy()


def noise_from_second_differences(y) -> float:
    """Raw white-noise σ per axis from a time-ordered series: the MAD of second
    differences (smooth motion cancels; white noise has variance 6σ² there), axes averaged
    in variance. Correlated noise (filtered or interpolated data) comes out too small,
    which then shows as misfit."""
    y = np.asarray(y, float)
    d2 = np.diff(y, n=2, axis=0)
    d2 = d2[np.all(np.isfinite(d2), axis=1)]
    if len(d2) < 10:
        return math.nan
    s = 1.4826 * np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0) / math.sqrt(6.0)
    return float(np.sqrt(np.mean(s**2)))


# the raw axes' noise is taken as the white noise unless it exceeds the magnitude's by this
# factor (a turn between samples): on holds and fast reads the two agree within 0.93–1.2
RADIAL_NOISE_RATIO = 1.5


def radial_noise_from_second_differences(y, W, h) -> float:
    """Raw white-noise σ per axis from the calibrated magnitude ``|W (y − h)|`` of a
    time-ordered series: the MAD of its second differences over the RMS radial gain ``|Wᵀ û|``.
    A turn leaves the magnitude alone, so a tumble read slowly (a field turning by a tenth of a
    radian between samples) does not count as noise here as it does in the raw axes' second
    differences (``noise_from_second_differences``: 18 times the white noise on an RM3100
    tumbled at 10 Hz)."""
    y = np.asarray(y, float)
    m = (y - np.asarray(h, float)) @ np.asarray(W, float).T
    mag = np.linalg.norm(m, axis=1)
    ok = np.isfinite(mag) & (mag > 0)
    if ok.sum() < 12:
        return math.nan
    u = m[ok] / mag[ok, None]
    gain = math.sqrt(float(np.mean(np.sum((u @ np.asarray(W, float)) ** 2, axis=1))))
    d2 = np.diff(mag[ok], n=2)
    s = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0)
    return s / gain if gain > 0 else math.nan


def turn_free_noise(noise_raw: float, y, W, h) -> float:
    """``noise_raw`` (the raw axes' second differences), or the magnitude's white noise
    (``radial_noise_from_second_differences``) where ``noise_raw`` exceeds it by more than
    ``RADIAL_NOISE_RATIO`` or is not a number: a turn between samples read as noise."""
    radial = radial_noise_from_second_differences(y, W, h)
    if math.isfinite(radial) and radial > 0 and not noise_raw <= RADIAL_NOISE_RATIO * radial:
        return radial
    return noise_raw


# a magnetometer read through a quantiser of step q whose white noise σ is below q/2 is not
# dithered: the rounding error of a still unit is a constant per still stretch (see
# rounding_shared_var); at σ = q/2 that constant's variance is e^(−π²) ≈ 5e-5 of q²/12
UNDITHERED_SIGMA_Q = 0.5


def quantum(y) -> np.ndarray:
    """Per axis, the step of the grid the readings lie on (the smallest nonzero difference
    between distinct values, when every value is a whole number of it from the smallest to
    1e-3 of it), else 0: readings in counts, or counts converted with a fixed factor."""
    y = np.asarray(y, float)
    out = np.zeros(y.shape[1])
    for a in range(y.shape[1]):
        v = np.unique(y[np.isfinite(y[:, a]), a])
        if len(v) < 2:
            continue
        q = float(np.min(np.diff(v)))
        r = (v - v[0]) / q
        if q > 0 and np.max(np.abs(r - np.round(r))) < 1e-3:
            out[a] = q
    return out


def rounding_shared_var(sigma, q) -> np.ndarray:
    """Variance of the part of the rounding error that a still stretch's samples share, per axis.

    A reading ``Q(x + n)`` (round to the grid of step ``q``, white noise ``n`` of σ) of a
    constant ``x``: the error ``Q(x + n) − x`` has variance ``σ² + q²/12`` (the rounding error
    is uniform and independent of ``n``), of which its mean over the stretch,
    ``E_n[Q(x + n)] − x``, the sawtooth smoothed by the noise, keeps
    ``τ² = Σ_k q²/(2π²k²) exp(−4π²k²σ²/q²)`` (its Fourier series, x uniform on the grid):
    q²/12 at σ = 0, no row averages it down; negligible from σ = q/2 (dithered). The rest,
    ``σ² + q²/12 − τ²``, is white within the stretch. 0 where ``q`` is 0."""
    s = np.asarray(sigma, float)
    q = np.asarray(q, float)
    out = np.zeros(np.broadcast(s, q).shape)
    ok = np.broadcast_to(q > 0, out.shape)
    qq = np.broadcast_to(q, out.shape)[ok]
    ss = np.broadcast_to(s, out.shape)[ok]
    K = 40
    k = np.arange(1, K + 1)[:, None]
    a = 4 * math.pi**2 * (ss / qq) ** 2
    # the terms beyond K as Σ_{k>K} 1/k² ≈ 1/(K + ½) times their first factor (σ → 0: to 1e-5)
    terms = np.sum(np.exp(-a * k**2) / k**2, axis=0) + np.exp(-a * (K + 1) ** 2) / (K + 0.5)
    out[ok] = qq**2 / (2 * math.pi**2) * terms
    return out


def quantised_noise(y, stretches, q) -> tuple[np.ndarray, np.ndarray]:
    """(σ, τ²) per axis of a magnetometer on a quantiser of step ``q`` (:func:`quantum`): σ the
    white noise before the quantiser, from the readings' scatter within the still stretches
    ``[(start, stop), …]`` (half the mean square of successive differences, pooled; a jump of
    more than 3 steps is left out: the field moved, a hard-iron step in a hold, not noise), which
    is ``σ² + q²/12 − τ²(σ)`` (:func:`rounding_shared_var`; increasing in σ, solved by
    bisection); τ² the variance of
    the rounding error a stretch shares, 0 where the quantiser is dithered (σ ≥ q/2) or there
    is none. Axes on one step share one σ (one chip's noise, axes averaged in variance as
    :func:`noise_from_second_differences` does): the scatter of a still, undithered axis is a
    few flips between two counts, in the stretches whose value lies near a step, and one axis
    alone put σ anywhere from 0.6 to 1.25 times its value. NaN σ where the stretches hold too
    few samples."""
    y = np.asarray(y, float)
    q = np.asarray(q, float)
    d = [np.diff(y[i:j], axis=0) for i, j in stretches if j - i >= 2]
    d = np.concatenate(d) if d else np.zeros((0, y.shape[1]))
    d = d[np.all(np.isfinite(d), axis=1)]
    jump = np.any(np.abs(d) > np.where(q > 0, 3 * q, np.inf), axis=1)
    if len(d) and jump.mean() < 0.5:  # else the noise spans many steps (dithered: no jump to tell)
        d = d[~jump]
    if len(d) < 10:
        return np.full(y.shape[1], math.nan), np.zeros(y.shape[1])
    within = np.mean(d**2, axis=0) / 2.0
    sigma = np.sqrt(within)  # no quantiser: the scatter is the noise
    tau2 = np.zeros(y.shape[1])
    for qa in np.unique(q[q > 0]):
        axes = q == qa
        v = float(np.mean(within[axes]))

        def f(s, qa=qa):
            return s**2 + qa**2 / 12.0 - float(rounding_shared_var(s, qa))

        hi = UNDITHERED_SIGMA_Q * qa
        if v >= f(hi):
            sigma[axes] = math.sqrt(max(v - qa**2 / 12.0, 0.0))  # dithered: Sheppard's correction
            continue
        lo = 0.0
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if f(mid) < v else (lo, mid)
        sigma[axes] = 0.5 * (lo + hi)
        tau2[axes] = float(rounding_shared_var(sigma[axes][0], qa))
    return sigma, tau2


def noise_bias_nT(y, W, h, noise_raw: float) -> np.ndarray:
    """Per-row ``E|W(y − h)| − |W(y_true − h)|`` for white raw noise: the noise across the
    ellipsoid's normal lengthens the vector by ``σ² (‖W‖²_F − |Wᵀû|²) / (2 |m|)`` (second
    order; ~0.4 nT for 150 nT noise on a 55,000 nT field, enough to bias W's scale by a
    quarter sigma). Added to F in every fit so that the *true* field has magnitude F."""
    n, _, gain = magnitude_jacobian(y, np.asarray(W, float), np.asarray(h, float))
    return float(noise_raw) ** 2 * (np.sum(np.asarray(W, float) ** 2) - gain**2) / (2.0 * n)


def batch_fit(y, W0, h0, field_nT: float, noise_raw: float, *, weights_at=None, W_free=W_FREE) -> FitResult:
    """Nonlinear least squares of ``|W(y − h)| − (F + b)`` over W (upper) and h through
    ``solvers.fit``, b the noise bias (:func:`noise_bias_nT`, when NOISE_BIAS_CORRECTION).
    Per-row sigma ``noise_raw · |Wᵀû|``; sigma and b at ``weights_at`` = (W, h) (default
    the start): the raw noise along the ellipsoid normal. When the residuals exceed that
    noise the engine scales the covariance by the reduced χ² (``misfit_scaled``)."""
    y = np.asarray(y, float)
    Wa, ha = weights_at if weights_at is not None else (W0, h0)
    _, _, gain = magnitude_jacobian(y, np.asarray(Wa, float), np.asarray(ha, float))
    sigma = float(noise_raw) * gain
    F = float(field_nT) + (noise_bias_nT(y, Wa, ha, noise_raw) if NOISE_BIAS_CORRECTION else 0.0)

    def resid(p):
        return np.linalg.norm(calibrated(y, p["W"], p["h"]), axis=1) - F

    W_free = np.asarray(W_free, bool)
    cols = [k for k, (i, j) in enumerate(zip(*UPPER)) if W_free[i, j]] + [6, 7, 8]

    def jac(p):
        return magnitude_jacobian(y, p["W"], p["h"])[1][:, cols]

    return fit(
        resid,
        {"W": np.asarray(W0, float), "h": np.asarray(h0, float)},
        free={"W": W_free, "h": True},
        sigma=sigma,
        jac=jac,
        scale_on_misfit=True,
    )


class MagRLS:
    """Recursive least squares on θ = [W upper (6), h (3)] (see the module docstring).

    ``linearise``:

    - ``'running'`` (extended RLS, for live streams): each sample is linearised at the
      current estimate. Order-dependent when the model does not fit exactly: early,
      partial-sphere samples move the linearisation point.
    - ``'fixed'`` (for a recorded capture): every sample is linearised at ``theta_ref``
      (the pass's start), i.e. exact RLS of the linearised model; a pass then equals one
      Gauss–Newton step on all samples, whatever their order, and repeated passes
      (:func:`rls_passes`) converge to the batch solution.

    ``update(y_row)`` processes one raw sample, ``process(Y)`` many. ``P`` is in units of
    θ², for the measurement variance ``noise_raw² |Wᵀû|²``."""

    def __init__(
        self,
        W0,
        h0,
        field_nT: float,
        P0,
        *,
        noise_raw: float = 1.0,
        forgetting: float = 1.0,
        linearise: str = "running",
    ):
        if linearise not in ("running", "fixed"):
            raise ValueError("linearise must be 'running' or 'fixed'")
        self.theta = theta_of(W0, h0)
        self.theta_ref = self.theta.copy()
        self.P = np.array(P0, dtype=float)
        self.F = float(field_nT)
        self.r0 = float(noise_raw) ** 2
        self.lam = float(forgetting)
        self.linearise = linearise
        self.n = 0

    @property
    def W(self) -> np.ndarray:
        return W_h_of(self.theta)[0]

    @property
    def h(self) -> np.ndarray:
        return W_h_of(self.theta)[1]

    def process(self, Y) -> None:
        Y = np.asarray(Y, float)
        if self.linearise == "fixed":
            self._process_fixed(Y)
        else:
            self._process_running(Y)
        self.n += len(Y)

    def _process_fixed(self, Y: np.ndarray) -> None:
        th, P, lam = self.theta, self.P, self.lam
        W_ref, h_ref = W_h_of(self.theta_ref)
        n_ref, J, gain = magnitude_jacobian(Y, W_ref, h_ref)
        # pseudo-measurement of the linearised model: z = F − n_ref + J θ_ref = J θ
        z = (self.F - n_ref) + J @ self.theta_ref
        if NOISE_BIAS_CORRECTION:
            z += self.r0 * (np.sum(W_ref**2) - gain * gain) / (2.0 * n_ref)
        R = lam * self.r0 * gain * gain
        for H, zk, rk in zip(J, z.tolist(), R.tolist()):
            PH = P @ H
            K = PH / (rk + H @ PH)
            th += K * (zk - H @ th)
            P -= np.outer(K, PH)
            if lam != 1.0:
                P /= lam

    def _process_running(self, Y: np.ndarray) -> None:
        th, P, F, r0, lam = self.theta, self.P, self.F, self.r0, self.lam
        bias = NOISE_BIAS_CORRECTION
        H = np.empty(9)
        for y0, y1, y2 in Y.tolist():
            w00, w01, w02, w11, w12, w22, h0, h1, h2 = th.tolist()
            d0, d1, d2 = y0 - h0, y1 - h1, y2 - h2
            u0 = w00 * d0 + w01 * d1 + w02 * d2  # u = W d: mag.inverse for one row,
            u1 = w11 * d1 + w12 * d2  # written out for speed
            u2 = w22 * d2
            n = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
            a0, a1, a2 = u0 / n, u1 / n, u2 / n
            g0 = a0 * w00
            g1 = a0 * w01 + a1 * w11
            g2 = a0 * w02 + a1 * w12 + a2 * w22  # g = Wᵀ û
            H[:] = (a0 * d0, a0 * d1, a0 * d2, a1 * d1, a1 * d2, a2 * d2, -g0, -g1, -g2)
            PH = P @ H
            g2 = g0 * g0 + g1 * g1 + g2 * g2
            s = lam * r0 * g2 + H @ PH
            K = PH / s
            b = (
                r0 * (w00 * w00 + w01 * w01 + w02 * w02 + w11 * w11 + w12 * w12 + w22 * w22 - g2) / (2.0 * n)
                if bias
                else 0.0
            )
            th += K * (F + b - n)
            P -= np.outer(K, PH)
            if lam != 1.0:
                P /= lam

    def update(self, y_row) -> None:
        self.process(np.atleast_2d(y_row))


def rls_passes(
    y, W0, h0, field_nT: float, noise_raw: float, *, passes: int = 2, inflation: float | None = None
) -> MagRLS:
    """RLS over a recorded capture: ``passes`` passes with fixed linearisation, each started
    at the previous pass's estimate with ``P0 = inflation × (Jᵀ Σ⁻¹ J)⁻¹`` there."""
    inflation = RLS_P0_INFLATION if inflation is None else inflation
    W, h = np.asarray(W0, float), np.asarray(h0, float)
    rls = None
    for _ in range(max(1, passes)):
        P0 = inflation * fisher_covariance(y, W, h, noise_raw)
        rls = MagRLS(W, h, field_nT, P0, noise_raw=noise_raw, linearise="fixed")
        rls.process(y)
        W, h = rls.W, rls.h
    return rls


def fisher_covariance(y, W, h, noise_raw: float) -> np.ndarray:
    """``(Jᵀ Σ⁻¹ J)⁻¹`` of θ at (W, h) for white raw noise ``noise_raw`` per axis: the CRLB
    of the magnitude model (radial residual, variance ``noise_raw² |Wᵀû|²``)."""
    _, J, gain = magnitude_jacobian(y, np.asarray(W, float), np.asarray(h, float))
    Jw = J / (noise_raw * gain)[:, None]
    return np.linalg.inv(Jw.T @ Jw)


@dataclass
class MagCalibration:
    """What the magnetometer part found."""

    W: np.ndarray
    h: np.ndarray
    W_sigma: np.ndarray
    h_sigma: np.ndarray
    field_nT: float
    method: str
    W_ellipsoid: np.ndarray
    h_ellipsoid: np.ndarray
    batch: FitResult
    rls_minus_batch_sigma: float  # max |θ_rls − θ_batch| / σ_batch (NaN: no RLS)
    noise_raw: float  # raw noise estimate (per axis)
    residual_rms_nT: float
    n_samples: int
    n_distinct: int
    coverage: float
    magnitude_before: dict = field(default_factory=dict)
    magnitude_after: dict = field(default_factory=dict)


def _spread(x: np.ndarray) -> dict:
    return {
        "mean": float(np.mean(x)),
        "std": float(np.std(x)),
        "min": float(np.min(x)),
        "max": float(np.max(x)),
        "std_percent": float(100.0 * np.std(x) / np.mean(x)),
    }


def check_orientations(
    y, *, need: int = MIN_RLS_ORIENTATIONS, min_coverage: float = MIN_COVERAGE, directions=None
) -> tuple[int, float]:
    """Distinct orientations and coverage of the field directions; raises TooFewPositions /
    CoverageTooLow with the reason."""
    if directions is None:
        y = np.asarray(y, float)
        y = y[np.all(np.isfinite(y), axis=1)]
        # About the midrange centre even sensor noise points everywhere: first ask whether
        # the field itself turned (its range against its size, as a sweep makes ~2×).
        if len(y) and not np.any(y):
            raise CoverageTooLow(
                "no magnetometer data (all zero): every sample reads 0, 0, 0 "
                "(a magnetometer not fitted, disabled or never read)"
            )
        span = float(np.max(np.ptp(y, axis=0))) if len(y) else 0.0
        size = float(np.median(np.linalg.norm(y - np.median(y, axis=0), axis=1)) + np.linalg.norm(np.median(y, axis=0)))
        if len(y) and span < 0.1 * max(size, 1e-300):
            raise CoverageTooLow(
                f"the field hardly changed direction (largest range {span:.3g} against a field of about "
                f"{size:.3g} in raw units): the unit was not turned; turn it through all orientations, "
                "including upside down"
            )
    u = midrange_directions(y) if directions is None else unit_rows(directions)
    n_dist = distinct_directions(u)
    cov = coverage(u)
    if n_dist < need:
        raise TooFewPositions(
            f"only {n_dist} distinct field directions (>= {DISTINCT_SEPARATION_DEG:.0f}° apart); "
            f"the {'RLS' if need >= MIN_RLS_ORIENTATIONS else 'ellipsoid fit'} needs at least {need}: "
            "turn the unit through more orientations"
        )
    sp = spread(u)
    if sp < MIN_SPREAD:
        raise CoverageTooLow(
            f"the field directions lie in one plane (spread {sp:.2f}, need {MIN_SPREAD:.2f}; "
            f"{100 * cov:.0f}% of the sphere): the unit was turned about one axis only; "
            "turn it through all orientations, including upside down"
        )
    if cov < min_coverage:
        raise CoverageTooLow(
            f"the field direction came within {COVERAGE_RADIUS_DEG:.0f}° of only {100 * cov:.0f}% of the "
            f"sphere (need {100 * min_coverage:.0f}%): turn the unit through all orientations, "
            "including upside down"
        )
    return n_dist, cov


def calibrate_mag(
    y,
    field_nT: float | None,
    *,
    unit_factor_nT: float | None = None,
    method: str = "rls",
    noise_raw: float | None = None,
    min_coverage: float = MIN_COVERAGE,
) -> MagCalibration:
    """Ellipsoid fit → RLS (and the batch reference) on raw magnetometer rows ``y``.

    ``field_nT``: the IGRF total field; None → F = ellipsoid radius × ``unit_factor_nT``
    (or 1). ``method``: 'rls' (reported W, h from the RLS), 'batch', or 'ellipsoid'.
    ``noise_raw``: raw white noise per axis (e.g. :func:`noise_from_second_differences`);
    None → estimated from the ellipsoid residuals (then misfit cannot be detected)."""
    y = np.asarray(y, float)
    y = y[np.all(np.isfinite(y), axis=1)]
    if method not in ("rls", "batch", "ellipsoid"):
        raise ValueError(f"unknown compass method {method!r}: rls, batch or ellipsoid")
    n0, _ = check_orientations(y, need=MIN_ELLIPSOID_ORIENTATIONS, min_coverage=min_coverage)
    full = n0 >= MIN_RLS_ORIENTATIONS
    if not full and method != "ellipsoid":
        raise TooFewPositions(
            f"only {n0} distinct field directions (>= {DISTINCT_SEPARATION_DEG:.0f}° apart): the RLS "
            f"(full upper-triangular W and h, 9 parameters) needs at least {MIN_RLS_ORIENTATIONS}; "
            f"with {MIN_ELLIPSOID_ORIENTATIONS} to {MIN_RLS_ORIENTATIONS - 1} only the axis-aligned "
            "ellipsoid (method 'ellipsoid', 6 parameters) can be fitted: turn the unit through more orientations"
        )
    W1, h1, radius = ellipsoid_fit(y, 1.0, axis_aligned=not full)
    if field_nT is None:
        F = radius * (unit_factor_nT if unit_factor_nT else 1.0)
    else:
        F = float(field_nT)
    W_e = W1 * F
    m_e = calibrated(y, W_e, h1)
    n_dist, cov = check_orientations(
        y, need=MIN_RLS_ORIENTATIONS if full else MIN_ELLIPSOID_ORIENTATIONS, min_coverage=min_coverage, directions=m_e
    )
    W_free = W_FREE if full else np.eye(3, dtype=bool)
    if noise_raw is not None:
        # a turn between samples reads as noise in the raw axes' second differences; the magnitude
        # does not turn (a tumble read at 10 Hz: 18 times the white noise, every σ as many times)
        noise_raw = turn_free_noise(noise_raw, y, W_e, h1)
    if noise_raw is None:
        _, _, gain_e = magnitude_jacobian(y, W_e, h1)
        r_e = (np.linalg.norm(m_e, axis=1) - F) / gain_e
        noise_raw = float(np.sqrt(np.sum(r_e**2) / max(len(y) - int(W_free.sum()) - 3, 1)))
    batch = batch_fit(y, W_e, h1, F, noise_raw, W_free=W_free)
    if not batch.success or batch.unidentifiable:
        raise NotIdentifiable(
            "the soft/hard-iron fit is not identifiable from these data "
            f"({', '.join(batch.unidentifiable) or batch.message})"
        )
    Wb, hb = batch.params["W"], batch.params["h"]
    sig_raw = float(noise_raw) * (math.sqrt(batch.reduced_chi2) if batch.misfit_scaled else 1.0)
    if full:
        th_b = theta_of(Wb, hb)
        sig_b = np.concatenate([batch.sigma["W"][UPPER], batch.sigma["h"]])
        # RLS from the ellipsoid values, same noise (and bias term) as the batch
        rls = rls_passes(y, W_e, h1, F, noise_raw, passes=RLS_PASSES)
        diff = float(np.max(np.abs(rls.theta - th_b) / sig_b))
    else:
        rls, diff = None, math.nan
    if method == "rls":
        W, h = rls.W, rls.h
    elif method == "batch":
        W, h = Wb, hb
    else:  # the ellipsoid: the batch optimum of the ellipsoid's own model when axis-aligned
        W, h = (W_e, h1) if full else (Wb, hb)
    raw_mag = np.linalg.norm(y, axis=1) * (unit_factor_nT if unit_factor_nT else 1.0)
    after = np.linalg.norm(calibrated(y, W, h), axis=1)
    resid = after - F
    return MagCalibration(
        W=W,
        h=h,
        W_sigma=batch.sigma["W"] * W_free,
        h_sigma=batch.sigma["h"],
        field_nT=F,
        method=method,
        W_ellipsoid=W_e,
        h_ellipsoid=h1,
        batch=batch,
        rls_minus_batch_sigma=diff,
        noise_raw=sig_raw,
        residual_rms_nT=float(np.sqrt(np.mean(resid**2))),
        n_samples=len(y),
        n_distinct=n_dist,
        coverage=cov,
        magnitude_before=_spread(raw_mag),
        magnitude_after=_spread(after),
    )


# ---------------------------------------------------------------- 5. heading and sign


def level_field(m_body, pitch_rad, roll_rad) -> np.ndarray:
    """``R_y(θ) R_x(φ) m_b`` per row: the field in the levelled (heading) frame."""
    m = np.atleast_2d(np.asarray(m_body, float))
    th = np.broadcast_to(np.asarray(pitch_rad, float), (len(m),))
    ph = np.broadcast_to(np.asarray(roll_rad, float), (len(m),))
    cth, sth, cph, sph = np.cos(th), np.sin(th), np.cos(ph), np.sin(ph)
    y1 = cph * m[:, 1] - sph * m[:, 2]
    z1 = sph * m[:, 1] + cph * m[:, 2]
    x2 = cth * m[:, 0] + sth * z1
    z2 = -sth * m[:, 0] + cth * z1
    return np.column_stack([x2, y1, z2])


def heading_deg(
    m_body_nT, pitch_rad, roll_rad, declination_deg: float = 0.0, max_tilt_deg: float = HEADING_MAX_TILT_DEG
) -> tuple[np.ndarray, np.ndarray]:
    """Tilt-compensated (magnetic, true) heading of body x in [0, 360) per row; NaN where
    |pitch| exceeds ``max_tilt_deg`` (roll and heading are undefined near ±90°)."""
    ml = level_field(m_body_nT, pitch_rad, roll_rad)
    mag = np.degrees(np.arctan2(-ml[:, 1], ml[:, 0])) % 360.0
    bad = np.abs(np.degrees(np.broadcast_to(np.asarray(pitch_rad, float), mag.shape))) > max_tilt_deg
    mag = np.where(bad, np.nan, mag)
    return mag, (mag + declination_deg) % 360.0


def circular_mean_deg(a) -> float:
    a = np.radians(np.asarray(a, float))
    a = a[np.isfinite(a)]
    if len(a) == 0:
        return math.nan
    return math.degrees(math.atan2(np.mean(np.sin(a)), np.mean(np.cos(a)))) % 360.0


def accel_mag_angle_deg(f, m) -> np.ndarray:
    """Angle between the accelerometer vector and the field, per row [deg]."""
    fu, mu = unit_rows(f), unit_rows(m)
    return np.degrees(np.arccos(np.clip(np.sum(fu * mu, axis=1), -1.0, 1.0)))


@dataclass
class SignVerdict:
    sign: str  # 'specific_force' or 'gravity'
    angle_deg: float  # median accel–field angle as given
    expected_deg: float | None  # 90 + inclination for specific force
    reason: str


def detect_accel_sign(f, m_cal, inclination_deg: float | None) -> SignVerdict:
    """Does the accelerometer report specific force (up axis +g) or the gravity direction?

    With specific force the angle between f (up) and the field is ``90° + I``; with the
    gravity direction ``90° − I``. Without a place, I is unknown: an angle below 90° is
    taken as the gravity direction *assuming the northern magnetic hemisphere* (I > 0)."""
    ang = float(np.nanmedian(accel_mag_angle_deg(f, m_cal)))
    if inclination_deg is not None:
        e_sf, e_gr = 90.0 + inclination_deg, 90.0 - inclination_deg
        if abs(inclination_deg) < 10.0:
            return SignVerdict(
                "specific_force",
                ang,
                e_sf,
                f"inclination {inclination_deg:.1f}° is too shallow to tell the sign; assumed specific force",
            )
        if abs(ang - e_gr) < abs(ang - e_sf):
            return SignVerdict(
                "gravity",
                ang,
                e_sf,
                f"accelerometer–field angle {ang:.1f}° matches the gravity direction "
                f"(90° − I = {e_gr:.1f}°), not specific force (90° + I = {e_sf:.1f}°)",
            )
        return SignVerdict(
            "specific_force",
            ang,
            e_sf,
            f"accelerometer–field angle {ang:.1f}° matches specific force (90° + I = {e_sf:.1f}°)",
        )
    if ang < 90.0:
        return SignVerdict(
            "gravity",
            ang,
            None,
            f"accelerometer–field angle {ang:.1f}° < 90°: the accelerometer points "
            "along the field's downward component, i.e. reports the gravity "
            "direction (assuming the northern magnetic hemisphere; no site given)",
        )
    return SignVerdict(
        "specific_force",
        ang,
        None,
        f"accelerometer–field angle {ang:.1f}° > 90°: specific force "
        "(assuming the northern magnetic hemisphere; no site given)",
    )
