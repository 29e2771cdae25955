"""Flight-controller logs carry the vehicle's body frame: x forward, y right, z down (PX4,
ArduPilot, MAVLink). P4 works in its own frame (x forward, y up, z right) and takes a
capture's axes from its ``frame`` metadata, so an imported log must say it: without it a level
vehicle was reported rolled 90 degrees and the drift's y (up) and z (right) were the log's
y (right) and z (down). (The drift on the sensor's own axes, which the exporter writes, was
right either way: the attitude from the accelerometer absorbs the relabelling.)
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from station.capture import read_capture
from tests.station_run import run_station
from tests.test_import_ardupilot import DataFlashWriter

OMEGA_IE_RAD_S = 7.292115e-5  # WGS-84
LAT_DEG = 47.397742  # the GPS fix DataFlashWriter.gps writes (ArduPilot SITL's home)
FRD = "x forward, y right, z down"


def _still_level_bin(path, bias_rad_s, seconds=240.0, rate_hz=100.0, noise_rad_s=5e-4, seed=7):
    """A DataFlash log of a level vehicle standing still, nose north: the gyro reads the drift
    plus the Earth's rate in FRD (north, east, down components, heading 0), the accelerometer
    the specific force of a level board (-g on z down)."""
    rng = np.random.default_rng(seed)
    lat = math.radians(LAT_DEG)
    earth = OMEGA_IE_RAD_S * np.array([math.cos(lat), 0.0, -math.sin(lat)])
    w = DataFlashWriter(path)
    w.param(1000, "AHRS_ORIENTATION", 0)
    n = int(seconds * rate_hz)
    for k in range(n):
        t = 500_000 + round(k * 1e6 / rate_hz)
        gyro = np.asarray(bias_rad_s) + earth + rng.normal(0, noise_rad_s, 3)
        acc = np.array([0.0, 0.0, -9.80665]) + rng.normal(0, 0.02, 3)
        w.imu(t, 0, gyro, acc)
        if k == 10:
            w.gps(t, LAT_DEG, 8.545594, 488.0)
    w.close()


@pytest.fixture(scope="module")
def still_bin(tmp_path_factory):
    path = tmp_path_factory.mktemp("frame") / "still.bin"
    bias = (0.0012, -0.0007, 0.0004)
    _still_level_bin(path, bias)
    return path, np.asarray(bias)


def test_dataflash_import_says_the_body_frame(still_bin, tmp_path):
    log, _ = still_bin
    out = tmp_path / "p4.csv"
    res = run_station("import", log, "--procedure", "gyro-drift", "--out", out)
    assert res.returncode == 0, res.stderr
    meta = read_capture(out).meta
    assert meta["frame"] == FRD
    assert abs(float(meta["latitude_deg"]) - LAT_DEG) < 1e-6


def test_p4_on_an_imported_log_reports_a_level_board_and_the_drift_on_its_axes(still_bin):
    """The vehicle stands level: pitch and roll 0. The drift in P4's frame (x forward, y up,
    z right) is the FRD truth (x, -z, y), and on the sensor's axes (what the exporter writes as
    INS_GYROFFS) the truth itself, within 4 sigma, with the Earth's rate at the GPS latitude
    removed."""
    log, bias = still_bin
    res = run_station("calibrate", log, "--procedure", "gyro-drift", "--json")
    assert res.returncode == 0, res.stderr
    doc = json.loads(res.stdout)
    p = doc["params"]
    assert abs(p["pitch_deg"]) < 1.0 and abs(p["roll_deg"]) < 1.0, (p["pitch_deg"], p["roll_deg"])
    raw = doc["drift_raw"]
    assert raw["axes"] == "the capture's gx gy gz" and raw["unit"] == "rad/s"
    value, sigma = np.asarray(raw["value"]), np.asarray(raw["sigma"])
    assert np.all(sigma < 0.1 * OMEGA_IE_RAD_S), sigma  # the test can see an Earth-rate error
    assert np.all(np.abs(value - bias) < 4 * sigma), (value - bias, sigma)
    fur = np.array([bias[0], -bias[2], bias[1]])
    body, body_sigma = np.asarray(p["drift"]), np.asarray(doc["uncertainty"]["drift"])
    assert np.all(np.abs(body - fur) < 4 * body_sigma), (body, fur, body_sigma)


@pytest.mark.parametrize(
    "log,source,frame",
    [
        ("sample.ulg", "auto", FRD),  # sensor_combined: after the board rotation
        ("sample_logging_tagged_and_default_params.ulg", "raw", FRD),  # SITL, SENS_BOARD_ROT 0, CAL_*_ROT -1
        ("sample_log_small.ulg", "raw", "x back, y left, z down"),  # CubeOrange with SENS_BOARD_ROT 4 (yaw 180)
        ("sample_log_small.ulg", "combined", FRD),
    ],
)
def test_px4_import_says_where_the_axes_point(shared_data, tmp_path, log, source, frame):
    out = tmp_path / "c.csv"
    path = shared_data / "px4_ulog" / "original" / log
    res = run_station("import", path, "--procedure", "gyro-drift", "--source", source, "--out", out)
    assert res.returncode == 0, res.stderr
    assert read_capture(out).meta["frame"] == frame
