"""The simulated bench follows the operator (solvers.simulate.LiveImu / LiveVehicle,
station.sources): a placement lands within a hand's error of the asked attitude and rocks
until the same stillness detector the guides use sees it settle; a sweep covers the
sphere as the compass calibration measures it; the reference IMU reads the unit's motion
with its own small drift; the vehicle's velocity set is ill-conditioned on a straight road
and well-conditioned with turns and hills."""

from __future__ import annotations

import math

import numpy as np
import pytest

from solvers import frames
from solvers.detectors import FieldCoverage
from solvers.ldv import KAPPA_REFUSE, KAPPA_WARN, velocity_condition
from solvers.positions import P1_POSITIONS, angle_between_deg
from solvers.simulate import PLACEMENT_FLAT_DEG, PLACEMENT_TILTED_DEG, WOBBLE_S, LiveImu, LiveVehicle
from solvers.stillness import StillnessTracker

RATE_HZ = 100.0


def still_track(imu, seconds, tracker, chunk=10):
    """Feed `seconds` of the bench to the tracker; (times, is_still) per chunk."""
    out = []
    for _ in range(int(seconds * RATE_HZ / chunk)):
        d = imu.read(chunk)
        st = tracker.update(
            d["t_s"], np.column_stack([d["ax"], d["ay"], d["az"]]), np.column_stack([d["gx"], d["gy"], d["gz"]])
        )
        out.append((float(d["t_s"][-1]), st.is_still))
    return out


def test_a_placement_rocks_then_settles_as_the_p1_guide_sees_it():
    imu = LiveImu(seed=11, rate_hz=RATE_HZ, hold_s=1e9)
    tracker = StillnessTracker(RATE_HZ, init_rest_s=2.0, window_s=0.5, min_duration_s=0.0, margin_s=0.0)
    still_track(imu, 3.0, tracker)
    t0 = imu.t_s
    imu.set_orientation("y_up")
    track = still_track(imu, 10.0, tracker)
    landed = t0 + imu.MOVE_S
    # moving, then rocking on its face after the set-down: not still for a while after landing
    rocking = [s for t, s in track if landed + 0.2 <= t <= landed + 0.7]
    assert rocking and not any(rocking)
    first_still = next(t for t, s in track if s and t > landed)
    assert landed + 0.7 < first_still < landed + WOBBLE_S + 1.0  # the detector sees it settle
    assert all(s for t, s in track if t > landed + WOBBLE_S + 1.0)


@pytest.mark.parametrize("name, bound", [("z_up", PLACEMENT_FLAT_DEG), ("yz_45", PLACEMENT_TILTED_DEG)])
def test_placements_land_within_a_hands_error_and_differ_each_time(name, bound):
    imu = LiveImu(seed=3, rate_hz=RATE_HZ, hold_s=1e9)
    angles, headings = [], []
    for _ in range(12):
        imu.set_orientation(name)
        imu.read(int((imu.MOVE_S + WOBBLE_S + 0.5) * RATE_HZ))
        f_dir = imu.C.T @ np.array([0.0, 0.0, -1.0])  # the specific force direction, body frame
        angles.append(angle_between_deg(f_dir, P1_POSITIONS[name]))
        headings.append(math.degrees(frames.C_n_b_to_euler(imu.C)[2]))
    assert max(angles) <= bound + 1e-9 and min(angles) < bound and max(angles) > 0.2 * bound
    assert np.ptp(headings) > 30  # set down at any heading


def test_a_sweep_covers_the_sphere_as_the_compass_calibration_measures_it():
    imu = LiveImu(procedure="compass", seed=0, rate_hz=50.0, hold_s=1e9)
    cov = FieldCoverage(50.0)
    imu.set_orientation("sweep")
    assert imu.driving == "sweep"
    fractions = []
    for _ in range(60):
        d = imu.read(50)
        cov.update(np.column_stack([d["mx"], d["my"], d["mz"]]))
        fractions.append(cov.fraction)
    assert fractions[9] < 0.8 and fractions[-1] >= 0.8  # a minute of sweeping, not ten seconds
    imu.set_orientation("still")
    assert imu.driving is None
    d = imu.read(int((WOBBLE_S + 0.5) * 50))
    g = np.column_stack([d["gx"], d["gy"], d["gz"]])
    assert np.linalg.norm(g[-10:].mean(axis=0) - imu.gyro["eps"]) < 0.005  # at rest: the gyro bias


def test_the_reference_imu_reads_the_units_motion_with_its_own_small_drift():
    imu = LiveImu(procedure="gyro-drift", seed=5, rate_hz=RATE_HZ, hold_s=1e9, reference=True)
    imu.set_orientation("table")
    d = imu.read(int(60 * RATE_HZ))
    g = np.column_stack([d["gx"], d["gy"], d["gz"]])
    r = np.column_stack([d["ref_gx"], d["ref_gy"], d["ref_gz"]])
    assert np.ptp(r[:, 2]) > 0.3  # the rate table turns both
    diff = (g - r).mean(axis=0)
    # unit minus reference = the unit's drift minus the reference's (~1 °/h), within the noise
    np.testing.assert_allclose(diff, imu.gyro["eps"] - imu.ref_bias, atol=5 * 0.003 / math.sqrt(len(g)))


def test_a_straight_road_leaves_the_ldv_angles_unidentifiable_turns_fix_it():
    car = LiveVehicle(seed=2)
    car.read(50)
    parked = car.read(50)
    assert np.allclose([parked[k] for k in ("vx", "vy", "vz")], 0.0, atol=0.05)
    car.set_orientation("drive")
    car.read(300)  # 30 s to cruise
    d = car.read(1200)  # two minutes straight
    v = np.column_stack([d["vx"], d["vy"], d["vz"]])
    assert 5 < np.median(v[:, 0]) < 16 and velocity_condition(v) > KAPPA_REFUSE
    car.set_orientation("turns")
    car.read(100)
    d = car.read(1200)
    v = np.column_stack([d["vx"], d["vy"], d["vz"]])
    assert velocity_condition(v) < KAPPA_WARN
    with pytest.raises(ValueError, match="unknown vehicle command"):
        car.set_orientation("fly")


def test_the_level_unit_points_its_forward_axis_north_as_p4_asks():
    """P4 on a static base: 'level, forward (x) axis north'. The simulated unit lies so:
    the mode B calibration removes the Earth rate for that heading and recovers the
    unit's own drift (in P4's frame, x fwd, y up, z right, from x fwd, y left, z up)."""
    from station.calibrate import calibrate_capture
    from station.procedures.gyrodrift_guide import HoldConfig, HoldGuide

    imu = LiveImu(procedure="gyro-drift", seed=8, rate_hz=RATE_HZ, hold_s=1e9)
    C = imu.C
    np.testing.assert_allclose(C @ [1.0, 0.0, 0.0], [1.0, 0.0, 0.0], atol=1e-12)  # x north (NED)
    np.testing.assert_allclose(C @ [0.0, 0.0, 1.0], [0.0, 0.0, -1.0], atol=1e-12)  # z up
    guide = HoldGuide(
        sample_rate_hz=RATE_HZ,
        units=imu.units,
        device_id=imu.device_id,
        site=imu.site,
        config=HoldConfig(duration_s=300.0, frame="x forward, y left, z up"),
    )
    while guide.phase != "done":
        d = imu.read(100)
        guide.update(
            d["t_s"],
            np.column_stack([d["ax"], d["ay"], d["az"]]),
            np.column_stack([d["gx"], d["gy"], d["gz"]]),
            d["temp_c"],
        )
    res = calibrate_capture(guide.capture(extra_meta={"accel_offset": "1.65, 1.65, 1.65"}))
    eps = imu.gyro["eps"]
    truth_p4 = np.array([eps[0], eps[2], -eps[1]])
    err = np.abs(np.asarray(res["params"]["drift"]) - truth_p4)
    assert np.all(err < 4 * np.asarray(res["uncertainty"]["drift"])), (err, res["uncertainty"]["drift"])
