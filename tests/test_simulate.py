"""The simulator: valid captures for every procedure and effect, read back identically,
consistent with the forward models it is built on."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from solvers.models import accel
from solvers.simulate import EFFECTS_BY_PROCEDURE, PROCEDURES, SimulationError, simulate
from station.capture import Capture, read_capture, write_capture

SMALL = {
    "accel-tabletop": {"hold_s": 3.0, "move_s": 1.0},
    "accel-centrifuge": {},
    "compass": {"n_orientations": 10, "hold_s": 1.0, "move_s": 1.0},
    "gyro-drift": {"duration_s": 20.0},
    "ldv": {"duration_s": 60.0},
}
SIZES = {
    "temperature_bias": 0.01,
    "time_drift": 0.05,
    "quadratic": 1e-3,
    "scale_asymmetry": 1e-3,
    "misalignment": 5e-4,
    "cubic": 1e-6,
    "lever_arm": 0.02,
    "g_sensitivity": 1e-4,
    "earth_rate": 1.0,
    "mag_accel_misalignment": 0.02,
    "field_anomaly": 0.05,
    "time_varying_hard_iron": 2.0,
    "time_delay": 0.05,
    "offset": 0.02,
}


def _cases():
    for proc in PROCEDURES:
        yield proc, None
        for eff in EFFECTS_BY_PROCEDURE[proc]:
            yield proc, eff


@pytest.mark.parametrize("procedure,effect", list(_cases()))
def test_every_procedure_and_effect_round_trips_through_a_capture_file(tmp_path, procedure, effect):
    effects = {effect: SIZES[effect]} if effect else None
    sim = simulate(procedure, seed=7, effects=effects, **SMALL[procedure])
    path = tmp_path / "c.csv"
    write_capture(path, Capture(meta=sim.meta, columns=sim.columns, path=str(path)))
    back = read_capture(path)
    assert back.procedure == procedure
    assert list(back.columns) == list(sim.columns)
    for name, col in sim.columns.items():
        if col.dtype == object:
            assert list(back.columns[name]) == list(col)
        else:
            np.testing.assert_array_equal(back.columns[name], col)
    json.dumps(sim.truth)  # the truth is JSON-able
    if effect and effect != "earth_rate":
        assert sim.truth["effects"] == {effect: SIZES[effect]}


def test_same_seed_same_capture_other_seed_other_capture():
    a = simulate("accel-tabletop", seed=1, hold_s=2.0, move_s=1.0)
    b = simulate("accel-tabletop", seed=1, hold_s=2.0, move_s=1.0)
    c = simulate("accel-tabletop", seed=2, hold_s=2.0, move_s=1.0)
    np.testing.assert_array_equal(a.columns["ax"], b.columns["ax"])
    assert not np.array_equal(a.columns["ax"], c.columns["ax"])


def test_tabletop_static_rows_obey_the_truth_through_the_model_inverse():
    """Held rows, calibrated with the true (B, M) by the same model's inverse, have |A| = g
    within the simulated noise: the simulator really is the forward model."""
    sim = simulate("accel-tabletop", seed=4, hold_s=5.0, move_s=2.0)
    held = sim.columns["position"] != ""
    V = np.column_stack([sim.columns[k][held] for k in ("ax", "ay", "az")])
    A = accel.inverse(V, accel.p1_to_forward(sim.truth["B"], sim.truth["M"]))
    norm = np.linalg.norm(A, axis=1)
    # 0.01 m/s² white noise per axis (+ tiny bias instability, rounding to 1 µV)
    assert abs(norm.mean() - sim.truth["g_mps2"]) < 0.002
    assert 0.007 < norm.std() < 0.013
    # the 12 source positions are all there, in order
    labels = [p for i, p in enumerate(sim.columns["position"]) if p and sim.columns["position"][i - 1] != p]
    assert labels == sim.truth["positions"] and len(labels) == 12


def test_centrifuge_norm_condition_holds_at_truth():
    sim = simulate("accel-centrifuge", seed=0, noise_g=0.0)
    t = sim.truth
    N = np.column_stack([sim.columns[k] for k in ("ax", "ay", "az")])
    f = accel.inverse(N, {"S": np.array(t["S"]), "b": np.array(t["b"]), "D": np.array(t["D"])})
    A = sim.columns["speed_rad_s"] ** 2 * t["radius_m"] / t["g_mps2"]
    np.testing.assert_allclose(np.sum(f**2, axis=1), A**2 + 1, rtol=1e-9)


def test_unknown_effect_for_procedure_is_refused():
    with pytest.raises(SimulationError, match="does not apply"):
        simulate("ldv", effects={"quadratic": 1.0})


def test_cli_simulate_writes_capture_and_truth(tmp_path):
    out, truth = tmp_path / "g.csv", tmp_path / "g.json"
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "station",
            "simulate",
            "--procedure",
            "gyro-drift",
            "--out",
            str(out),
            "--truth",
            str(truth),
            "--seed",
            "5",
            "--effect",
            "temperature_bias=1e-4",
            "--option",
            "duration_s=10",
        ],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert read_capture(out).procedure == "gyro-drift"
    assert json.loads(truth.read_text())["effects"] == {"temperature_bias": 1e-4}


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--effect", "warp=1"], "does not apply"),
        (["--effect", "temperature_bias=abc"], "not a number"),
        (["--effect", "temperature_bias"], "NAME=VALUE"),
        (["--option", "no_such_option=3"], "not an option of ldv"),
    ],
)
def test_cli_simulate_bad_arguments_one_line_exit_2(tmp_path, args, needle):
    out = tmp_path / "x.csv"
    r = subprocess.run(
        [sys.executable, "-m", "station", "simulate", "--procedure", "ldv", "--out", str(out), *args],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2
    assert needle in r.stderr and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not out.exists()


@pytest.mark.parametrize("too_long", ["truth", "out"])
def test_cli_simulate_writes_the_capture_and_its_truth_or_neither(tmp_path, too_long):
    """`simulate --out cap.csv --truth T` where T cannot be written (a read-only folder, a full
    disk; here a name whose temporary the file system refuses as too long) said so with exit 2
    but left cap.csv written without its truth. Both files or neither."""
    from tests.station_run import assert_one_line_refusal, run_station

    long_name = "t" * 240  # the file itself fits in 255 bytes, its hidden temporary beside it does not
    out = tmp_path / (long_name + ".csv" if too_long == "out" else "cap.csv")
    truth = tmp_path / (long_name + ".json" if too_long == "truth" else "truth.json")
    res = run_station("simulate", "--procedure", "accel-centrifuge", "--out", out, "--truth", truth)
    assert_one_line_refusal(res, "cannot write", "File name too long")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "procedure, option, column",
    [("compass", "mag_noise_uT=1e300", "mx"), ("accel-centrifuge", "noise_g=1e300", "ax")],
)
def test_cli_simulate_refuses_options_that_make_a_capture_the_reader_refuses(tmp_path, procedure, option, column):
    """`simulate --option mag_noise_uT=1e300` wrote a capture with exit 0 that `calibrate`,
    `inspect` and `diagnose` then refused (6.6e299 uT "is beyond what any magnetometer
    reports"). The options are input: one line naming the column and the bound, nothing
    written; an ordinary noise still simulates and reads back."""
    from tests.station_run import assert_one_line_refusal, run_station

    out = tmp_path / "sim.csv"
    res = run_station("simulate", "--procedure", procedure, "--out", out, "--option", option)
    assert_one_line_refusal(res, f"column '{column}'", "beyond what any")
    assert not out.exists()
    res = run_station("simulate", "--procedure", procedure, "--out", out, "--option", option.replace("1e300", "0.01"))
    assert res.returncode == 0, res.stderr
    assert run_station("inspect", out).returncode == 0


def _today_utc() -> str:
    import datetime as dt

    return dt.datetime.now(dt.UTC).date().isoformat()


def test_a_capture_simulated_now_is_dated_today_and_filed_now(tmp_path):
    """`station simulate` wrote the simulator's fixed date (2026-11-21) into every capture, so one
    simulated and saved days later (after a demo's calibration, say) was filed on that old day's
    last second, behind what was saved since (qa-s25b). A capture simulated now says today (UTC),
    and `calibrate --save` files it at the save."""
    import datetime as dt
    import sqlite3

    from tests.station_run import run_station

    before = _today_utc()
    out, db = tmp_path / "p1.csv", tmp_path / "station.db"
    assert run_station("simulate", "--procedure", "accel-tabletop", "--seed", "3", "--out", out).returncode == 0
    assert read_capture(out).meta["date"] in {before, _today_utc()}
    assert run_station("--db", db, "devices", "add", "SIM-ACC-0000").returncode == 0
    start = dt.datetime.now(dt.UTC).replace(microsecond=0)
    res = run_station("calibrate", out, "--save", "--device", "SIM-ACC-0000", "--db", db)
    assert res.returncode == 0, res.stderr
    end = dt.datetime.now(dt.UTC)
    with sqlite3.connect(db) as con:
        (time,) = con.execute("select time from calibrations").fetchone()
    assert start <= dt.datetime.fromisoformat(time.replace("Z", "+00:00")) <= end, time


@pytest.mark.parametrize("procedure", ["accel-tabletop", "compass", "gyro-drift", "ldv"])
def test_the_date_comes_from_the_command_line_and_the_simulator_gets_it(tmp_path, procedure):
    """Two routes, one answer: `simulate --date D` is the simulator's capture at site date D (the
    compass field is IGRF's of D), and without --date it is today's; solvers/ reads no clock."""
    from solvers.simulate import DEFAULT_SITE
    from tests.station_run import run_station

    options = {"compass": {"n_orientations": 10, "hold_s": 1.0, "move_s": 1.0}}.get(procedure, {})
    args = [a for k, v in options.items() for a in ("--option", f"{k}={v:g}")]
    for date in ("2024-02-29", None):
        out = tmp_path / f"{date}.csv"
        res = run_station(
            "simulate",
            "--procedure",
            procedure,
            "--seed",
            "9",
            "--out",
            out,
            *args,
            *(["--date", date] if date else []),
        )
        assert res.returncode == 0, res.stderr
        day = date or _today_utc()
        want = simulate(procedure, seed=9, site={"date": day}, **options)
        got = read_capture(out)
        assert got.meta["date"] == day
        for name, col in want.columns.items():
            if col.dtype == object:
                assert list(got.columns[name]) == list(col)
            else:
                np.testing.assert_array_equal(got.columns[name], col, err_msg=name)
    assert DEFAULT_SITE["date"] == "2026-11-21"  # the simulator's own default stays fixed (reproducible)


def test_a_table_without_a_site_takes_a_date_only_when_given(tmp_path):
    """P2's simulated table has no site and wrote no date (it is filed at its save); --date gives it one."""
    from tests.station_run import run_station

    out = tmp_path / "p2.csv"
    assert run_station("simulate", "--procedure", "accel-centrifuge", "--out", out).returncode == 0
    assert "date" not in read_capture(out).meta
    assert (
        run_station("simulate", "--procedure", "accel-centrifuge", "--out", out, "--date", "2025-06-01").returncode == 0
    )
    assert read_capture(out).meta["date"] == "2025-06-01"


@pytest.mark.parametrize(
    "procedure, date, needle",
    [
        ("accel-tabletop", "2025-13-01", "'2025-13-01' is not a date (YYYY-MM-DD"),
        ("accel-tabletop", "21/11/2026", "'21/11/2026' is not a date (YYYY-MM-DD"),
        ("accel-tabletop", "20261121", "'20261121' is not a date (YYYY-MM-DD"),
        ("compass", "1700-01-01", "--date 1700-01-01: 1700-01-01 is 200.0 years outside the IGRF coverage"),
    ],
)
def test_a_date_the_capture_cannot_carry_is_one_line(tmp_path, procedure, date, needle):
    out = tmp_path / "x.csv"
    r = subprocess.run(
        [sys.executable, "-m", "station", "simulate", "--procedure", procedure, "--out", str(out), "--date", date],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2 and r.stdout == ""
    assert needle in r.stderr and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert not out.exists()
