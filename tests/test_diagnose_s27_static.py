"""`station diagnose` on static captures an outside bench writes: benchmarks/indep_s27_generator.py,
written from the contracts only (its own orientation sets, noise with bias instability and random
walk, holds numbered in its own order). The hidden effect's name goes to the generator only; each
test reads the capture file through the real command and checks the verdict."""

from __future__ import annotations

import json
import sys

import numpy as np
from station_run import ROOT, run_station


def _generator():
    if str(ROOT / "benchmarks") not in sys.path:
        sys.path.insert(0, str(ROOT / "benchmarks"))
    import indep_s27_generator

    return indep_s27_generator


def _write(tmp_path, procedure, hidden, seed):
    path = tmp_path / "capture.csv"
    _generator().make_one(procedure, hidden, 10.0, seed, str(path))
    return path


def _diagnose(path) -> dict:
    res = run_station("diagnose", path, "--json", "--no-plots")
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def test_p1_table_numbered_in_the_benchs_own_order_names_its_effect(tmp_path):
    """A table of 22 positions of the bench's own set, numbered 1..22 in the order taken (P1's
    own numbers 1-12 mean directions: these do not), a scale asymmetry at 10σ. The calibration
    sets the labels aside (they read far from P1's directions); diagnose used their directions
    all the same, fitted a baseline pulled by them and named `residual:input_axis`."""
    path = _write(tmp_path, "P1", "scale_asymmetry", 700919)
    cal = json.loads(run_station("calibrate", path, "--json").stdout)
    assert cal["labels_used"] is False
    res = _diagnose(path)
    assert "scale_asymmetry" in res["verdict"], (res["verdict"], res["candidates"])
    assert not any(v.startswith("residual:") for v in res["verdict"]), res["verdict"]


def test_p1_eleven_positions_numbered_in_their_own_order_are_calibrated(tmp_path):
    """11 positions (no effect) numbered 1..11 in the bench's own order: the labels' directions
    collapsed the fit ('the fit collapsed ... check the position labels', exit 2), since the check
    that sets wrong labels aside ran only from 12 positions. A collapse is no calibration: the
    fit without the labels is tried, and the null is diagnosed clean."""
    path = _write(tmp_path, "P1", "none", 700833)
    cal = run_station("calibrate", path, "--json")
    assert cal.returncode == 0, cal.stderr
    assert json.loads(cal.stdout)["labels_used"] is False
    assert _diagnose(path)["verdict"] == []


def test_p2_time_series_time_drift_is_named(tmp_path):
    """A centrifuge time series (18 mountings x 3 speeds, holds of 5-30 s, ramps between speeds,
    a stop to remount) with a bias drifting in time at 10σ: diagnose averaged each hold but left
    its time and temperature out ('no time in the capture (t or elapsed_s column)') and named
    nothing."""
    res = _diagnose(_write(tmp_path, "P2", "time_drift", 701014))
    assert "time_drift" in res["verdict"], (res["verdict"], res["candidates"])


def test_p4_mode_a_on_several_positions_names_g_sensitivity(tmp_path):
    """Mode A (reference IMU) with the pair turned between 16 labelled positions, a gyro bias
    proportional to the specific force at 10σ: mode A took the whole record as one orientation
    ('one static orientation: the specific force does not change') and named nothing."""
    res = _diagnose(_write(tmp_path, "P4", "g_sensitivity", 702003))
    assert "g_sensitivity" in res["verdict"], (res["verdict"], res["candidates"])


def test_p1_bias_step_during_a_hold_is_named_not_left_as_an_outlier_part(tmp_path):
    """A P1 time series of 13 holds (125 Hz, g, a temperature that cycles) with a bias step at
    10σ that falls during a hold, between two of its parts. The step scan tried places between
    holds only: there a step (3 + its place) takes every hold mean the baseline leaves (13 − 9)
    and explains little (deviance 19 against a bound of 46); nothing was named and the hold's
    part that holds the step was reported as an outlier (6.9σ), as if a knock. A step moves
    every later hold: tried between the parts of each hold as well, it is named, and no part
    is left an outlier."""
    res = _diagnose(_write(tmp_path, "P1", "bias_step", 700013))
    assert "residual:time" in res["verdict"], (res["verdict"], res["candidates"])
    step = next(e for e in res["effects"] if e["name"] == "residual:time")
    assert step["shape"] == "step", step
    assert not [q for q in res["quality"] if q["kind"] == "outlier"], res["quality"]


def test_p4_latitude_without_headings_fits_each_heading_not_north(tmp_path):
    """Mode B at a known latitude (-33.3°), 10 positions labelled, no `heading_deg` (a tabletop
    session's positions: pitch and roll from the accelerometer, the heading unknown), the gyro
    noise scaled so the Earth rate is at 30σ of it (the generator's `earth_rate` row written with
    the latitude: nothing is hidden beyond the Earth rate, which the baseline must hold). The
    diagnosis took every heading as 0 (north): the Earth rate's north part, Ω cos L, was removed
    along the wrong direction at every position, the residuals were reported as structured and
    `g_sensitivity` was named. Each position's heading is now fitted with the bias: the verdict
    is empty, and the headings found are the bench's (written by the same seed with its heading
    column, read back from that file)."""
    gen = _generator()
    path, with_heading = tmp_path / "capture.csv", tmp_path / "with_heading.csv"
    gen.make_one("P4", "earth_rate", 30.0, 708029, str(path), no_heading=True)
    gen.make_one("P4", "earth_rate", 30.0, 708029, str(with_heading))
    assert "heading_deg" not in path.read_text().split("\nt,", 1)[1].split("\n", 1)[0]
    res = _diagnose(path)
    assert res["verdict"] == [], (res["verdict"], res["candidates"])
    assert not [q for q in res["quality"] if q["kind"] == "residuals_not_white"], res["quality"]
    from station.capture import read_capture

    h = read_capture(str(with_heading)).columns["heading_deg"]
    bench_deg = np.array(list(dict.fromkeys(np.round(h[np.isfinite(h)], 2))))  # one per position, in order
    fitted_deg = np.degrees(np.asarray(res["baseline"]["params"]["heading_rad"], float))
    assert fitted_deg.shape == bench_deg.shape
    err = (fitted_deg - bench_deg + 180.0) % 360.0 - 180.0
    # at 30σ over 10 positions a heading is fixed to about 10° (the north part, Ω cos L, is ~6σ
    # of one position's mean); heading 0 would be off by 21-158° at every one of these 10
    assert np.median(np.abs(err)) < 10.0 and np.max(np.abs(err)) < 25.0, np.round(err, 1)


def test_p4_null_with_slow_noise_below_the_wander_gate_names_nothing(tmp_path):
    """Mode B, 18 positions over 17 min at 50 Hz, no temperature, no effect: the generator's noise
    is white plus a Gauss–Markov bias (τ 60-600 s) and a random walk on each axis. REML did not
    call the wander evident (ratio over white noise below 16 on every axis), so a line in time was
    tested against white noise: deviance 13.6 against a bound of 11.7, and `time_drift` was named.
    With the slow noise profiled out the line's ratio is 6.4: nothing is named."""
    res = _diagnose(_write(tmp_path, "P4", "none", 702131))
    assert res["verdict"] == [], (res["verdict"], res["candidates"])


def test_p4_power_up_record_still_names_its_warm_up(shared_data):
    """The real MPU-6050 record from power-up (449 s unmoved, counts, no temperature): its warm-up
    is a drift in time well beyond its wander, and stays named (`time_drift`) with every
    candidate tested against the slow noise."""
    res = _diagnose(shared_data / "mpu6050_unc" / "mpu6050_unc_tinit_static.capture.csv")
    assert "time_drift" in res["verdict"], (res["verdict"], res["candidates"])


def test_p1_null_whose_linearised_asymmetry_vanishes_when_refitted_names_nothing(tmp_path):
    """A time series with no effect, 11 holds (one moved and left out). The scale asymmetry's
    linearised test took a step of A ≈ −1.4, far outside the model's range (deviance 84 against a
    bound of 28, held-out RMS −32 %, most of it on the changes within holds); the final refit put
    A at 0 ± 4e-5 with the baseline's residual, and it was named all the same. An effect the
    refitted model does not need is not named."""
    path = _write(tmp_path, "P1", "none", 721101)
    res = _diagnose(path)
    assert res["verdict"] == [], (res["verdict"], res["candidates"])


def test_p4_heading_column_labels_the_holds_and_the_turns_between_them_are_left_out(tmp_path):
    """12 positions with a per-row `heading_deg` and no `position` column, no latitude, the turns
    between holds in the record (the bench writes the last hold's heading until the next one),
    the gyro noise scaled so the Earth rate is at 10σ. Each heading's rows were taken as one
    static position, turns and all: rates of up to 1.9 rad/s averaged into the position means,
    the Earth rate not identifiable (±4.2e-5 rad/s against 7.3e-5) and diagnose named nothing.
    The heading now labels the static intervals found in the record; the latitude the gyros
    imply is the bench's (written by the same seed into the file it makes without headings)."""
    gen = _generator()
    path, site = tmp_path / "capture.csv", tmp_path / "site.csv"
    gen.make_one("P4", "earth_rate", 10.0, 742003, str(path))
    gen.make_one("P4", "earth_rate", 10.0, 742003, str(site), no_heading=True)
    header = path.read_text().split("\nt,", 1)[1].split("\n", 1)[0]
    assert "heading_deg" in header and "position" not in header and "latitude_deg" not in path.read_text()
    from station.capture import read_capture

    lat_deg = read_capture(str(site)).float_meta("latitude_deg")
    cal = run_station("calibrate", path, "--json")
    assert cal.returncode == 0, cal.stderr
    fit = json.loads(cal.stdout)["fit"]
    assert fit["latitude_identifiable"], fit
    err = fit["latitude_from_gyros_deg"] - lat_deg
    assert abs(err) < 3.0 * fit["sigma_latitude_from_gyros_deg"], (fit, lat_deg)
    assert fit["sigma_latitude_from_gyros_deg"] < 15.0, fit
    res = _diagnose(path)
    assert res["verdict"] == ["earth_rate"], (res["verdict"], res["candidates"])


def test_p2_table_null_whose_bias_wanders_names_nothing(tmp_path):
    """A table of averages with no effect whose bias wanders (the generator's Gauss–Markov bias
    instability and random walk): the rows of one mounting, run one speed after another, share
    the wander, and their σ (std/√n) leaves it out. Tested against the rows' white noise alone
    it named `misalignment` (ΔBIC −8). The wander is evident on this table (REML likelihood
    ratio far above 2.71), and tested net of it nothing is named."""
    path = tmp_path / "null.csv"
    _generator().make_one("P2", "none", 0.0, 749034, str(path))
    res = _diagnose(path)
    assert res["baseline"]["slow_noise"]["bias_sigma"] > 0, res["baseline"]["slow_noise"]
    assert res["verdict"] == [], (res["verdict"], res["candidates"])


def test_p2_mounting_bias_is_sized_within_its_uncertainty(tmp_path):
    """The station's own P2 table (20 mountings × 3 speeds, white noise 1e-5 g) with a bias per
    mounting and axis of 5e-5 g added (drawn here, independent of the simulator): the bias the
    diagnosis sizes on the table is that σ, within what 20 mountings can tell (six draws of the
    bias gave 0.94–1.26 of it; ±40 % allowed); on the table as written (no such bias) none is
    evident, and the rows' σ stand alone."""
    src = tmp_path / "p2.csv"
    assert run_station("simulate", "--procedure", "accel-centrifuge", "--seed", 5, "--out", src).returncode == 0
    clean = _diagnose(src)["baseline"]["slow_noise"]
    assert clean["bias_sigma"] == 0.0 and "none evident" in clean["model"], clean
    lines = src.read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("position,"))
    names = lines[head].split(",")
    ix = [names.index(c) for c in ("ax", "ay", "az")]
    rng = np.random.default_rng(2026)
    bias = {}
    out = lines[: head + 1]
    for line in lines[head + 1 :]:
        f = line.split(",")
        b = bias.setdefault(f[0], rng.normal(0.0, 5e-5, 3))
        for k, i in enumerate(ix):
            f[i] = f"{float(f[i]) + b[k]:.9f}"
        out.append(",".join(f))
    path = tmp_path / "p2-bias.csv"
    path.write_text("\n".join(out) + "\n")
    res = _diagnose(path)
    sized = res["baseline"]["slow_noise"]["bias_sigma"]
    assert 0.6 * 5e-5 < sized < 1.4 * 5e-5, res["baseline"]["slow_noise"]
    assert res["verdict"] == [], (res["verdict"], res["candidates"])
