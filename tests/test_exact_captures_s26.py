"""Time series from a simple independent simulator with its noise switched off (s26f): what
`station diagnose FILE --json` makes of exact data. Captures are written here from
/work/shared/spec alone (capture-format.md, procedures.md), with the physics of
``tests/spec_captures_s26.py``; the station's own simulator is not used.

diagnose.md: "say nothing where there is nothing" (verdict [] on exact data) and name a
hidden effect alone when exact data hold one.
"""

from __future__ import annotations

import json

import numpy as np

import tests.spec_captures_s26 as G
from tests.station_run import run_station


def _diagnose(path) -> dict:
    res = run_station("diagnose", path, "--json")
    assert res.returncode == 0, res.stderr
    assert "NaN" not in res.stdout and "Infinity" not in res.stdout
    assert "Warning" not in res.stderr, res.stderr  # no numpy division warnings
    return json.loads(res.stdout)


def _write(path, meta, cols, rows, fmt="{:.17g}"):
    path.write_bytes(G.render(meta, cols, rows, fmt=fmt))
    return path


# ---------------------------------------------------------------------------- P1


def _p1_holds(hold: int = 300, D=None) -> tuple[list, list, list]:
    """18 labelled holds (the 12 of P1 and 6 more), each ``hold`` rows at 100 Hz of the exact
    output V = M⁻¹ (f + D f² − B), f = g u, temperature exactly constant."""
    Minv = np.linalg.inv(G.P1_M)
    D = np.zeros(3) if D is None else np.asarray(D, float)
    rows, t = [], 0.0
    for i, u in enumerate(G.p1_directions(6)):
        f = 9.8 * u
        v = Minv @ (f + D * f * f - G.P1_B)
        for _ in range(hold):
            rows.append([t, i + 1, *v, 25.0])
            t += 0.01
    meta = [("procedure", "accel-tabletop"), ("device", "S26F-P1"), ("accel_unit", "V"), ("g_mps2", "9.8")]
    return meta, ["t", "position", "ax", "ay", "az", "temp_c"], rows


def test_p1_exact_time_series_has_verdict_none(tmp_path):
    """An exact P1 time series (labelled holds, 17 digits): each sub-hold's standard error is
    ~1e-17 m/s², and the norm rows, weighted by it 1e12 times above the direction rows, left the
    baseline fit 2e-5 m/s² from the exact answer, and an effect was named in that (main: verdict
    ['residual:time'] here; ['scale_asymmetry'], A ~ 5e-7, with 1 s holds). The norm rows now have calibrate's noise floor
    (0.1 µg), the baseline reaches the truth and nothing is sought below it."""
    path = _write(tmp_path / "p1_exact.csv", *_p1_holds())
    j = _diagnose(path)
    assert j["verdict"] == [], j["candidates"]
    assert any("noise-free" in (c.get("reason") or "") for c in j["candidates"]), j["candidates"]
    # and no data-quality finding made of the rounding: main (with the floor above) had two
    # "outlier" rows beyond 5σ and "residuals_not_white ... something remains" at 1e-16 m/s²
    assert j["quality"] == [], j["quality"]


def test_p1_exact_time_series_with_a_quadratic_names_it_alone(tmp_path):
    """An exact P1 series with a quadratic term (D = 2e-4, -1e-4, 1.5e-4 per m/s²): the quadratic
    takes the held-out RMS from 2e-3 to 7.7e-7 m/s², yet main's verdict was [] (delta_bic +564):
    the deviance profiles a noise scale per kind of row, and the hold contrasts' residual is
    rounding (<= 9e-16 m/s²) before and after, their ratio arbitrary. A kind the baseline
    leaves below the noise floor now counts at the floor (``engine.row_floor``): the quadratic
    alone, D to 1e-12."""
    path = _write(tmp_path / "p1_quadratic.csv", *_p1_holds(D=[2e-4, -1e-4, 1.5e-4]))
    assert _diagnose(path)["verdict"] == ["quadratic"]


# ---------------------------------------------------------------------------- P2


def test_p2_exact_table_with_elapsed_s_keeps_every_row(tmp_path):
    """P2's 60 exact rows (20 orientations at 2π, 4π, 6π rad/s, R = 1 m) with `elapsed_s` and a
    constant temperature: calibrate's outlier screen measured a spread of 1.3e-15 g and left a
    row 1.4e-14 g off out of the fit as "far beyond the others" (main: n_positions 59, and diagnose
    reported it as an `outlier`). The spread has the 0.1 µg floor now: every row is kept, S, b, D
    come back to 1e-9, and diagnose finds nothing."""
    rng = np.random.default_rng(5)
    fs = G.p2_forces(9.8, 1.0, (2 * np.pi, 4 * np.pi, 6 * np.pi), 20, rng)
    rows = [[i + 1, w, *G.p2_output(f), 60.0 * i, 25.0] for i, (w, f) in enumerate(fs)]
    meta = [("procedure", "accel-centrifuge"), ("device", "S26F-P2"), ("accel_unit", "g")]
    meta += [("radius_m", "1"), ("g_mps2", "9.8")]
    path = _write(
        tmp_path / "p2_exact.csv", meta, ["position", "speed_rad_s", "ax", "ay", "az", "elapsed_s", "temp_c"], rows
    )
    res = run_station("calibrate", path, "--json")
    assert res.returncode == 0, res.stderr
    j = json.loads(res.stdout)
    assert j["n_positions"] == 60, j["warnings"]
    assert not any("disagree" in w for w in j["warnings"]), j["warnings"]
    for name, true in (("S", G.P2_S), ("b", G.P2_B), ("D", G.P2_D)):
        np.testing.assert_allclose(j["params"][name], true, rtol=1e-9, atol=1e-12)
    d = _diagnose(path)
    assert d["verdict"] == [] and d["quality"] == [], (d["verdict"], d["quality"])


# ---------------------------------------------------------------------------- P3


def test_p3_exact_holds_have_verdict_none_and_no_outliers(tmp_path):
    """24 exact holds of a compass (IGRF field at the place and date through W and h, gravity,
    gyro columns exactly 0): diagnose found 9 rows "beyond 5σ" in 1e-8 nT of rounding and said the
    residuals were not noise-like (main). The compass problem has a noise floor now (1e-3 nT)."""
    rng = np.random.default_rng(6)
    F = G.igrf_ned_nT(39.98, 116.35, 52.0, "2026-11-21")
    _, _, mags, accs = G.p3_raw(F, G.random_rotations(24, rng), "uT", 9.8)
    rows, t = [], 0.0
    for i, (m, a) in enumerate(zip(mags, accs)):
        for _ in range(40):
            rows.append([t, i + 1, *m, *(a / 9.8), 0.0, 0.0])
            t += 0.02
    meta = [("procedure", "compass"), ("device", "S26F-P3"), ("mag_unit", "uT"), ("accel_unit", "g")]
    meta += [("gyro_unit", "deg/s"), ("latitude_deg", "39.98"), ("longitude_deg", "116.35")]
    meta += [("altitude_m", "52"), ("date", "2026-11-21")]
    cols = ["t", "position", "mx", "my", "mz", "ax", "ay", "az", "gx", "gy"]
    j = _diagnose(_write(tmp_path / "p3_holds.csv", meta, cols, rows))
    assert j["verdict"] == [] and j["quality"] == [], (j["verdict"], j["quality"])
    assert any("noise-free" in (c.get("reason") or "") for c in j["candidates"]), j["candidates"]


# ---------------------------------------------------------------------------- P4


def _p4_mode_a(n: int = 3000, drift_rad_s2=None) -> tuple[list, list, list]:
    """Mode A at 10 Hz: reference rates Ω(t), the unit ω = Ω + ε exactly (plus a bias linear in
    elapsed time when ``drift_rad_s2`` is given), temperature exactly constant."""
    t = np.arange(n) / 10.0
    Om = np.column_stack([0.2 * np.sin(0.3 * t), 0.1 * np.cos(0.2 * t), 0.05 * np.sin(0.5 * t + 1)])
    om = Om + G.P4_EPS
    if drift_rad_s2 is not None:
        om = om + np.asarray(drift_rad_s2) * t[:, None]
    rows = [[t[i], *om[i], *Om[i], 25.0] for i in range(n)]
    meta = [("procedure", "gyro-drift"), ("device", "S26F-P4"), ("gyro_unit", "rad/s"), ("gyro_mode", "reference")]
    return meta, ["t", "gx", "gy", "gz", "ref_gx", "ref_gy", "ref_gz", "temp_c"], rows


def test_p4_mode_a_exact_has_verdict_none(tmp_path):
    """Exact mode-A data: the unit minus the reference is ε to 1e-17 rad/s, and the F tests, scale
    free, named `residual:time` in that rounding (main). Below the gyro noise floor (1e-9 rad/s,
    under any real gyro's block mean) nothing is sought."""
    j = _diagnose(_write(tmp_path / "p4a_exact.csv", *_p4_mode_a()))
    assert j["verdict"] == [] and j["quality"] == [], (j["effects"], j["quality"])
    assert any("noise-free" in (c.get("reason") or "") for c in j["candidates"]), j["candidates"]


def test_p4_mode_a_exact_with_a_time_drift_names_it_alone(tmp_path):
    """Exact data with one effect (a bias linear in time, 2e-6 rad/s per s): `time_drift` is named,
    its slope recovered, and nothing beside it (main: ['time_drift', 'residual:time'], the second
    found in the exact residual the first leaves)."""
    slope = np.array([2e-6, -1e-6, 1.5e-6])
    j = _diagnose(_write(tmp_path / "p4a_drift.csv", *_p4_mode_a(drift_rad_s2=slope)))
    assert j["verdict"] == ["time_drift"], j["effects"]


# ---------------------------------------------------------------------------- found, not fixed


def test_p4_mode_a_rounded_to_two_decimals_has_verdict_none(tmp_path):
    """Mode A written to 2 decimals (0.01 rad/s, quantisation the only noise): diagnose named
    `residual:time` (periodic, 18.8 s, gain 0.016), the error of rounding a noise-free sinusoid,
    a function of the rate itself: the quantiser's structure, not the gyro's. Rates on a grid have
    at least its noise (step/√12 a sample): below it nothing is sought."""
    j = _diagnose(_write(tmp_path / "p4a_q.csv", *_p4_mode_a(), fmt="{:.2f}"))
    assert j["verdict"] == [], j["effects"]


def _p3_tumble(n: int = 960) -> tuple[list, list, list]:
    """A compass tumbling slowly at 50 Hz, R(t) = Rz(0.35 t) Ry(0.23 t) Rx(0.41 t), exact field
    (IGRF at the place and date, ppigrf) through W and h, accelerometer exactly gravity."""
    ts = np.arange(n) * 0.02
    F = G.igrf_ned_nT(39.98, 116.35, 52.0, "2026-11-21")
    Rs = [G.rot("z", 0.35 * s) @ G.rot("y", 0.23 * s) @ G.rot("x", 0.41 * s) for s in ts]
    _, _, mags, accs = G.p3_raw(F, Rs, "uT", 9.8)
    rows = [[s, *m, *(a / 9.8)] for s, m, a in zip(ts, mags, accs)]
    meta = [("procedure", "compass"), ("device", "S26F-P3"), ("mag_unit", "uT"), ("accel_unit", "g")]
    meta += [("latitude_deg", "39.98"), ("longitude_deg", "116.35"), ("altitude_m", "52"), ("date", "2026-11-21")]
    return meta, ["t", "mx", "my", "mz", "ax", "ay", "az"], rows


def test_p3_exact_tumble_has_verdict_none(tmp_path):
    """An exact compass tumble: calibrate recovers W and h exactly, but diagnose's baseline refit
    left 39 nT RMS and named `field_anomaly` (gain 1.0): `engine._aux_scales` took the dip rows'
    σ down to their exact residual (1e-10), 1e10 below the magnitude rows'. The dip rows' σ now
    has a floor (`Problem.aux_noise_floor`, 1e-6)."""
    j = _diagnose(_write(tmp_path / "p3_tumble.csv", *_p3_tumble()))
    assert j["verdict"] == [], j["effects"]


def _p4_mode_b_drifting(slope_rad_s2: float = 2e-7, n: int = 3000):
    """Mode B, one level position at heading 0, 10 Hz: the Earth rate in the body (x forward, y
    up, z right) plus ε plus a bias linear in elapsed time, all exact."""
    wE, C = G.p4_earth_rate_body(39.98, 0.0)
    f = C @ np.array([0.0, 9.8, 0.0])
    t = np.arange(n) / 10.0
    rows = [[t[i], *(f / 9.8), *(wE + G.P4_EPS + slope_rad_s2 * t[i]), 25.0] for i in range(n)]
    meta = [("procedure", "gyro-drift"), ("device", "S26F-P4"), ("gyro_unit", "rad/s"), ("accel_unit", "g")]
    meta += [("g_mps2", "9.8"), ("gyro_mode", "static"), ("latitude_deg", "39.98"), ("heading_deg", "0")]
    return (meta, ["t", "ax", "ay", "az", "gx", "gy", "gz", "temp_c"], rows), float(t.mean())


def test_p4_mode_b_exact_with_a_time_drift_is_calibrated_and_named(tmp_path):
    """Mode B, one exact static record whose bias drifts 2e-7 rad/s per s (the whole record at
    rest, no position column): the stillness detector measured the rate noise as ~0, called the
    drift a turn and kept 6.6 s of 300; calibrate and diagnose refused it, exit 2: "mode B: 6.6 s
    (66 samples) is too short" (main). With a rate-noise floor under any MEMS gyro's (3e-5 rad/s
    per sample) the record is one rest: calibrate gives the mean bias (P4's constant ε: the
    drift at the record's mean time), diagnose names `time_drift` alone."""
    slope = 2e-7
    data, t_mean = _p4_mode_b_drifting(slope)
    path = _write(tmp_path / "p4b_drift.csv", *data)
    res = run_station("calibrate", path, "--json")
    assert res.returncode == 0, res.stderr
    j = json.loads(res.stdout)
    assert j["n_positions"] == 1
    np.testing.assert_allclose(j["params"]["drift"], G.P4_EPS + slope * t_mean, atol=1e-10)
    assert _diagnose(path)["verdict"] == ["time_drift"]
