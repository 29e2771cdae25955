"""How the importer puts a second sensor on the rows of the first (station/importers/_common.align)."""

from __future__ import annotations

import numpy as np

from station.importers._common import align


def test_slower_stream_is_interpolated_exactly_on_a_line_and_left_empty_outside():
    grid = np.arange(0, 2, 0.005)  # 200 Hz rows
    t = np.arange(0.1, 1.9, 0.02)  # 50 Hz compass
    v = np.column_stack([3 * t + 1, -t, np.full_like(t, 7.0)])
    out, mode = align(grid, t, v, 0.005)
    assert mode == "linear"
    inside = (grid >= t[0]) & (grid <= t[-1])
    np.testing.assert_allclose(out[inside, 0], 3 * grid[inside] + 1, atol=1e-12)
    assert np.isnan(out[~inside]).all()


def test_same_rate_stream_keeps_its_own_samples():
    rng = np.random.default_rng(0)
    grid = np.arange(0, 1, 0.01)
    t = grid + rng.uniform(-0.003, 0.003, grid.size)  # the gyro, 100 Hz, its own jitter
    v = rng.normal(size=(grid.size, 3))
    out, mode = align(grid, t, v, 0.01)
    assert mode == "nearest"
    np.testing.assert_array_equal(out, v)  # no smoothing: the noise is the sensor's


def test_a_gap_in_the_second_stream_stays_empty():
    grid = np.arange(0, 1, 0.01)
    t = np.concatenate([np.arange(0, 0.4, 0.01), np.arange(0.6, 1, 0.01)])
    out, _ = align(grid, t, np.ones((t.size, 1)), 0.01)
    gap = (grid > 0.42) & (grid < 0.58)
    assert np.isnan(out[gap]).all() and not np.isnan(out[~gap & (grid < 0.39)]).any()
