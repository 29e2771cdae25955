"""Forward models: conventions tested once, forward/inverse exact, effects switch on by name."""

from __future__ import annotations

import math

import numpy as np
import pytest

from solvers import frames
from solvers.models import Conditions, accel, gyro, ldv, mag
from solvers.positions import P1_POSITIONS, C_n_b_for


def test_specific_force_convention_axis_up_reads_plus_g():
    # Level, Z up: the body z axis points up, so the specific force reads (0, 0, +g).
    C_n_b = C_n_b_for([0.0, 0.0, 1.0])
    g = 9.8
    f_b = C_n_b.T @ np.array([0.0, 0.0, -g])  # NED specific force at rest is "up" = −z
    np.testing.assert_allclose(f_b, [0.0, 0.0, g], atol=1e-12)


@pytest.mark.parametrize("name", list(P1_POSITIONS))
def test_p1_positions_are_reached_by_their_attitudes(name):
    d = P1_POSITIONS[name]
    for heading in (0.0, 1.0, -2.5):
        C = C_n_b_for(d, heading)
        np.testing.assert_allclose(C.T @ C, np.eye(3), atol=1e-12)
        assert np.linalg.det(C) == pytest.approx(1.0)
        np.testing.assert_allclose(C.T @ [0, 0, -1.0], d, atol=1e-12)


def test_euler_round_trip_and_yaw_sense():
    C = frames.euler_to_C_n_b(0.1, -0.2, 2.0)
    np.testing.assert_allclose(frames.C_n_b_to_euler(C), (0.1, -0.2, 2.0), atol=1e-12)
    # yaw 90°: body x (forward) points east
    np.testing.assert_allclose(frames.euler_to_C_n_b(0, 0, math.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_rotvec_round_trip_including_near_pi():
    rng = np.random.default_rng(3)
    for _ in range(50):
        v = rng.normal(size=3)
        v *= rng.uniform(0, math.pi - 1e-3) / np.linalg.norm(v)
        np.testing.assert_allclose(frames.matrix_to_rotvec(frames.rotvec_to_matrix(v)), v, atol=1e-7)


def test_normal_gravity_known_values():
    # WGS-84 normal gravity: 9.7803253359 m/s² at the equator, 9.8321849378 at the poles
    # (NIMA TR8350.2 table 3.4); tolerance 1e-9 m/s², rounding of the published constants.
    assert frames.normal_gravity_mps2(0.0) == pytest.approx(9.7803253359, abs=1e-9)
    assert frames.normal_gravity_mps2(90.0) == pytest.approx(9.8321849378, abs=1e-9)
    # free-air gradient about −3.086e-6 s⁻²: 1000 m up is ~3.09 mm/s² less
    assert frames.normal_gravity_mps2(45.0) - frames.normal_gravity_mps2(45.0, 1000.0) == pytest.approx(
        3.086e-3, rel=2e-3
    )


def test_p4_frames_level_north_projection_by_hand():
    # Level, x forward pointing north, y up, z right (east): body = nav (N, U, E).
    C = frames.p4_C_n_b(0.0, 0.0, 0.0)
    np.testing.assert_allclose(C, np.eye(3), atol=1e-12)
    lat = 30.0
    w = gyro.earth_rate_body(lat, C)
    np.testing.assert_allclose(w, [7.2921151e-5 * math.cos(math.radians(30)), 7.2921151e-5 * 0.5, 0.0], rtol=1e-12)
    # pitch and roll recovered from the accelerometer
    C2 = frames.p4_C_n_b(math.radians(5), math.radians(-7), 0.0)
    f_b = C2.T @ np.array([0.0, 9.8, 0.0])
    p, r = frames.p4_pitch_roll_from_accel(f_b)
    assert math.degrees(p) == pytest.approx(5.0, abs=1e-9)
    assert math.degrees(r) == pytest.approx(-7.0, abs=1e-9)
    # pitch up raises the forward axis: x then reads +g sinθ
    assert f_b[0] == pytest.approx(9.8 * math.sin(math.radians(5)))


def _accel_params(rng):
    K = np.diag([0.085, 0.09, 0.08]) @ (np.eye(3) + 0.01 * rng.normal(size=(3, 3)))
    return {"K": K, "b": np.array([1.6, 1.7, 1.65])}


@pytest.mark.parametrize(
    "effects",
    [
        (),
        ("quadratic",),
        ("cubic",),
        ("scale_asymmetry",),
        ("temperature_bias", "time_drift"),
        ("quadratic", "cubic", "scale_asymmetry"),
    ],
)
def test_accel_inverse_is_exact(effects):
    rng = np.random.default_rng(1)
    p = _accel_params(rng)
    for e in effects:
        p.update(
            accel.effect_blocks(e, {"quadratic": 1e-3, "cubic": 1e-5, "scale_asymmetry": 1e-3}.get(e, 0.01), rng, p)
        )
    f = rng.normal(scale=9.8, size=(200, 3))
    cond = Conditions(t_s=np.linspace(0, 600, 200), temp_c=np.linspace(20, 30, 200))
    y = accel.forward(f, p, cond)
    np.testing.assert_allclose(accel.inverse(y, p, cond), f, atol=1e-9)


def test_p1_parametrisation_round_trip():
    rng = np.random.default_rng(2)
    p = _accel_params(rng)
    B, M = accel.forward_to_p1(p)
    V = accel.forward(rng.normal(size=(5, 3)), p)
    A = B + V @ M.T  # source 000: A = B + M V
    np.testing.assert_allclose(A, accel.inverse(V, p), atol=1e-12)
    q = accel.p1_to_forward(B, M)
    np.testing.assert_allclose(q["K"], p["K"], atol=1e-12)
    np.testing.assert_allclose(q["b"], p["b"], atol=1e-12)


def test_p2_gain_and_quadratic_match_source_form():
    # N = K [f + D f∘f] + b with K = S Φ (source 001), one axis worked by hand.
    p = {
        "S": np.array([1.29, 1.21, 1.26]),
        "b": np.array([0.213, 0.256, 0.516]),
        "D": np.array([5.7e-5, 3.1e-5, 4.5e-5]),
    }
    y = accel.forward(np.array([[0.0, 0.0, -1.0]]), p)
    assert y[0, 2] == pytest.approx(1.26 * (-1.0 + 4.5e-5) + 0.516, abs=1e-15)
    p["gamma"] = np.array([1e-3, 0, 0, 0, 0, 0])
    y = accel.forward(np.array([[0.0, 2.0, 0.0]]), p)
    assert y[0, 0] == pytest.approx(1.29 * 1e-3 * (2.0 + 4 * 3.1e-5) + 0.213, abs=1e-15)


def test_effect_needs_its_condition():
    p = {"K": np.eye(3), "b": np.zeros(3), "bT": np.ones(3)}
    with pytest.raises(ValueError, match="temperature"):
        accel.forward(np.zeros((2, 3)), p)


def test_unknown_effect_is_named():
    with pytest.raises(KeyError, match="known"):
        accel.effect_blocks("warp_drive", 1.0, np.random.default_rng(0), {"K": np.eye(3), "b": np.zeros(3)})


def test_gyro_forward_inverse_and_g_sensitivity():
    rng = np.random.default_rng(4)
    p = {"eps": np.array([1e-3, -2e-3, 5e-4]), "K": np.eye(3) * 1.01, "G": 1e-4 * rng.normal(size=(3, 3))}
    f = rng.normal(scale=9.8, size=(10, 3))
    w = rng.normal(scale=0.1, size=(10, 3))
    cond = Conditions(f_mps2=f)
    y = gyro.forward(w, p, cond)
    np.testing.assert_allclose(gyro.inverse(y, p, cond), w, atol=1e-14)


def test_mag_forward_inverse_and_hard_iron_step():
    rng = np.random.default_rng(5)
    W = 1000 * (np.eye(3) + np.triu(0.05 * rng.normal(size=(3, 3))))
    p = {
        "W": W,
        "h": np.array([3.0, -4.0, 1.0]),
        "dh": np.array([1.0, 0.0, 0.0]),
        "t_on_s": np.array(5.0),
        "rho": np.array([0.01, -0.02, 0.005]),
    }
    m = rng.normal(scale=30000, size=(10, 3))
    cond = Conditions(t_s=np.arange(10.0))
    y = mag.forward(m, p, cond)
    np.testing.assert_allclose(mag.inverse(y, p, cond), m, atol=1e-7)
    # the step is on from t_on_s: the raw offset differs by dh exactly there
    y0 = mag.forward(np.zeros((10, 3)), p, cond)
    np.testing.assert_allclose(y0[5:] - y0[:5].mean(axis=0), np.tile([1.0, 0, 0], (5, 1)), atol=1e-12)


def test_ldv_angles_round_trip_and_source_equation():
    dK = np.array([0.01, -0.02, 0.005])
    a, b = np.array([60.0, 120.0, 90.0]), np.array([90.0, 90.0, 60.0])
    c = np.degrees(np.arccos(np.sqrt(1 - np.cos(np.radians(a)) ** 2 - np.cos(np.radians(b)) ** 2)))
    X = ldv.X_from_angles(dK, a, b, c)
    back = ldv.angles_from_X(X)
    np.testing.assert_allclose(back["dK"], dK, atol=1e-12)
    np.testing.assert_allclose(back["alpha_deg"], a, atol=1e-9)
    v = np.array([[10.0, 1.0, -0.5]])
    y = ldv.forward(v, {"X": X})
    # V_L = (1 + δK)(Vx cos α + Vy cos β + Vz cos γ), beam 1 by hand
    by_hand = 1.01 * (
        10 * math.cos(math.radians(60)) + 1 * math.cos(math.radians(90)) - 0.5 * math.cos(math.radians(c[0]))
    )
    assert y[0, 0] == pytest.approx(by_hand, abs=1e-12)


def test_ldv_delay_and_lever_arm():
    t = np.arange(0, 10, 0.01)
    v = np.column_stack([t, np.zeros_like(t), np.zeros_like(t)])  # ramp in x
    X = np.eye(3)
    y = ldv.forward(v, {"X": X, "tau_s": np.array(0.5)}, Conditions(t_s=t))
    assert y[600, 0] == pytest.approx(t[600] - 0.5, abs=1e-9)
    w = np.tile([0.0, 0.0, 0.2], (len(t), 1))
    y = ldv.forward(v, {"X": X, "r": np.array([1.0, 0.0, 0.0])}, Conditions(omega_body_rad_s=w))
    assert y[0, 1] == pytest.approx(0.2, abs=1e-12)  # ω × r = (0, 0.2, 0)
