"""Static-interval detection (solvers/stillness.py): planted truth, batch == incremental,
bad input, and the three real multi-position recordings of ../shared/data."""

from __future__ import annotations

import math

import numpy as np
import pytest

from solvers.errors import NotIdentifiable, SolverError, TooFewPositions
from solvers.stillness import (
    StillnessInputError,
    StillnessTracker,
    cluster_orientations,
    detect_static_intervals,
)

FS = 100.0
G = 9.81
SIGMA_A = 0.02  # accelerometer white noise [m/s^2]
SIGMA_W = 0.004  # gyro white noise [rad/s]
BIAS_A = np.array([0.10, -0.05, 0.20])
BIAS_W = np.array([0.010, -0.020, 0.005])
H = 50  # half window at 100 Hz with the default 1 s window


# ---------------------------------------------------------------- synthetic sessions


def _rot(u, phi):
    """Rotation matrix about unit axis u by phi [rad] (Rodrigues)."""
    u = np.asarray(u, float) / np.linalg.norm(u)
    k = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    return np.eye(3) + math.sin(phi) * k + (1 - math.cos(phi)) * (k @ k)


def session(seed, rests_s, moves, *, start_moving=False, fs=FS):
    """A multi-position recording with a known schedule.

    rests_s: rest durations [s]; moves: (body axis, angle_deg, duration_s) between them (one
    more than the rests when start_moving, the recording then opens with a move). Each
    move follows a raised-cosine rate profile (zero rate at both ends). Returns t_s,
    accel [m/s^2] (specific force + bias + noise), gyro [rad/s], the planted rests as
    [start, stop) sample ranges, and the noise-free accel mean of each rest.
    """
    rng = np.random.default_rng(seed)
    c_n_b = np.eye(3)
    g_n = np.array([0.0, 0.0, G])
    acc, rate, truth, means = [], [], [], []
    n = 0
    steps = []
    moves = list(moves)
    if start_moving:
        steps.append(("move", moves.pop(0)))
    for i, r in enumerate(rests_s):
        steps.append(("rest", r))
        if i < len(moves):
            steps.append(("move", moves[i]))
    for kind, spec in steps:
        if kind == "rest":
            k = int(round(spec * fs))
            f = c_n_b.T @ g_n
            acc.append(np.tile(f, (k, 1)))
            rate.append(np.zeros((k, 3)))
            truth.append((n, n + k))
            means.append(f + BIAS_A)
        else:
            u, ang, dur = spec
            u = np.asarray(u, float) / np.linalg.norm(u)
            th = math.radians(ang)
            k = int(round(dur * fs))
            tt = (np.arange(k) + 0.5) / k
            phi = th * (tt - np.sin(2 * np.pi * tt) / (2 * np.pi))
            dphi = th * (1 - np.cos(2 * np.pi * tt)) / dur
            acc.append(np.array([(c_n_b @ _rot(u, p)).T @ g_n for p in phi]))
            rate.append(dphi[:, None] * u)
            c_n_b = c_n_b @ _rot(u, th)
        n += k
    a = np.vstack(acc) + BIAS_A + rng.normal(0, SIGMA_A, (n, 3))
    w = np.vstack(rate) + BIAS_W + rng.normal(0, SIGMA_W, (n, 3))
    return np.arange(n) / fs, a, w, truth, np.array(means)


def schedule(seed, n_poses=8):
    rng = np.random.default_rng(seed)
    rests = list(rng.uniform(3.0, 6.0, n_poses))
    moves = [(rng.normal(size=3), rng.uniform(40, 150), rng.uniform(1.0, 2.5)) for _ in range(n_poses)]
    return rests, moves


def to_counts(a, scale=G / 4096.0, offset=32768.0):
    """Unsigned ADC counts: round(a / scale + offset)."""
    return np.round(a / scale + offset)


def assert_recovers(result, truth, truth_means, unit_scale=1.0, unit_offset=0.0):
    """Each planted rest found once, inside it up to the undetectable motion tail, mean unbiased.

    Bounds: the trimmed interval may start up to H samples late (the half-window margin)
    and may begin up to 15 samples (0.15 s) before the planted rest where the end of a
    raised-cosine move changes the reading by less than the noise (phi ~ t^3: 0.15 s
    before the end of a 1 s, 150 deg move the attitude is 0.02 deg from its final value).
    Means: within 5 sigma/sqrt(n) + 0.005 m/s^2 (that tail) of the noise-free reading.
    """
    got = result.intervals
    assert len(got) == len(truth), [(iv.start, iv.stop) for iv in got]
    for iv, (s, e), m in zip(got, truth, truth_means):
        assert s - 15 <= iv.start <= s + H, (iv.start, s)
        assert e - H <= iv.stop <= e + 15, (iv.stop, e)
        assert iv.n == iv.stop - iv.start
        mean_mps2 = (iv.accel_mean - unit_offset) * unit_scale
        tol = 5 * SIGMA_A / math.sqrt(iv.n) + 0.005
        assert np.all(np.abs(mean_mps2 - m) < tol), (mean_mps2, m)


# ---------------------------------------------------------------- planted truth


@pytest.mark.parametrize("units", ["mps2", "counts"])
def test_planted_intervals_with_initial_rest(units):
    rests, moves = schedule(1)
    t, a, w, truth, means = session(1, [20.0] + rests, moves)
    scale, offset = (1.0, 0.0) if units == "mps2" else (G / 4096.0, 32768.0)
    a_in = a if units == "mps2" else to_counts(a, scale, offset)
    res = detect_static_intervals(t, a_in, w, init_rest_s=20.0)
    assert res.noise_source == "initial_rest"
    assert res.warnings == []
    assert_recovers(res, truth, means, scale, offset)
    # the noise floor is the planted white noise (+ quantization in counts), within 10 %
    expect = math.sqrt(SIGMA_A**2 + (scale**2 / 12 if units == "counts" else 0.0))
    np.testing.assert_allclose(res.noise.accel_std * scale, expect, rtol=0.10)
    np.testing.assert_allclose(res.noise.gyro_std, SIGMA_W, rtol=0.10)
    np.testing.assert_allclose(res.noise.gyro_bias, BIAS_W, atol=3 * SIGMA_W / math.sqrt(1000))
    # the first interval is the initial rest, reaching the first sample (no trim there)
    assert res.intervals[0].start == 0


@pytest.mark.parametrize("units", ["mps2", "counts"])
def test_planted_intervals_without_initial_rest(units):
    """The recording opens with a move: the noise floor comes from the data themselves."""
    rests, moves = schedule(2)
    t, a, w, truth, means = session(2, rests, moves, start_moving=True)
    scale, offset = (1.0, 0.0) if units == "mps2" else (G / 4096.0, 32768.0)
    a_in = a if units == "mps2" else to_counts(a, scale, offset)
    res = detect_static_intervals(t, a_in, w)
    assert res.noise_source == "robust"
    assert res.warnings == []
    assert_recovers(res, truth, means, scale, offset)
    expect = math.sqrt(SIGMA_A**2 + (scale**2 / 12 if units == "counts" else 0.0))
    np.testing.assert_allclose(res.noise.accel_std * scale, expect, rtol=0.10)
    # init_rest_s=0 means "no initial rest" too
    res0 = detect_static_intervals(t, a_in, w, init_rest_s=0)
    assert [(iv.start, iv.stop) for iv in res0.intervals] == [(iv.start, iv.stop) for iv in res.intervals]


def test_units_cancel():
    """An affine change of units (any scale, any offset) leaves the decisions unchanged."""
    rests, moves = schedule(3)
    t, a, w, _, _ = session(3, [10.0] + rests, moves)
    ref = detect_static_intervals(t, a, w, init_rest_s=10)
    other = detect_static_intervals(t, a / 0.0098 + 512.0, np.degrees(w), init_rest_s=10)
    assert [(i.start, i.stop) for i in other.intervals] == [(i.start, i.stop) for i in ref.intervals]
    np.testing.assert_allclose(other.level, ref.level, rtol=1e-6, equal_nan=True)


def test_level_statistic_for_a_bar():
    rests, moves = schedule(4, 3)
    t, a, w, truth, _ = session(4, [10.0] + rests, moves)
    res = detect_static_intervals(t, a, w, init_rest_s=10)
    n = len(t)
    assert res.level.shape == res.accel_var_norm.shape == res.gyro_rate.shape == (n,)
    assert np.isnan(res.level[:H]).all() and np.isnan(res.level[n - H :]).all()
    inside = res.still_mask
    assert np.all(res.level[inside & np.isfinite(res.level)] < 1)
    s, e = truth[1]
    assert np.nanmax(res.level[truth[0][1] : s]) > 10  # a move is far above threshold
    assert np.nanmedian(res.level[s + H : e - H]) < 0.5  # a rest is well below


def test_gyro_sees_a_turn_about_gravity():
    """A steady turn about the vertical keeps every accelerometer axis constant: only the
    gyro can tell it from rest."""
    rng = np.random.default_rng(5)
    n_rest, n_turn = 600, 400  # 6 s rest, 4 s turn at 20 deg/s, 6 s rest
    n = 2 * n_rest + n_turn
    a = BIAS_A + np.array([0, 0, G]) + rng.normal(0, SIGMA_A, (n, 3))
    w = BIAS_W + rng.normal(0, SIGMA_W, (n, 3))
    w[n_rest : n_rest + n_turn, 2] += math.radians(20.0)
    t = np.arange(n) / FS
    with_gyro = detect_static_intervals(t, a, w)
    assert len(with_gyro.intervals) == 2
    assert with_gyro.intervals[0].stop <= n_rest and with_gyro.intervals[1].start >= n_rest + n_turn
    assert not with_gyro.still_mask[n_rest : n_rest + n_turn].any()
    # accelerometer only: the turn is invisible (the reason the gyro test exists)
    accel_only = detect_static_intervals(t, a)
    assert [(i.start, i.stop) for i in accel_only.intervals] == [(0, n)]
    # and switching the gyro test off behaves the same
    off = detect_static_intervals(t, a, w, gyro_rate_factor=None)
    assert off.gyro_rate is None and len(off.intervals) == 1


def test_min_duration_and_margin():
    rests, moves = schedule(6)
    rests[3] = 1.6  # a short pose
    t, a, w, truth, _ = session(6, [10.0] + rests, moves)
    keep = detect_static_intervals(t, a, w, init_rest_s=10, min_duration_s=0.5)
    drop = detect_static_intervals(t, a, w, init_rest_s=10, min_duration_s=2.0)
    assert len(keep.intervals) == len(truth)
    assert len(drop.intervals) == len(truth) - 1
    assert all(iv.n >= 200 for iv in drop.intervals)
    # a wider margin trims each border with motion by the difference, not the series ends
    wide = detect_static_intervals(t, a, w, init_rest_s=10, min_duration_s=0.5, margin_s=0.8)
    assert len(wide.intervals) == len(keep.intervals)
    for x, y in zip(keep.intervals, wide.intervals):
        assert y.start == (0 if x.start == 0 else x.start + 30)
        assert y.stop == (len(t) if x.stop == len(t) else x.stop - 30)


# ---------------------------------------------------------------- batch == incremental


def _random_split(rng, n, max_batch):
    sizes = []
    while n > 0:
        k = int(min(n, rng.integers(1, max_batch + 1)))
        sizes.append(k)
        n -= k
    return sizes


def _feed(tracker, t, a, w, sizes, states=None):
    i = 0
    for k in sizes:
        st = tracker.update(t[i : i + k], a[i : i + k], None if w is None else w[i : i + k])
        if states is not None:
            states.append((i + k, st))
        i += k
    return tracker.finish()


def _same_intervals(got, ref):
    assert [(i.start, i.stop, i.t_start_s, i.t_stop_s, i.n) for i in got] == [
        (i.start, i.stop, i.t_start_s, i.t_stop_s, i.n) for i in ref
    ]
    for x, y in zip(got, ref):
        scale = np.abs(y.accel_mean).max()
        np.testing.assert_allclose(x.accel_mean, y.accel_mean, rtol=0, atol=1e-12 * scale)
        np.testing.assert_allclose(x.accel_std, y.accel_std, rtol=1e-8)
        if y.gyro_mean is not None:
            np.testing.assert_allclose(x.gyro_mean, y.gyro_mean, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(x.gyro_std, y.gyro_std, rtol=1e-8)


@pytest.mark.parametrize("gyro", [True, False])
@pytest.mark.parametrize("max_batch", [1, 9, 700, 5000])
def test_tracker_equals_batch_initial_rest(gyro, max_batch):
    rests, moves = schedule(7)
    t, a, w, _, _ = session(7, [12.0] + rests, moves)
    a = to_counts(a)  # raw counts, as a serial reader delivers them
    w = w if gyro else None
    ref = detect_static_intervals(t, a, w, init_rest_s=12, sample_rate_hz=FS)
    tr = StillnessTracker(FS, init_rest_s=12)
    got = _feed(tr, t, a, w, _random_split(np.random.default_rng(max_batch), len(t), max_batch))
    _same_intervals(got, ref.intervals)
    np.testing.assert_array_equal(tr.noise.accel_var, ref.noise.accel_var)
    assert tr.thresholds == ref.thresholds


def test_tracker_equals_batch_robust_via_from_result():
    rests, moves = schedule(8)
    t, a, w, _, _ = session(8, rests, moves, start_moving=True)
    ref = detect_static_intervals(t, a, w, sample_rate_hz=FS)
    for seed in range(3):
        tr = StillnessTracker.from_result(ref)
        got = _feed(tr, t, a, w, _random_split(np.random.default_rng(seed), len(t), 40 * (seed + 1)))
        _same_intervals(got, ref.intervals)


def test_tracker_live_state_follows_the_batch_level():
    """Row by row, the tracker's level is the batch level of the window centred H rows back."""
    rests, moves = schedule(9, 4)
    t, a, w, truth, means = session(9, [10.0] + rests, moves)
    ref = detect_static_intervals(t, a, w, init_rest_s=10, sample_rate_hz=FS)
    tr = StillnessTracker(FS, init_rest_s=10)
    states = []
    _feed(tr, t, a, w, [1] * len(t), states)
    n_init = 1000
    for n_seen, st in states:
        if n_seen < n_init:
            assert st.calibrating and math.isnan(st.level)
            continue
        assert not st.calibrating
        assert st.level == ref.level[n_seen - 1 - H]
        assert st.is_still == (st.level < 1)
    # in the middle of the second planted rest: still, for about as long as it has lasted,
    # with a running mean equal to the planted reading
    s, e = truth[1]
    mid = (s + e) // 2
    st = states[mid - 1][1]
    assert st.is_still
    assert abs(st.still_for_s - (mid - 1 - s) / FS) < 0.2
    assert np.all(np.abs(st.accel_mean - means[1]) < 5 * SIGMA_A / math.sqrt(mid - s - H) + 0.005)
    assert st.accel_std is not None and np.allclose(st.accel_std, SIGMA_A, rtol=0.3)
    # during the move after it: not still, bar above 1, no running mean
    st = states[e + 100][1]
    assert not st.is_still and st.level > 1 and st.accel_mean is None and st.still_for_s == 0
    # each interval is announced once, by the update that closed it
    announced = [iv for _, st in states for iv in st.new_intervals]
    assert [(i.start, i.stop) for i in announced] == [(i.start, i.stop) for i in ref.intervals[:-1]]


# ---------------------------------------------------------------- edge cases


def test_all_still():
    rng = np.random.default_rng(10)
    n = 3000
    t = np.arange(n) / FS
    a = BIAS_A + [0, 0, G] + rng.normal(0, SIGMA_A, (n, 3))
    w = BIAS_W + rng.normal(0, SIGMA_W, (n, 3))
    for init in (None, 5.0):
        res = detect_static_intervals(t, a, w, init_rest_s=init)
        assert [(i.start, i.stop) for i in res.intervals] == [(0, n)]
        np.testing.assert_allclose(res.noise.accel_std, SIGMA_A, rtol=0.1)
        np.testing.assert_allclose(res.intervals[0].accel_mean, BIAS_A + [0, 0, G], atol=5 * SIGMA_A / math.sqrt(n))


def _tumbling(seed, n, rate_dps=40.0):
    """Continuous rotation about a slowly wandering axis: never at rest."""
    rng = np.random.default_rng(seed)
    c = np.eye(3)
    f, rates = np.empty((n, 3)), np.empty((n, 3))
    axis = rng.normal(size=3)
    for i in range(n):
        axis = axis + 0.02 * rng.normal(size=3)
        u = axis / np.linalg.norm(axis)
        rates[i] = math.radians(rate_dps) * u
        c = c @ _rot(u, math.radians(rate_dps) / FS)
        f[i] = c.T @ [0, 0, G]
    return f + rng.normal(0, SIGMA_A, (n, 3)), rates + rng.normal(0, SIGMA_W, (n, 3))


def test_all_moving():
    n = 3000
    t = np.arange(n) / FS
    a, w = _tumbling(11, n)
    res = detect_static_intervals(t, a, w)
    assert res.intervals == []
    assert res.noise_source == "first_differences"
    assert any("no rest found" in m for m in res.warnings)
    # accelerometer only: the same
    assert detect_static_intervals(t, a).intervals == []
    # after an initial rest, only the rest itself is static
    rng = np.random.default_rng(12)
    rest = np.array([0, 0, G]) + rng.normal(0, SIGMA_A, (1000, 3))
    a2 = np.vstack([rest, a])
    w2 = np.vstack([rng.normal(0, SIGMA_W, (1000, 3)), w])
    t2 = np.arange(len(a2)) / FS
    res2 = detect_static_intervals(t2, a2, w2, init_rest_s=10)
    assert res2.noise_source == "initial_rest"
    assert len(res2.intervals) == 1 and res2.intervals[0].start == 0
    assert 1000 - H <= res2.intervals[0].stop <= 1000


def test_moving_initial_rest_is_flagged():
    rests, moves = schedule(13)
    moves[0] = ([1.0, 0.3, 0.0], 120.0, 3.0)
    t, a, w, _, _ = session(13, rests, moves, start_moving=True)
    res = detect_static_intervals(t, a, w, init_rest_s=2.5)  # the first 3 s are a move
    assert res.noise_source == "initial_rest"
    assert any("was the unit moving" in m for m in res.warnings)


def test_short_series():
    rng = np.random.default_rng(14)
    a = [0, 0, G] + rng.normal(0, SIGMA_A, (101, 3))
    t = np.arange(101) / FS
    res = detect_static_intervals(t, a)  # exactly one window
    assert [(i.start, i.stop) for i in res.intervals] == [(0, 101)]
    with pytest.raises(StillnessInputError, match="shorter than one 101-sample window"):
        detect_static_intervals(t[:100], a[:100])
    with pytest.raises(ValueError, match="too few"):
        detect_static_intervals(t[:1], a[:1])
    with pytest.raises(ValueError, match="needs 1500 samples, the data has 101"):
        detect_static_intervals(t, a, init_rest_s=15)
    with pytest.raises(ValueError, match="shorter than one"):
        detect_static_intervals(t, a, init_rest_s=0.5)


def test_nan_rows():
    rests, moves = schedule(15)
    t, a, w, truth, _ = session(15, [10.0] + rests, moves)
    bad_row = (truth[2][0] + truth[2][1]) // 2
    a[bad_row, 1] = np.nan
    with pytest.raises(StillnessInputError, match=f"row {bad_row}: NaN") as exc:
        detect_static_intervals(t, a, w)
    assert exc.value.row == bad_row
    assert isinstance(exc.value, SolverError)
    res = detect_static_intervals(t, a, w, init_rest_s=10, nan_policy="omit")
    # the NaN row splits its rest: no interval contains it, the others are untouched
    assert not any(iv.start <= bad_row < iv.stop for iv in res.intervals)
    assert np.isinf(res.level[bad_row - H : bad_row + H + 1]).all()
    clean = detect_static_intervals(t, np.nan_to_num(a, nan=a[bad_row - 1, 1]), w, init_rest_s=10)
    far = [(i.start, i.stop) for i in clean.intervals if abs(i.start - bad_row) > 1000 and abs(i.stop - bad_row) > 1000]
    assert set(far) <= {(i.start, i.stop) for i in res.intervals}
    for iv in res.intervals:
        assert np.isfinite(iv.accel_mean).all()
    # the tracker with the same policy agrees
    tr = StillnessTracker(FS, init_rest_s=10, nan_policy="omit")
    got = _feed(tr, t, a, w, _random_split(np.random.default_rng(0), len(t), 50))
    assert [(i.start, i.stop) for i in got] == [(i.start, i.stop) for i in res.intervals]
    # and without it, it names the row
    tr = StillnessTracker(FS, init_rest_s=10)
    tr.update(t[:bad_row], a[:bad_row], w[:bad_row])
    with pytest.raises(StillnessInputError, match=f"row {bad_row}:"):
        tr.update(t[bad_row:], a[bad_row:], w[bad_row:])


def test_bad_input():
    t = np.arange(500) / FS
    a = np.zeros((500, 3))
    with pytest.raises(ValueError, match="accel has 499 rows but t_s has 500"):
        detect_static_intervals(t, a[:-1])
    with pytest.raises(ValueError, match="gyro has 400 rows"):
        detect_static_intervals(t, a, a[:400])
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        detect_static_intervals(t, a[:, :2])
    t_bad = t.copy()
    t_bad[7] = t_bad[6]
    with pytest.raises(ValueError, match="row 7: t_s does not increase"):
        detect_static_intervals(t_bad, a)
    t_bad[7] = np.nan
    with pytest.raises(ValueError, match="row 7: t_s is not a finite number"):
        detect_static_intervals(t_bad, a)
    with pytest.raises(ValueError, match="threshold_factor"):
        detect_static_intervals(t, a, threshold_factor=0)
    with pytest.raises(ValueError, match="nan_policy"):
        detect_static_intervals(t, a, nan_policy="drop")


def test_tracker_misuse():
    with pytest.raises(ValueError, match="exactly one of"):
        StillnessTracker(FS)
    tr = StillnessTracker(FS, init_rest_s=2)
    t = np.arange(300) / FS
    a = np.zeros((300, 3))
    tr.update(t[:10], a[:10], a[:10])
    with pytest.raises(ValueError, match="every update or in none"):
        tr.update(t[10:20], a[10:20])
    with pytest.raises(ValueError, match="row 10: t_s does not increase"):
        tr.update(t[5:20], a[5:20], a[5:20])
    tr.update(t[10:], a[10:], a[10:])  # a failed update left the tracker usable
    assert tr.state.n_samples == 300 and tr.state.is_still
    tr.finish()
    with pytest.raises(ValueError, match="finished"):
        tr.update(t[:1] + 10, a[:1], a[:1])


# ---------------------------------------------------------------- orientations


def test_cluster_orientations_synthetic():
    """Nine poses on six faces, one revisited twice: six orientations, labels by first visit."""
    faces = [(0, 0, 1), (0, 0, -1), (1, 0, 0), (0, 0, 1), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (1, 0, 0), (0, 0, 1)]
    rng = np.random.default_rng(16)
    means = []
    for f in faces:  # each pose off its face by up to 1.5 deg
        tilt = _rot(rng.normal(size=3), math.radians(rng.uniform(0, 1.5)))
        means.append(G * tilt @ np.array(f, float))
    means = np.array(means)
    cl = cluster_orientations(means, max_angle_deg=5.0)
    assert cl.n_orientations == 6
    assert cl.labels.tolist() == [0, 1, 2, 0, 3, 4, 5, 2, 0]
    assert cl.spread_deg.max() < 3.0
    # unsigned counts with a zero-g offset: directions need the offset, given or fitted
    offset = np.array([33123.0, 33276.0, 32360.0])
    counts = means * 415 + offset
    assert cluster_orientations(counts, offset=offset).labels.tolist() == cl.labels.tolist()
    fitted = cluster_orientations(counts, offset="sphere")
    assert fitted.labels.tolist() == cl.labels.tolist()
    np.testing.assert_allclose(fitted.offset, offset, atol=0.02 * 415 * G)
    assert cluster_orientations(counts).n_orientations < 6  # raw counts all point near (1,1,1)
    # 10 deg apart is two orientations at 5 deg, one at 15 deg
    pair = np.array([[0, 0, G], G * _rot([1, 0, 0], math.radians(10)) @ [0, 0, 1]])
    assert cluster_orientations(pair, 5.0).n_orientations == 2
    assert cluster_orientations(pair, 15.0).n_orientations == 1


def test_cluster_orientations_errors():
    with pytest.raises(TooFewPositions):
        cluster_orientations(np.array([[0, 0, 1.0], [1, 0, 0], [0, 1, 0]]), offset="sphere")
    flat = np.array([[math.cos(x), math.sin(x), 0.0] for x in np.linspace(0, 3, 6)])
    with pytest.raises(NotIdentifiable):
        cluster_orientations(flat, offset="sphere")
    assert cluster_orientations(np.zeros((0, 3))).n_orientations == 0


def test_cluster_orientations_of_detected_intervals():
    rests, moves = schedule(17)
    t, a, w, truth, means = session(17, [10.0] + rests, moves)
    res = detect_static_intervals(t, a, w, init_rest_s=10)
    cl = cluster_orientations(res.intervals)
    expect = cluster_orientations(means)
    assert cl.labels.tolist() == expect.labels.tolist()


# ---------------------------------------------------------------- real recordings


def _read(path):
    from station.capture import read_capture

    c = read_capture(path)
    t = np.asarray(c.columns["t"], float)
    a = np.column_stack([c.columns[k] for k in ("ax", "ay", "az")])
    g = np.column_stack([c.columns[k] for k in ("gx", "gy", "gz")])
    return c, t, a, g


def test_xsens_38_intervals(shared_data):
    """SOURCE.md: a 1 s moving-variance detector finds 38 static intervals, a 51.5 s rest
    first, then 37 poses of 3-11 s. imu_tk's own app uses the first 50 s as initial rest."""
    c, t, a, g = _read(shared_data / "imu_tk_xsens" / "imu_tk_xsens.capture.csv")
    res = detect_static_intervals(t, a, g, init_rest_s=50)
    assert len(res.intervals) == 38
    first = res.intervals[0]
    assert first.start == 0 and abs(first.duration_s - 51.5) < 0.3
    # trimmed poses: 3-11 s less up to one window (the half-window margin at each end)
    d = np.array([iv.duration_s for iv in res.intervals[1:]])
    assert d.min() > 3.0 - 1.0 and d.max() < 11.0 + 0.5
    # SOURCE.md: gyro at the first rest has mean (32777, 32460, 32512) counts, sigma ~27
    np.testing.assert_allclose(first.gyro_mean, [32777, 32460, 32512], atol=1.0)
    np.testing.assert_allclose(res.noise.gyro_std, 27, rtol=0.1)
    # no initial rest given: the same 38, bounds within 0.3 s
    rob = detect_static_intervals(t, a, g)
    assert rob.noise_source == "robust" and len(rob.intervals) == 38
    for x, y in zip(res.intervals, rob.intervals):
        assert abs(x.start - y.start) <= 30 and abs(x.stop - y.stop) <= 30
    # static |a| with the datasheet offsets and scales: 9.716-9.902 m/s^2 (SOURCE.md)
    offset, scale = np.array([33123, 33276, 32360.0]), np.array([415, 413, 415.0])
    mag = [np.linalg.norm((iv.accel_mean - offset) / scale) for iv in res.intervals]
    assert 9.70 < min(mag) and max(mag) < 9.92
    # 37 poses revisit 16 distinct orientations (the fitted zero-g offset is the datasheet's)
    cl = cluster_orientations(res.intervals, offset="sphere")
    assert cl.n_orientations == 16
    np.testing.assert_allclose(cl.offset, offset, atol=20)


def test_mpu6050_10_intervals(shared_data):
    """SOURCE.md: 10 static intervals (36.6 s rest, then 9 poses); the authors' detector kept
    10 intervals (static_intervals.csv), each of which lies inside one of ours."""
    c, t, a, g = _read(shared_data / "mpu6050_unc" / "mpu6050_unc_calibration.capture.csv")
    authors = [
        (150, 3613),
        (4297, 4299),
        (4934, 4946),
        (5585, 5690),
        (6205, 6368),
        (7018, 7046),
        (7570, 7765),
        (8297, 8457),
        (9094, 9158),
        (9662, 10095),
    ]
    for init in (36.5, None):
        res = detect_static_intervals(t, a, g, init_rest_s=init)
        assert len(res.intervals) == 10, init
        # the authors declared a 36.5 s initialisation; the unit rests about 1 s longer
        assert 36.5 <= res.intervals[0].duration_s < 38.0
        for s, e in authors:
            assert sum(iv.start <= s and e <= iv.stop for iv in res.intervals) == 1, (s, e)
        assert cluster_orientations(res.intervals).n_orientations == 10
    # the live tracker on the same rows, in serial-reader-sized batches, agrees
    tr = StillnessTracker(100.0, init_rest_s=36.5)
    ref = detect_static_intervals(t, a, g, init_rest_s=36.5, sample_rate_hz=100.0)
    _same_intervals(_feed(tr, t, a, g, _random_split(np.random.default_rng(1), len(t), 30)), ref.intervals)


def test_ferraris_13_intervals_cover_labelled_sections(shared_data):
    """SOURCE.md: 13 static intervals of 2 s or more (the six labelled poses plus rests before
    and after the three 360 deg turns); each labelled section lies in one detected interval."""
    c, t, a, g = _read(shared_data / "imucal_ferraris" / "imucal_ferraris.capture.csv")
    res = detect_static_intervals(t, a, g)
    assert res.noise_source == "robust"
    long = [iv for iv in res.intervals if iv.duration_s >= 2.0]
    assert len(long) == 13
    cl = cluster_orientations(res.intervals)
    assert cl.n_orientations == 6  # the six faces; the extra rests repeat them

    cl_, tl, al, gl = _read(shared_data / "imucal_ferraris" / "imucal_ferraris_labelled.capture.csv")
    np.testing.assert_array_equal(al, a)
    pos = cl_.columns["position"]
    for label in ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a"):
        rows = np.flatnonzero(pos == label)
        assert len(rows) > 400
        covering = [iv for iv in res.intervals if iv.start <= rows[0] and rows[-1] < iv.stop]
        assert len(covering) == 1, label
        # +x up reads +1 g on x, and so on (imucal's table)
        axis, sign = "xyz".index(label[0]), (1 if label[2] == "p" else -1)
        assert sign * covering[0].accel_mean[axis] > 9.0
