"""Live detectors: orientation check, equal-area sphere coverage, and the glue that feeds
reader batches from the project's simulator to the stillness tracker."""
from __future__ import annotations

import math

import numpy as np
import pytest

from solvers.positions import P1_POSITIONS
from solvers.simulate import LiveImu
from station.device.live import LiveDetectors, SphereCoverage, eq_partition, orientation_check
from station.device.protocol import SENSOR_FIELDS
from station.device.reader import Batch
from station.device.simdevice import NOMINAL_ACCEL_V


def batch_from(imu: LiveImu, seconds: float) -> Batch:
    d = imu.read(int(round(seconds * imu.rate_hz)))
    n = len(d["t_s"])
    return Batch(d["t_s"], np.arange(n), np.zeros(n, dtype=np.int64), np.column_stack([d[k] for k in SENSOR_FIELDS]))


def nominal_B_M():
    """A = B + M V from the simulated family's nominal front end (V = K f + b)."""
    M = np.linalg.inv(NOMINAL_ACCEL_V["K"])
    return -M @ NOMINAL_ACCEL_V["b"], M


def test_orientation_check_known_angles():
    g = 9.81
    assert orientation_check([g, 0, 0], "x_up").angle_deg == pytest.approx(0.0, abs=1e-12)
    c = orientation_check([0, 0, g], "x_up")
    assert c.angle_deg == pytest.approx(90.0) and not c.wrong_face_up and not c.ok
    c = orientation_check([-g, 0.01, 0], "x_up")
    assert c.angle_deg > 179.9 and c.wrong_face_up
    tilt = math.radians(5.0)
    c = orientation_check([math.cos(tilt), 0, math.sin(tilt)], "x_up", tolerance_deg=6)
    assert c.angle_deg == pytest.approx(5.0, abs=1e-9) and c.ok
    c = orientation_check([1, 1, 0], P1_POSITIONS["xy_45"])
    assert c.angle_deg == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("n", [1, 2, 3, 12, 100, 400])
def test_eq_partition_cells_have_equal_area(n):
    edges, per_zone = eq_partition(n)
    assert sum(per_zone) == n and edges[0] == 0 and edges[-1] == pytest.approx(math.pi)
    areas = [2 * math.pi * (math.cos(edges[j]) - math.cos(edges[j + 1])) / per_zone[j] for j in range(len(per_zone))]
    np.testing.assert_allclose(areas, 4 * math.pi / n, rtol=1e-12)


def test_sphere_coverage_counts_cells():
    s = SphereCoverage(100)
    s.update([[0, 0, 2.0], [0, 0, 5.0]])
    assert s.fraction == pytest.approx(0.01)
    s.update([[0, 0, -1.0], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [np.nan, 0, 0], [0, 0, 0]])
    assert s.visited.sum() == 6
    # uniform directions: every cell, with counts consistent with equal areas (Poisson, 4000 each)
    u = SphereCoverage(100)
    u.update(np.random.default_rng(0).normal(size=(400_000, 3)))
    assert u.fraction == 1.0 and abs(u.counts - 4000).max() < 6 * math.sqrt(4000)


def test_stillness_and_orientation_from_the_simulator():
    imu = LiveImu(procedure="accel-tabletop", seed=2, rate_hz=100.0)
    B, M = nominal_B_M()
    det = LiveDetectors(100.0, units=imu.units, init_rest_s=2.0, accel_B=B, accel_M=M)
    det.expect("x_up")  # the simulated unit starts at positions[0] = x_up
    st = det.update(batch_from(imu, 4.0))
    assert st.stillness.is_still and st.stillness.still_for_s > 1.0
    # placement error ~1 deg, table tilt 0.3 deg, nominal scaling (2 % scale, 0.03 V bias): a few degrees
    assert st.orientation.ok and st.orientation.angle_deg < 5.0
    det.expect("x_down")
    st = det.update(None)
    assert st.orientation.wrong_face_up and st.orientation.angle_deg > 170.0
    imu.set_orientation("z_up")
    st = det.update(batch_from(imu, 1.5))
    assert not st.stillness.is_still
    st = det.update(batch_from(imu, 5.0))
    det.expect("z_up")
    st = det.update(None)
    assert st.stillness.is_still and st.orientation.ok and st.samples == 1050


def test_raw_units_without_a_calibration_give_no_orientation_guess():
    imu = LiveImu(procedure="accel-tabletop", seed=0, rate_hz=100.0)
    det = LiveDetectors(100.0, units=imu.units, init_rest_s=2.0)
    det.expect("z_up")
    st = det.update(batch_from(imu, 2.5))
    assert st.orientation is None and "rough calibration" in det.orientation_unavailable


def test_compass_coverage_grows_as_the_scripted_operator_turns_the_unit():
    imu = LiveImu(procedure="compass", seed=4, rate_hz=50.0, hold_s=1.0)
    det = LiveDetectors(50.0, units=imu.units, init_rest_s=2.0)
    st = det.update(batch_from(imu, 2.0))
    at_rest = st.coverage
    assert at_rest <= 0.03  # one direction plus noise: a cell or two of 100
    imu.set_auto(True)
    for _ in range(12):
        st = det.update(batch_from(imu, 3.5))  # hold 1 s + move 2.5 s per position
    assert st.coverage > 0.15 and st.coverage > 5 * at_rest
