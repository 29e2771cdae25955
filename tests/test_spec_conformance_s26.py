"""Conformance with /work/shared/spec, tested from outside: captures written by
``tests/spec_captures_s26.py`` from the spec's words and equations alone (not the station's
simulator or writer), run through the real CLI (``station calibrate|diagnose FILE --json``).

Each valid capture must be accepted and give back the simulated truth within the reported
1-σ uncertainty (5σ, plus a floor far below any noise for the noise-free cases); each invalid
one must be refused in one line naming file and line, exit 2, nothing on stdout.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import tests.spec_captures_s26 as G
from tests.station_run import assert_one_line_refusal, run_station

K_SIGMA = 5.0  # a 5σ miss in one of ~20 parameters is a real mismatch, not bad luck (seeded anyway)


def _calibrate(path) -> dict:
    res = run_station("calibrate", path, "--json")
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def _within(label, est, unc, true, floor=0.0, k=K_SIGMA):
    est, unc, true = (np.asarray(a, float) for a in (est, unc, true))
    assert est.shape == true.shape == unc.shape, label
    miss = np.abs(est - true) > k * unc + floor
    assert not miss.any(), f"{label}: est {est[miss]} true {true[miss]} σ {unc[miss]}"


def _common(j: dict, procedure: str, device: str) -> None:
    """calibrate.md: the fields every result has, their types, and `uncertainty` with the
    shape of every numeric parameter."""
    assert j["procedure"] == procedure and j["device"] == device
    assert isinstance(j["model"], str) and isinstance(j["residual_rms"], float)
    assert isinstance(j["n_positions"], int) and isinstance(j["warnings"], list)

    def same_shape(p, u, where):
        if isinstance(p, dict):
            assert isinstance(u, dict), where
            for k in p:
                if not isinstance(p[k], str):
                    same_shape(p[k], u[k], f"{where}.{k}")
        elif isinstance(p, list):
            assert isinstance(u, list) and len(u) == len(p), where
            for i, (a, b) in enumerate(zip(p, u)):
                same_shape(a, b, f"{where}[{i}]")

    for k, v in j["params"].items():
        if not isinstance(v, str) and k != "reference":  # compass: the IGRF reference is given, not fitted
            same_shape(v, j["uncertainty"][k], k)


# ---------------------------------------------------------------------------- P1


def _p1_table(rng, *, noise_v, fmt="{:.9g}", **render):
    V = G.p1_volts(9.8, G.p1_directions(), rng, noise_v)
    meta = [("procedure", "accel-tabletop"), ("device", "S26-P1"), ("accel_unit", "V"), ("g_mps2", "9.8")]
    return G.render(meta, ["position", "ax", "ay", "az"], [[i + 1, *v] for i, v in enumerate(V)], fmt=fmt, **render)


def test_p1_noise_free_table_at_full_precision_is_calibrated(tmp_path):
    """A simulator that writes exact averages with Python's repr (17 digits) left norm residuals
    of ~1e-15 m/s²; estimated from them, the norm noise outweighed the labelled directions'
    placement σ by 1e14 and the station refused a perfect capture: "the positions cannot
    determine M[0][1], ... (condition number inf)". Now the estimate has a floor (0.1 µg) and
    the 12 coefficients come back exactly, with a warning that says so."""
    path = tmp_path / "exact.csv"
    path.write_bytes(_p1_table(np.random.default_rng(1), noise_v=0.0, fmt="{:.17g}"))
    j = _calibrate(path)
    _common(j, "accel-tabletop", "S26-P1")
    assert j["gauge"] == "table"
    _within("B", j["params"]["B"], j["uncertainty"]["B"], G.P1_B)
    _within("M", j["params"]["M"], j["uncertainty"]["M"], G.P1_M)
    # exact data, exact answer but for the table gauge's rotation debias (the diagonal scaled by
    # 1 + the placement-rotation variance, ~1e-5 here: solvers.tabletop.debias_rotation)
    np.testing.assert_allclose(j["params"]["B"], G.P1_B, rtol=3e-5, atol=1e-9)
    np.testing.assert_allclose(j["params"]["M"], G.P1_M, rtol=3e-5, atol=1e-9)
    assert any("noise-free" in w for w in j["warnings"]), j["warnings"]
    # and no second warning contradicting it ("estimated from the residuals (9.8e-07 m/s^2)")
    assert not any("estimated from the residuals" in w for w in j["warnings"]), j["warnings"]


@pytest.mark.parametrize(
    ("unit", "raw_per_volt"),
    [("V", 1.0), ("mV", 1e3), ("counts", 4096.0)],
)
def test_p1_table_every_variant_recovers_the_truth(tmp_path, unit, raw_per_volt):
    """Table of averages with n, <col>_std and temp_c, columns shuffled, CRLF, BOM, an unknown
    metadata key whose value holds a colon, g from latitude and altitude (no g_mps2)."""
    rng = np.random.default_rng(2)
    g = G.normal_gravity_mps2(39.98, 52.0)
    V = G.p1_volts(g, G.p1_directions(), rng, 1e-5)
    rows = [
        [i + 1, *(v * raw_per_volt), 3000, *(np.full(3, 1e-5 * np.sqrt(3000) * raw_per_volt)), 24.5]
        for i, v in enumerate(V)
    ]
    cols = ["position", "ax", "ay", "az", "n", "ax_std", "ay_std", "az_std", "temp_c"]
    meta = [
        ("procedure", "accel-tabletop"),
        ("device", "S26-P1"),
        ("accel_unit", unit),
        ("latitude_deg", "39.98"),
        ("longitude_deg", "116.35"),
        ("altitude_m", "52"),
        ("date", "2026-11-21T10:00:00Z"),
        ("operator_note", "bench 3: left table"),
    ]
    order = ["ax_std", "n", "temp_c", "position", "az", "ay_std", "ay", "az_std", "ax"]
    path = tmp_path / f"p1_{unit}.csv"
    path.write_bytes(G.render(meta, cols, rows, order=order, crlf=True, bom=True))
    j = _calibrate(path)
    _common(j, "accel-tabletop", "S26-P1")
    assert j["g_mps2"] == pytest.approx(g, abs=1e-5)
    assert j["n_positions"] == 12 and j["gauge"] == "table"
    _within("B", j["params"]["B"], j["uncertainty"]["B"], G.P1_B)
    _within("M", j["params"]["M"], j["uncertainty"]["M"], G.P1_M / raw_per_volt)


def test_p1_time_series_without_position_column(tmp_path):
    """No `position`: the holds are found by the stillness detector, the rotation the norm cannot
    see is fixed by a stated gauge; what the norm does see (MᵀM, MᵀB) is the truth."""
    rng = np.random.default_rng(3)
    Vm = G.p1_volts(9.8, G.p1_directions(), rng, 0.0)
    rows, t = [], 0.0
    for i, v in enumerate(Vm):
        nxt = Vm[(i + 1) % len(Vm)]
        for x in v + rng.normal(0, 2e-3, (300, 3)):
            rows.append([round(t, 4), *x])
            t += 0.01
        for a in np.linspace(0, 1, 150, endpoint=False):  # turned by hand to the next hold
            rows.append([round(t, 4), *((1 - a) * v + a * nxt + rng.normal(0, 0.3, 3))])
            t += 0.01
    meta = [("procedure", "accel-tabletop"), ("device", "S26-P1"), ("accel_unit", "V"), ("g_mps2", "9.8")]
    path = tmp_path / "nopos.csv"
    path.write_bytes(G.render(meta, ["t", "ax", "ay", "az"], rows, order=["az", "t", "ax", "ay"]))
    j = _calibrate(path)
    _common(j, "accel-tabletop", "S26-P1")
    assert j["n_positions"] == 12 and "gauge" in j
    # the truth in the upper-triangular gauge: M_true = Q U (QR, diag(U) > 0), M = U, B = Qᵀ B_true
    Q, U = np.linalg.qr(G.P1_M)
    sign = np.sign(np.diag(U))
    Q, U = Q * sign, sign[:, None] * U
    _within("B", j["params"]["B"], j["uncertainty"]["B"], Q.T @ G.P1_B)
    _within("M", j["params"]["M"], j["uncertainty"]["M"], U, floor=1e-12)


def test_p1_back_to_back_short_holds_are_not_named_moved(tmp_path, capsys):
    """A simulator that writes 3 s holds back to back (the label changes between two rows, t
    even, white noise only): the stillness detector's windows that straddle each change see two
    attitudes, and `diagnose` named every one of the 12 positions `moved` (26 % of samples)."""
    from station.cli import main

    rng = np.random.default_rng(4)
    rows, t = [], 0.0
    for i, v in enumerate(G.p1_volts(9.8, G.p1_directions(), rng, 0.0)):
        for x in v + rng.normal(0, 2e-3, (300, 3)):
            rows.append([round(t, 4), i + 1, *x])
            t += 0.01
    meta = [("procedure", "accel-tabletop"), ("device", "S26-P1"), ("accel_unit", "V"), ("g_mps2", "9.8")]
    path = tmp_path / "holds.csv"
    path.write_bytes(G.render(meta, ["t", "position", "ax", "ay", "az"], rows))
    assert main(["diagnose", str(path), "--json"]) == 0
    j = json.loads(capsys.readouterr().out)
    assert not [q for q in j["quality"] if q["kind"] == "moved"], j["quality"]
    assert j["verdict"] == []


# ---------------------------------------------------------------------------- P2


def test_p2_table_in_volts_crlf_bom_shuffled(tmp_path):
    rng = np.random.default_rng(5)
    rows = [
        [i + 1, w, *(G.p2_output(f) + rng.normal(0, 1e-5, 3))]
        for i, (w, f) in enumerate(G.p2_forces(9.8, 1.0, (2 * np.pi, 4 * np.pi, 6 * np.pi), 20, rng))
    ]
    meta = [
        ("procedure", "accel-centrifuge"),
        ("device", "S26-P2"),
        ("accel_unit", "V"),
        ("radius_m", "1"),
        ("g_mps2", "9.8"),
    ]
    path = tmp_path / "p2.csv"
    cols = ["position", "speed_rad_s", "ax", "ay", "az"]
    path.write_bytes(
        G.render(meta, cols, rows, order=["az", "speed_rad_s", "ax", "position", "ay"], crlf=True, bom=True)
    )
    j = _calibrate(path)
    _common(j, "accel-centrifuge", "S26-P2")
    for name, true in (("S", G.P2_S), ("b", G.P2_B), ("D", G.P2_D)):
        _within(name, j["params"][name], j["uncertainty"][name], true)
    assert len(j["params"].get("gamma", [0] * 6)) == 6


# ---------------------------------------------------------------------------- P3


@pytest.mark.parametrize("unit", ["gauss", "µT", "nT"])
def test_p3_time_series_hard_and_soft_iron_and_igrf_reference(tmp_path, unit):
    """W upper triangular (mag_unit → nT) and h (mag_unit) come back; the reference is IGRF at
    the place and date (ppigrf, independently of the station), N/E/D, total, dip, declination."""
    rng = np.random.default_rng(6)
    F = G.igrf_ned_nT(39.98, 116.35, 52.0, "2026-11-21")
    W, h, mags, accs = G.p3_raw(F, G.random_rotations(30, rng), unit, 9.8)
    k = G.NT_PER[unit]
    rows, t = [], 0.0
    for i, (m, a) in enumerate(zip(mags, accs)):
        for _ in range(20):
            rows.append([round(t, 3), i + 1, *(m + rng.normal(0, 20.0 / k, 3)), *(a / 9.8), 0.0, 0.0])
            t += 0.01
    meta = [
        ("procedure", "compass"),
        ("device", "S26-P3"),
        ("mag_unit", unit),
        ("accel_unit", "g"),
        ("gyro_unit", "deg/s"),
        ("latitude_deg", "39.98"),
        ("longitude_deg", "116.35"),
        ("altitude_m", "52"),
        ("date", "2026-11-21"),
    ]
    cols = ["t", "position", "mx", "my", "mz", "ax", "ay", "az", "gx", "gy"]
    path = tmp_path / "p3.csv"
    order = ["my", "t", "gy", "ax", "mz", "position", "az", "gx", "ay", "mx"]
    path.write_bytes(G.render(meta, cols, rows, order=order, crlf=True, bom=True))
    j = _calibrate(path)
    _common(j, "compass", "S26-P3")
    p = j["params"]
    _within("hard_iron", p["hard_iron"], j["uncertainty"]["hard_iron"], h)
    _within("soft_iron", p["soft_iron"], j["uncertainty"]["soft_iron"], W)
    assert np.all(np.tril(np.array(p["soft_iron"]), -1) == 0)
    ref = p["reference"]
    np.testing.assert_allclose([ref["north_nT"], ref["east_nT"], ref["down_nT"]], F, atol=30)  # IGRF versions, altitude
    assert ref["total_nT"] == pytest.approx(np.linalg.norm(F), abs=30)
    assert ref["declination_deg"] == pytest.approx(np.degrees(np.arctan2(F[1], F[0])), abs=0.1)
    assert ref["inclination_deg"] == pytest.approx(np.degrees(np.arctan2(F[2], np.hypot(F[0], F[1]))), abs=0.1)


# ---------------------------------------------------------------------------- P4


@pytest.mark.parametrize(("unit", "rad_per_unit"), [("deg/h", np.pi / 180 / 3600), ("dps", np.pi / 180)])
def test_p4_mode_a_reference_imu(tmp_path, unit, rad_per_unit):
    rng = np.random.default_rng(7)
    t = np.arange(18000) / 100.0
    Om = np.column_stack([0.2 * np.sin(0.3 * t), 0.1 * np.cos(0.2 * t), 0.05 * np.sin(0.5 * t + 1)])
    om = Om + G.P4_EPS + rng.normal(0, 2e-3, Om.shape)
    rows = [[round(float(t[i]), 4), *(om[i] / rad_per_unit), *Om[i], 25.0] for i in range(len(t))]
    meta = [("procedure", "gyro-drift"), ("device", "S26-P4"), ("gyro_unit", unit), ("gyro_mode", "reference")]
    cols = ["t", "gx", "gy", "gz", "ref_gx", "ref_gy", "ref_gz", "temp_c"]
    path = tmp_path / "p4a.csv"
    order = ["ref_gz", "gz", "t", "temp_c", "ref_gx", "gx", "gy", "ref_gy"]
    path.write_bytes(G.render(meta, cols, rows, order=order, crlf=True))
    j = _calibrate(path)
    _common(j, "gyro-drift", "S26-P4")
    assert j["params"]["mode"] == "reference"
    _within("drift", j["params"]["drift"], j["uncertainty"]["drift"], G.P4_EPS)


@pytest.mark.parametrize(("heading_deg", "pitch_deg", "roll_deg"), [(None, 3.0, 2.0), (90.0, 0.0, 0.0)])
def test_p4_mode_b_static_earth_rate_removed(tmp_path, heading_deg, pitch_deg, roll_deg):
    """Body x forward, y up, z right; nav north-up-east (procedures.md P4). Positive pitch: nose
    up; positive roll: right side down."""
    rng = np.random.default_rng(8)
    wE, C_nb = G.p4_earth_rate_body(39.98, heading_deg or 0.0, pitch_deg, roll_deg)
    f_b = C_nb @ np.array([0.0, 9.8, 0.0])
    n = 18000
    om = wE + G.P4_EPS + rng.normal(0, 2e-3, (n, 3))
    rows = [[round(i / 100.0, 4), *(f_b / 9.8 + rng.normal(0, 0.01, 3)), *om[i]] for i in range(n)]
    meta = [("procedure", "gyro-drift"), ("device", "S26-P4"), ("gyro_unit", "rad/s"), ("accel_unit", "g")]
    meta += [("g_mps2", "9.8"), ("gyro_mode", "static"), ("latitude_deg", "39.98")]
    meta += [("heading_deg", f"{heading_deg}")] if heading_deg is not None else []
    path = tmp_path / "p4b.csv"
    path.write_bytes(G.render(meta, ["t", "ax", "ay", "az", "gx", "gy", "gz"], rows))
    j = _calibrate(path)
    _common(j, "gyro-drift", "S26-P4")
    p = j["params"]
    assert p["mode"] == "static"
    _within("drift", p["drift"], j["uncertainty"]["drift"], G.P4_EPS)
    np.testing.assert_allclose(p["earth_rate_body"], wE, atol=2e-7)
    assert p["pitch_deg"] == pytest.approx(pitch_deg, abs=0.05)
    assert p["roll_deg"] == pytest.approx(roll_deg, abs=0.05)


# ---------------------------------------------------------------------------- P5


def _p5_check(j, k=K_SIGMA):
    _common(j, "ldv", "S26-P5")
    ang = G.p5_true_angles_deg()
    assert isinstance(j["params"]["condition_number"], float)
    for b in range(3):
        p, u = j["params"][f"beam{b + 1}"], j["uncertainty"][f"beam{b + 1}"]
        _within(f"beam{b + 1} dK", p["dK"], u["dK"], G.P5_DK[b], k=k)
        names = ("alpha_deg", "beta_deg", "gamma_deg")
        _within(f"beam{b + 1} angles", [p[n] for n in names], [u[n] for n in names], ang[b], k=k)
        assert p["sigma_mps"] >= 0


def test_p5_navigation_frame_reference_crlf_bom_shuffled(tmp_path):
    rng = np.random.default_rng(9)
    vb = G.p5_epochs(200, rng)
    vl = G.p5_beams(vb, rng, 0.01)
    rows = []
    for i in range(len(vb)):
        ro, pi, ya = rng.uniform(-10, 10), rng.uniform(-8, 8), rng.uniform(-180, 180)
        rows.append([round(i * 0.5, 3), *vl[i], *(G.c_b_n(ro, pi, ya) @ vb[i]), ro, pi, ya, 0.0, 0.0, 0.0])
    cols = ["t", "vl1", "vl2", "vl3", "vn", "ve", "vd", "roll_deg", "pitch_deg", "yaw_deg", "wx", "wy", "wz"]
    order = ["yaw_deg", "vl3", "wz", "t", "ve", "vl1", "roll_deg", "wx", "vd", "vl2", "pitch_deg", "wy", "vn"]
    path = tmp_path / "p5.csv"
    path.write_bytes(
        G.render([("procedure", "ldv"), ("device", "S26-P5")], cols, rows, order=order, crlf=True, bom=True)
    )
    _p5_check(_calibrate(path))


def _p5_table(tmp_path, n, seed=10):
    rng = np.random.default_rng(seed)
    vb = G.p5_epochs(n, rng)
    vl = G.p5_beams(vb, rng, 0.005)
    rows = [[i + 1, *vl[i], *vb[i]] for i in range(n)]
    path = tmp_path / f"p5_{n}.csv"
    path.write_bytes(
        G.render(
            [("procedure", "ldv"), ("device", "S26-P5")], ["position", "vl1", "vl2", "vl3", "vx", "vy", "vz"], rows
        )
    )
    return path


@pytest.mark.parametrize("n", [4, 6, 9])
def test_p5_a_few_averaged_epochs_in_motion_are_calibrated(tmp_path, n):
    """P5 records 'at n >= 3 times in different motion states'. A table of 4 to 9 such epochs,
    every one at 2-20 m/s, was refused: "the vehicle hardly moved: 4 of 4 epochs at a reference
    speed of 0.5 m/s or more". Only a record with parked epochs is refused as parked now.
    σ from n − 3 residual degrees of freedom: the truth is within Student's t (two-sided 1e-3),
    not 5σ (with 1 degree of freedom, 5σ is missed 13 % of the time)."""
    from scipy import stats

    j = _calibrate(_p5_table(tmp_path, n))
    _p5_check(j, k=max(K_SIGMA, float(stats.t.isf(0.5e-3, n - 3))))
    assert any(f"{n - 3} degree" in w for w in j["warnings"]), j["warnings"]  # and says how little σ rests on


def test_p5_three_epochs_are_refused_for_the_missing_uncertainty(tmp_path):
    """Three epochs determine X exactly and leave no residual for the 1-σ the contract requires:
    refused, and the line says that (not that the vehicle hardly moved)."""
    res = run_station("calibrate", _p5_table(tmp_path, 3), "--json")
    assert_one_line_refusal(res, "p5_3.csv", "at least 4 epochs")
    assert "hardly moved" not in res.stderr


# ---------------------------------------------------------------------------- bad input


def _bad_rows(rng):
    V = G.p1_volts(9.8, G.p1_directions(), rng, 1e-5)
    return [f"{i + 1},{v[0]:.7f},{v[1]:.7f},{v[2]:.7f}" for i, v in enumerate(V)]


_META = "# station-capture: 1\n# procedure: accel-tabletop\n# device: BAD\n# accel_unit: V\n# g_mps2: 9.8\n"


@pytest.mark.parametrize(
    ("name", "edit", "line", "needle"),
    [
        ("abc_crlf_bom", lambda m, h, r: (m, h, r[:4] + ["5,abc,1.0,2.0"] + r[5:], "crlf+bom"), 11, "'abc'"),
        ("nan", lambda m, h, r: (m, h, r[:3] + ["4,nan,1,2"] + r[4:], ""), 10, "'nan'"),
        ("short_row", lambda m, h, r: (m, h, r[:6] + ["7,1.0,2.0"] + r[7:], ""), 13, "too few fields"),
        ("dup_column", lambda m, h, r: (m, "position,ax,ay,ax", r, ""), 6, "duplicate column"),
        ("bad_unit", lambda m, h, r: (m.replace("accel_unit: V", "accel_unit: rad/s"), h, r, ""), 4, "accel_unit"),
        ("first_line", lambda m, h, r: (m.replace("# station-capture: 1\n", ""), h, r, ""), 1, "station-capture"),
        (
            "t_backwards",
            lambda m, h, r: (m, "t," + h, [f"{(i if i != 5 else 2)},{x}" for i, x in enumerate(r)], ""),
            12,
            "backwards",
        ),
        ("cr_only", lambda m, h, r: (m, h, r, "cr"), 1, "carriage return"),
    ],
)
def test_bad_capture_one_line_with_file_and_line(tmp_path, name, edit, line, needle):
    meta, header, rows, mode = edit(_META, "position,ax,ay,az", _bad_rows(np.random.default_rng(11)))
    text = meta + "\n".join([header, *rows]) + "\n"
    if mode == "crlf+bom":
        data = b"\xef\xbb\xbf" + text.replace("\n", "\r\n").encode()
    elif mode == "cr":
        data = text.replace("\n", "\r").encode()
    else:
        data = text.encode()
    path = tmp_path / f"{name}.csv"
    path.write_bytes(data)
    for cmd in ("calibrate", "diagnose"):
        assert_one_line_refusal(run_station(cmd, path, "--json"), f"{name}.csv:{line}: ", needle)


def test_p3_place_without_date_names_the_missing_date(tmp_path):
    """IGRF needs place and date. With latitude and longitude but no `date` the reference is null
    (every key present) and the warnings said "no declination without a place", which the
    capture has: they name the date now."""
    rng = np.random.default_rng(12)
    F = G.igrf_ned_nT(39.98, 116.35, 52.0, "2026-11-21")
    W, h, mags, accs = G.p3_raw(F, G.random_rotations(30, rng), "uT", 9.8)
    rows = [[i + 1, *(m + rng.normal(0, 0.02, 3)), *(a / 9.8)] for i, (m, a) in enumerate(zip(mags, accs))]
    meta = [("procedure", "compass"), ("device", "S26-P3"), ("mag_unit", "uT"), ("accel_unit", "g")]
    meta += [("latitude_deg", "39.98"), ("longitude_deg", "116.35")]
    path = tmp_path / "nodate.csv"
    path.write_bytes(G.render(meta, ["position", "mx", "my", "mz", "ax", "ay", "az"], rows))
    j = _calibrate(path)
    _common(j, "compass", "S26-P3")
    ref = j["params"]["reference"]
    assert set(ref) >= {"north_nT", "east_nT", "down_nT", "total_nT", "inclination_deg", "declination_deg"}
    assert all(v is None for v in ref.values())
    _within("hard_iron", j["params"]["hard_iron"], j["uncertainty"]["hard_iron"], h)
    decl = [w for w in j["warnings"] if "declination" in w]
    assert decl and all("date" in w and "without a place" not in w for w in decl), j["warnings"]


# ---------------------------------------------------------------------------- found, not fixed


def _diagnose_json(path) -> dict:
    res = run_station("diagnose", path, "--json")
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


@pytest.mark.parametrize("procedure", ["accel-tabletop", "accel-centrifuge"])
def test_noise_free_tables_have_verdict_none(tmp_path, procedure):
    """diagnose.md: 'say nothing where there is nothing'. On exact tables the scale-free F tests
    took the noise from the baseline's rounding (P1: 3e-7 m/s², P2: 5e-15 g) and named a quadratic
    and a scale asymmetry (P1), a cubic term (P2). A residual below the floor of any real noise
    (0.1 µg) leaves nothing to explain; each candidate says so."""
    rng = np.random.default_rng(13)
    if procedure == "accel-tabletop":
        data = _p1_table(rng, noise_v=0.0, fmt="{:.17g}")
    else:
        fs = G.p2_forces(9.8, 1.0, (2 * np.pi, 4 * np.pi, 6 * np.pi), 20, rng)
        meta = [
            ("procedure", procedure),
            ("device", "S26-P2"),
            ("accel_unit", "g"),
            ("radius_m", "1"),
            ("g_mps2", "9.8"),
        ]
        rows = [[i + 1, w, *G.p2_output(f)] for i, (w, f) in enumerate(fs)]
        data = G.render(meta, ["position", "speed_rad_s", "ax", "ay", "az"], rows, fmt="{:.17g}")
    path = tmp_path / "exact.csv"
    path.write_bytes(data)
    res = _diagnose_json(path)
    assert res["verdict"] == []
    assert any("noise-free" in (c.get("reason") or "") for c in res["candidates"]), res["candidates"]


def test_a_noise_free_table_with_an_effect_names_it_alone(tmp_path):
    """The floor takes nothing from an exact table with an effect in it: a second-order term per
    axis (diagnose.md `quadratic`, f + D f²) on 18 exact positions is named, D recovered to
    1e-12, and nothing is sought beside it in the exact residual it leaves."""
    D = np.array([2e-3, -1e-3, 1.5e-3])  # 1/(m/s²)
    Minv = np.linalg.inv(G.P1_M)
    V = [Minv @ (9.8 * u + D * (9.8 * u) ** 2 - G.P1_B) for u in G.p1_directions(6)]
    meta = [("procedure", "accel-tabletop"), ("device", "S26-P1"), ("accel_unit", "V"), ("g_mps2", "9.8")]
    path = tmp_path / "exact_quadratic.csv"
    path.write_bytes(
        G.render(meta, ["position", "ax", "ay", "az"], [[i + 1, *v] for i, v in enumerate(V)], fmt="{:.17g}")
    )
    res = _diagnose_json(path)
    assert res["verdict"] == ["quadratic"], res["verdict"]
    np.testing.assert_allclose(res["effects"][0]["params"]["D"], D, rtol=1e-9, atol=1e-12)


def _compass_table(path, seed, *, rotate_deg=0.0, field_scale=1.0, dip_deg=0.0, std=False):
    """A compass table of averages (30 positions, 20 nT per mean, 0.2 mg) written from the spec;
    ``rotate_deg``: the accelerometer turned against the magnetometer about a fixed axis;
    ``field_scale``, ``dip_deg``: the local field's magnitude and inclination against IGRF's."""
    rng = np.random.default_rng(seed)
    F = np.asarray(G.igrf_ned_nT(39.98, 116.35, 52.0, "2026-11-21"), float)
    hor = float(np.hypot(F[0], F[1]))
    inc = math.atan2(F[2], hor) + math.radians(dip_deg)
    tot = float(np.linalg.norm(F)) * field_scale
    F = np.array([F[0] / hor * tot * math.cos(inc), F[1] / hor * tot * math.cos(inc), tot * math.sin(inc)])
    _, _, mags, accs = G.p3_raw(F, G.random_rotations(30, rng), "uT", 9.8)
    ax = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    K = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
    th = math.radians(rotate_deg)
    R = np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K
    rows = [
        [i + 1, *(m + rng.normal(0, 0.02, 3)), *((R @ a) / 9.8 + rng.normal(0, 2e-4, 3))]
        for i, (m, a) in enumerate(zip(mags, accs))
    ]
    cols = ["position", "mx", "my", "mz", "ax", "ay", "az"]
    if std:  # 0.2 uT per sample over 100 samples: 20 nT per mean
        rows = [r + [0.2, 0.2, 0.2, 100] for r in rows]
        cols += ["mx_std", "my_std", "mz_std", "n"]
    meta = [("procedure", "compass"), ("device", "S26-P3"), ("mag_unit", "uT"), ("accel_unit", "g")]
    meta += [("latitude_deg", "39.98"), ("longitude_deg", "116.35"), ("altitude_m", "52"), ("date", "2026-11-21")]
    path.write_bytes(G.render(meta, cols, rows))
    return path


@pytest.mark.parametrize("std", [False, True])
def test_compass_table_of_averages_is_diagnosed(tmp_path, std):
    """A compass table of averages (capture-format: one row per position, no `t`) was refused by
    diagnose ("compass diagnosis needs a time series", exit 2) though calibrate takes it. The dip
    and the field's magnitude need no time: a null table names nothing, and what needs time says
    so."""
    path = _compass_table(tmp_path / "p3_table.csv", 14, std=std)
    assert _calibrate(path)["procedure"] == "compass"  # calibrate takes it
    res = _diagnose_json(path)
    assert res["verdict"] == [], res["verdict"]
    reasons = {c["name"]: c.get("reason") or "" for c in res["candidates"]}
    assert "no time" in reasons["time_drift"] and "no time" in reasons["time_varying_hard_iron"], reasons
    assert res["candidates"][[c["name"] for c in res["candidates"]].index("mag_accel_misalignment")]["delta_bic"]


def test_a_compass_table_names_a_rotation_between_the_sensors_and_a_field_anomaly(tmp_path):
    """The same tables with the accelerometer turned 2° against the magnetometer, and with a local
    field 6 % stronger and 1.5° steeper than IGRF's: each is named alone, the rotation's size and
    the dip's change recovered (the magnitude a common scale of W: diagnose.md)."""
    res = _diagnose_json(_compass_table(tmp_path / "rot.csv", 15, rotate_deg=2.0))
    assert res["verdict"] == ["mag_accel_misalignment"], res["verdict"]
    rho = np.asarray(res["effects"][0]["params"]["rho"])
    assert abs(math.degrees(np.linalg.norm(rho)) - 2.0) < 0.2, rho
    res = _diagnose_json(_compass_table(tmp_path / "field.csv", 21, field_scale=1.06, dip_deg=1.5))
    assert res["verdict"] == ["field_anomaly"], res["verdict"]
    inc = math.atan2(*np.asarray(G.igrf_ned_nT(39.98, 116.35, 52.0, "2026-11-21"), float)[[2, 0]])
    expected = -math.cos(inc) * math.radians(1.5)  # the change of −sin I
    assert abs(res["effects"][0]["params"]["dc_dip"] - expected) < 0.2 * abs(expected), res["effects"][0]["params"]
