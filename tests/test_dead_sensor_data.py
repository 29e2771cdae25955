"""A sensor whose every sample reads exactly 0, 0, 0 gave no data (no compass fitted, disabled,
or never read): it is said as such, not taken for a measurement. An ArduPilot log whose MAG
messages are all zero was calibrated as a compass that "was not turned".

The logs are written by pymavlink's own encoders (tests/test_import_ardupilot.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from station.capture import Capture, read_capture, write_capture
from tests.station_run import assert_one_line_refusal, run_station
from tests.test_import_ardupilot import DataFlashWriter


def _bin_with_zero_mag(path, n=400):
    """IMU at 400 Hz, MAG at 100 Hz reading 0, 0, 0 in every message."""
    w = DataFlashWriter(path)
    rng = np.random.default_rng(1)
    for k in range(n):
        t = 500_000 + k * 2500
        w.imu(t, 0, rng.normal(0, 0.01, 3), np.array([0.0, 0.0, -9.8]) + rng.normal(0, 0.05, 3))
        if k % 4 == 0:
            w.mag(t + 100, 0, (0, 0, 0))
    w.close()
    return path


@pytest.mark.parametrize("command", [["calibrate"], ["diagnose"], ["inspect"], ["import", "--out", "{out}"]])
def test_a_log_whose_magnetometer_reads_only_zeros_says_so_for_the_compass(tmp_path, command):
    log = _bin_with_zero_mag(tmp_path / "nomag.bin")
    out = tmp_path / "out.csv"
    res = run_station(command[0], log, "--procedure", "compass", *[a.format(out=out) for a in command[1:]])
    assert_one_line_refusal(res, f"{log}: ", "no magnetometer data (all zero)")
    assert "not turned" not in res.stderr
    assert not out.exists()


def test_the_zero_magnetometer_is_left_out_of_another_procedures_capture(tmp_path):
    log = _bin_with_zero_mag(tmp_path / "nomag.bin")
    out = tmp_path / "out.csv"
    res = run_station("import", log, "--procedure", "gyro-drift", "--out", out)
    assert res.returncode == 0, res.stderr
    assert "no magnetometer data (all zero)" in res.stderr and res.stderr.count("\n") == 1
    c = read_capture(out)
    assert "mx" not in c.columns and c.n_rows > 300


def test_a_capture_whose_magnetometer_reads_only_zeros_says_so(tmp_path, shared_data):
    """The same for a station capture: a real compass sweep (sunsided, MPU-6050 + HMC5883L)
    with its magnetometer columns zeroed."""
    src = read_capture(shared_data / "sunsided_marg" / "sunsided_full_sphere.capture.csv")
    cols = {k: np.asarray(v) for k, v in src.columns.items()}
    for c in ("mx", "my", "mz"):
        cols[c] = np.zeros_like(cols[c])
    path = tmp_path / "zero.csv"
    write_capture(path, Capture(dict(src.meta), cols))
    for command in ("calibrate", "diagnose"):
        assert_one_line_refusal(run_station(command, path), f"{path}: ", "no magnetometer data (all zero)")
