"""Live detectors: orientation check, the compass coverage (the calibration's own measure,
solvers.detectors, shared with the guides), and the glue that feeds reader batches from
the project's simulator to the stillness tracker."""

from __future__ import annotations

import math

import numpy as np
import pytest

from solvers import compass as C
from solvers.detectors import FieldCoverage
from solvers.positions import P1_POSITIONS
from solvers.simulate import LiveImu
from station.device.live import LiveDetectors, orientation_check
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


def test_field_coverage_is_the_calibrations_measure():
    """Every row kept (keep_hz = rate): exactly coverage(midrange_directions(rows)), the
    number solvers.compass.check_orientations refuses below 40 %; subsampled, close."""
    rng = np.random.default_rng(3)
    h = np.array([12.0, -7.0, 30.0])  # hard iron, raw units
    u = rng.normal(size=(3000, 3))
    u[:, 2] = np.abs(u[:, 2])  # the upper hemisphere only: a partial sweep
    rows = h + 50.0 * u / np.linalg.norm(u, axis=1, keepdims=True)
    exact = C.coverage(C.midrange_directions(rows))
    full = FieldCoverage(rate_hz=10.0, keep_hz=10.0, recentre_frac=0.0)  # follow the midrange exactly
    for chunk in np.array_split(rows, 37):
        full.update(chunk)
        # kept incrementally while the centre stays, recomputed when it moves: always the
        # calibration's function of the directions so far
        assert full.fraction == C.coverage(full.directions())
        full.grid()
    once = FieldCoverage(rate_hz=10.0, keep_hz=10.0)
    once.update(rows)
    np.testing.assert_array_equal(full.grid(), once.grid())
    assert full.fraction == exact
    lazy = FieldCoverage(rate_hz=10.0, keep_hz=10.0)  # default: re-centres after a 1 % move
    for chunk in np.array_split(rows, 37):
        lazy.update(chunk)
        assert lazy.fraction == C.coverage(lazy.directions())
    assert abs(lazy.fraction - exact) <= 1 / C.COVERAGE_CELLS
    assert (
        np.linalg.norm(lazy.centre() - lazy.midrange_centre()) <= 0.01 * 50.0 * 1.01 and 0.5 < exact < 1.0
    )  # about its midrange a hemisphere spreads out
    sub = FieldCoverage(rate_hz=100.0, keep_hz=10.0)
    sub.update(rows)
    assert sub.n_kept == 300 and abs(sub.fraction - exact) <= 2 / C.COVERAGE_CELLS
    assert full.enough == (exact >= C.MIN_COVERAGE)


def test_field_coverage_of_a_still_unit_is_one_direction_and_the_map_draws_it():
    """Noise about a fixed field: axes never turned over keep centre 0 (one direction,
    ~7 % of the sphere within 30°), not the noise's midrange (which would point anywhere)."""
    rng = np.random.default_rng(0)
    rows = np.array([0.0, 0.0, 45.0]) + 0.05 * rng.normal(size=(2000, 3))
    cov = FieldCoverage(rate_hz=100.0)
    cov.update(rows)
    assert cov.fraction <= 4 / C.COVERAGE_CELLS and not cov.enough
    grid = cov.grid(6, 12)
    # the 30° cap about +z: part of every cell of the top band (z > 0.67, 0..48°), nothing else
    assert np.all((grid[-1] > 0) & (grid[-1] < 1)) and not grid[:-1].any()
    cov.update([[np.nan, 0, 0]])  # ignored
    assert cov.n_kept == 200


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
    assert at_rest <= 4 / C.COVERAGE_CELLS  # one direction: its 30° cap, ~7 % of the sphere
    imu.set_auto(True)
    for _ in range(12):
        st = det.update(batch_from(imu, 3.5))  # hold 1 s + move 2.5 s per position
    assert st.coverage > 0.5 and st.coverage > 5 * at_rest  # the 30° measure: 12 positions and the moves


def test_field_coverage_with_a_known_centre_uses_every_block():
    rng = np.random.default_rng(5)
    u = rng.normal(size=(600, 3))
    rows = [3.0, 4.0, -2.0] + 40.0 * u / np.linalg.norm(u, axis=1, keepdims=True)
    cov = FieldCoverage(rate_hz=10.0, center=[3.0, 4.0, -2.0])
    for chunk in np.array_split(rows, 6):
        cov.update(chunk)
    assert len(cov.directions()) == 600
    assert cov.fraction == C.coverage(rows - [3.0, 4.0, -2.0]) == 1.0
