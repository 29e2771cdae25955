"""Captures of shapes the diagnose generator never writes (benchmarks/redteam_captures.py), through
the real ``station diagnose`` / ``station calibrate`` commands."""

from __future__ import annotations

import numpy as np

from tests.station_run import redteam_capture, station_json


def _write(tmp_path, proc, opts, effect=None, fmt=None, seed=4242):
    return redteam_capture(tmp_path, proc, opts, effect, seed, fmt)


def test_quiet_quantised_magnetometer_is_not_called_saturated(tmp_path):
    """A magnetometer in ADC counts whose noise is below one count holds one reading for many
    samples in every hold: at the hold with the extreme reading that is not clipping, and
    screening it out would drop good holds from the effect search."""
    path, _ = _write(tmp_path, "compass", {"unit": "counts", "noise": 20.0, "temp": "constant"})
    out = station_json("diagnose", path, "--json")
    assert [q for q in out["quality"] if q["kind"] == "saturation"] == []
    assert out["verdict"] == []


def test_quiet_gyro_in_counts_reading_one_value_is_diagnosed(tmp_path):
    """A static gyro in counts whose noise is a fraction of a count reads one value nearly all
    the time: that value is its column's extreme, yet no clipping. Calling it saturation
    screened out every sample and refused the capture ("0 static samples")."""
    path, _ = _write(tmp_path, "gyro-drift", {"unit": "counts", "noise": 2e-5, "duration_s": 200.0, "rate": 50.0})
    out = station_json("diagnose", path, "--json")
    assert [q for q in out["quality"] if q["kind"] == "saturation"] == []
    assert out["verdict"] == []


def _whole_second_p4(tmp_path):
    """P4 mode B logged at 50 Hz with t in whole epoch seconds: 50 rows share each stamp."""
    opts = {"t0": 1.7e9, "t_res": 1.0, "duration_s": 200.0, "rate": 50.0, "temp": "constant"}
    return _write(tmp_path, "gyro-drift", opts)


def test_gyro_drift_calibrates_with_coarse_time_stamps(tmp_path):
    """t non-decreasing (capture-format.md) with many rows per stamp: the median step is 0, so
    the step comes from the rows over the span instead of a refusal."""
    path, truth = _whole_second_p4(tmp_path)
    out = station_json("calibrate", path, "--json")
    drift, sigma = np.array(out["params"]["drift"]), np.array(out["uncertainty"]["drift"])
    assert np.all(np.abs(drift - truth["eps"]) < 4 * sigma + 1e-7), (drift, truth["eps"], sigma)


def test_coarse_time_stamps_are_not_gaps(tmp_path):
    """Each tick of a whole-second stamp is 1 s after 49 zero steps: against a median step of 0
    every tick was a gap, every sample screened out and the capture refused."""
    path, _ = _whole_second_p4(tmp_path)
    out = station_json("diagnose", path, "--json")
    assert [q for q in out["quality"] if q["kind"] == "gap"] == []
    assert out["verdict"] == []


def test_tabletop_diagnoses_with_coarse_time_stamps(tmp_path):
    """P1 at 50 Hz with t in whole epoch seconds: a hold's part has a median step of 0, which
    made its standard error infinite and the diagnosis fail ("residual is not finite")."""
    opts = {"hold_s": 12.0, "rate": 50.0, "t0": 1.7e9, "t_res": 1.0, "temp": "constant"}
    path, _ = _write(tmp_path, "accel-tabletop", opts)
    out = station_json("diagnose", path, "--json")
    assert out["verdict"] == []
    assert np.isfinite(out["baseline"]["cv_rms"])


def test_tabletop_finds_positions_with_coarse_time_stamps(tmp_path):
    """No position column and t in whole seconds (non-decreasing, capture-format.md): the
    stillness detector needs increasing times and the capture was refused ("t_s does not
    increase"); ties are now spread over their tick and the calibration recovers the truth."""
    opts = {"hold_s": 12.0, "rate": 50.0, "t_res": 1.0, "labels": False, "temp": "constant"}
    path, truth = _write(tmp_path, "accel-tabletop", opts)
    out = station_json("calibrate", path, "--json")
    assert out["n_positions"] == 12
    M, Mt = np.array(out["params"]["M"]), truth["M"]
    assert np.abs(M.T @ M - Mt.T @ Mt).max() < 1e-3 * np.abs(Mt.T @ Mt).max()


def _blank(path, column, rows):
    """Empty the field ``column`` (a missing value, capture-format.md) in the given data rows."""
    lines = path.read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    k = lines[head].split(",").index(column)
    for r in rows:
        f = lines[head + 1 + r].split(",")
        f[k] = ""
        lines[head + 1 + r] = ",".join(f)
    path.write_text("\n".join(lines) + "\n")


def test_one_missing_temperature_keeps_the_temperature_candidate_p4(tmp_path):
    """A large temperature bias in a P4 record with two empty temp_c fields: the empty fields
    dropped the temperature candidate ("no temperature in the capture") and another name was
    given; they are interpolated from their neighbours now."""
    opts = {"duration_s": 200.0, "rate": 50.0}
    path, _ = _write(tmp_path, "gyro-drift", opts, effect="temperature_bias")
    _blank(path, "temp_c", [100, 5000])
    assert station_json("diagnose", path, "--json")["verdict"] == ["temperature_bias"]


def test_one_missing_temperature_keeps_the_temperature_candidate_p2(tmp_path):
    """The same in a centrifuge table: one row's temp_c empty."""
    path, _ = _write(tmp_path, "accel-centrifuge", {}, effect="temperature_bias")
    _blank(path, "temp_c", [7])
    assert station_json("diagnose", path, "--json")["verdict"] == ["temperature_bias"]


def test_one_missing_temperature_keeps_the_temperature_candidate_compass(tmp_path):
    path, _ = _write(tmp_path, "compass", {}, effect="temperature_bias")
    _blank(path, "temp_c", [30, 500])
    assert station_json("diagnose", path, "--json")["verdict"] == ["temperature_bias"]


def test_one_missing_temperature_keeps_the_temperature_candidate_ldv(tmp_path):
    path, _ = _write(tmp_path, "ldv", {"duration_s": 200.0, "rate": 10.0}, effect="temperature_bias")
    _blank(path, "temp_c", [30, 500])
    assert "temperature_bias" in station_json("diagnose", path, "--json")["verdict"]


def test_compass_magnitude_rows_weighed_by_the_white_noise(tmp_path):
    """A compass temperature bias of tens of σ that calibrate does not model: calibrate scales
    its noise up by the misfit it leaves (9 times here), and diagnose took that as the magnitude
    rows' noise while it measured the dip rows' noise against the model with the bias fitted. The
    14 dip rows then weighed 80 times too much, bent W and h, and a periodic `residual:time`
    fitted what that left beside the bias. The magnitude rows' noise is the white noise measured
    in the samples now: under the extended model they scatter as that noise says."""
    from station.capture import read_capture
    from station.procedures.diagnose import analyse

    path, _ = _write(tmp_path, "compass", {}, effect="temperature_bias", seed=7)
    out, diag, _ = analyse(read_capture(str(path)))
    assert out["verdict"] == ["temperature_bias"]
    mag = np.asarray(diag.problem.row_types) == 0
    rms = float(np.sqrt(np.mean(diag.extended.weighted_residuals[mag] ** 2)))
    assert 0.7 < rms < 1.4, rms


def test_a_quiet_reading_at_a_power_of_two_inside_the_columns_range_is_not_clipping():
    """A magnetometer in counts (150 nT, noise below a count) that reads exactly −256 through a
    hold is the column's smallest reading, and −2⁸ is a two's-complement limit; but the same
    column reads +400 elsewhere, beyond the +255 such a converter gives, so it is not clipped
    there. It was called saturation and the hold left out of the effect search (red-team
    compass ``counts_quiet``, seed 9202)."""
    from solvers.diagnose.quality import saturation

    rng = np.random.default_rng(9202)
    holds = [-256.0, -120.0, 37.0, 215.0, 400.0, -3.0]
    x = np.concatenate([np.full(200, h) + (rng.random(200) < 0.02) * rng.choice([-1.0, 1.0], 200) for h in holds])
    x[:200] = -256.0  # the quiet hold at the column's extreme reads one value throughout
    assert saturation({"mz": x}) == []
    clipped = np.clip(x * 200.0, -32768.0, 32767.0)  # a 16-bit converter driven beyond its range
    found = saturation({"mz": clipped})
    assert [(q["column"], q["value"]) for q in found] == [("mz", 32767.0), ("mz", -32768.0)], found


def test_a_still_unit_pausing_where_one_axis_peaks_is_not_clipping():
    """A magnetometer in gauss (a 1.5 mG step, its noise below a step) turned by hand and held
    still for a second where ``mx`` is at its largest: every axis reads one value through the
    pause, ``mx`` the column's extreme, and it was named saturation ("stuck at 0.318 gauss, its
    extreme reading"; QA s27d, generator seed 700120) and the pause left out of the effect
    search. Nothing tells a clip where the whole unit is still; ``mx`` pinned while ``my`` and
    ``mz`` go on moving still is one."""
    from solvers.diagnose.quality import saturation

    q = 0.0015
    t = np.arange(1000) * 0.01
    field = 0.3 * np.column_stack([np.cos(0.7 * t), np.sin(0.7 * t) * np.cos(0.3 * t), np.sin(0.3 * t)])
    field[500:600] = field[500]  # the pause
    field[500:600, 0] = field[:, 0].max() + 0.01  # where mx peaks
    cols = {f"m{a}": np.round(field[:, i] / q) * q for i, a in enumerate("xyz")}
    assert saturation(cols) == [], saturation(cols)
    fine = {f"m{a}": field[:, i] for i, a in enumerate("xyz")}  # a converter far finer than the noise
    moving = dict(fine, mx=np.minimum(fine["mx"], 0.27))  # clipped at 0.27 while the unit turns
    assert [q_["column"] for q_ in saturation(moving)] == ["mx"]


def test_a_slow_quantised_signal_turning_at_its_peak_is_not_clipping():
    """A magnetometer read at 8 Hz in 1.5 mG steps (an AK8963's), turned slowly: where ``mx``
    turns at its largest it stays on one step for 5 or more samples while ``my`` and ``mz``
    move on, and that was named saturation ("mx stuck at 0.318 gauss, its extreme reading";
    QA s27d, generator seed 700120) and left out. A parabola through the samples on both sides
    stays within a step of the reading there; a clipped signal's goes beyond it."""
    from solvers.diagnose.quality import saturation

    q = 0.0015
    t = np.arange(400) / 8.0
    field = np.column_stack([0.318 * np.cos(0.3 * t), 0.2 * np.sin(0.3 * t), 0.1 + 0.05 * np.sin(0.11 * t)])
    cols = {f"m{a}": np.round(field[:, i] / q) * q for i, a in enumerate("xyz")}
    assert saturation(cols) == [], saturation(cols)
    clipped = dict(cols, mx=np.minimum(cols["mx"], 0.3))  # a range of 0.3 gauss: a flat top
    assert {q_["column"] for q_ in saturation(clipped)} == {"mx"}
