"""Memory of `station calibrate` on a long time series, measured by tracemalloc (numpy's arrays
are traced; the figure is deterministic, not a timing). The figures for a 160 MB capture, as
RSS, are benchmarks/bench_calibrate_memory.py's (docs/benchmarks.md)."""

from __future__ import annotations

import tracemalloc

from station.calibrate import calibrate_capture
from station.capture import read_capture
from tests.station_run import run_station


def test_a_long_gyro_drift_record_is_calibrated_within_7_times_its_arrays(tmp_path):
    """P4 mode B on 200,000 rows (12.8 MB of numeric arrays): the stillness detector and the
    drift fit together peaked at 8.1 times the capture's arrays (copies of every (N, 3) array:
    fancy-indexed rows when every row was finite, squared differences and their median's copy,
    a window-sum buffer grown to four times its piece, window statistics kept past their use).
    Now 5.8 times, with the same result to the bit."""
    path = tmp_path / "long.csv"
    res = run_station(
        "simulate", "--procedure", "gyro-drift", "--out", path, "--seed", "400003", "--option", "duration_s=2000"
    )
    assert res.returncode == 0, res.stderr
    capture = read_capture(path)
    arrays = sum(a.nbytes for a in capture.columns.values())
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        result = calibrate_capture(capture)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert result["params"]["mode"] == "static"
    assert peak <= 7.0 * arrays, f"peak {peak / 1e6:.1f} MB = {peak / arrays:.2f} x the arrays ({arrays / 1e6:.1f} MB)"
