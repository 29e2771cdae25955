"""What a bench engineer new to the station met on the command line: slightly wrong
arguments answered with one clear line (the real CLI, real files)."""

from __future__ import annotations

from tests.station_run import assert_one_line_refusal, run_station


def test_simulate_names_the_options_of_the_procedure_for_a_mistyped_one(tmp_path):
    """`--option mag_noise=1` (for mag_noise_uT) said "simulate_compass() got an unexpected
    keyword argument 'mag_noise'": Python's words for the simulator's function, not which
    options there are. Now it names the option and the procedure's options."""
    out = tmp_path / "c.csv"
    res = run_station("simulate", "--procedure", "compass", "--out", out, "--option", "mag_noise=1")
    assert_one_line_refusal(res, "--option mag_noise", "mag_noise_uT", "n_orientations")
    assert "keyword argument" not in res.stderr and "simulate_compass" not in res.stderr
    assert not out.exists()
    # the options not settable from the command line are not offered
    assert "site" not in res.stderr.split("mag_noise_uT", 1)[1]


def test_import_takes_the_unit_spellings_a_capture_takes(tmp_path):
    """`--unit gyro=dps` was refused ("not a gyro unit") though a capture declaring
    `gyro_unit: dps` is read as deg/s (README: units are read as other tools spell them);
    `t=sec` likewise. Now `--unit` reads the same spellings and writes the spec's names."""
    from station.capture import read_capture

    src = tmp_path / "bench.csv"
    rows = ["time_ms,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z"]
    rows += [f"{10 * i},0.01,0.02,9.81,0.5,-0.25,0.125" for i in range(300)]
    src.write_text("\n".join(rows) + "\n")
    out = tmp_path / "imu.csv"
    res = run_station(
        "import",
        src,
        "--procedure",
        "gyro-drift",
        "--map",
        "t=time_ms,ax=acc_x,ay=acc_y,az=acc_z,gx=gyr_x,gy=gyr_y,gz=gyr_z",
        "--unit",
        "accel=m/s2,gyro=dps,t=msec",
        "--out",
        out,
    )
    assert res.returncode == 0, res.stderr
    cap = read_capture(str(out))
    assert cap.meta["gyro_unit"] == "deg/s" and cap.meta["accel_unit"] == "m/s^2"
    assert abs(float(cap.columns["t"][-1]) - 2.99) < 1e-9  # milliseconds read as such
    # a unit that is none of them is still refused, naming what is allowed
    res = run_station(
        "import",
        src,
        "--procedure",
        "gyro-drift",
        "--map",
        "t=time_ms,gx=gyr_x,gy=gyr_y,gz=gyr_z",
        "--unit",
        "gyro=rpm,t=ms",
        "--out",
        tmp_path / "x.csv",
    )
    assert_one_line_refusal(res, "--unit gyro=rpm", "deg/s")


def _capture_without_device(tmp_path):
    from solvers.simulate import simulate
    from station.capture import write_capture
    from tests.station_run import capture_of

    cap = capture_of(simulate("gyro-drift", seed=5))
    del cap.meta["device"]
    path = tmp_path / "still.csv"
    write_capture(str(path), cap)
    return path


def test_calibrate_text_of_a_capture_without_a_device_says_none(tmp_path):
    """An imported CSV without --device has no device: `calibrate` printed "device     None"
    (Python's word), where `inspect` says "(none)"."""
    path = _capture_without_device(tmp_path)
    res = run_station("calibrate", path)
    assert res.returncode == 0, res.stderr
    line = next(x for x in res.stdout.splitlines() if x.startswith("device"))
    assert "None" not in line and "(none" in line, line


def test_saving_a_capture_without_a_device_names_the_option(tmp_path):
    """`calibrate FILE --save` of a capture without a device said "no device: pass device_id,
    or give 'device' in the result or the capture" (the library's argument, not the command's
    option). Now it names the file and --device; nothing is created."""
    path = _capture_without_device(tmp_path)
    db = tmp_path / "s.db"
    res = run_station("--db", db, "calibrate", path, "--save")
    assert_one_line_refusal(res, "still.csv", "--device ID")
    assert "device_id" not in res.stderr
    assert not db.exists()
    res = run_station("--db", db, "calibrate", path, "--save", "--device", "BENCH-1")
    assert res.returncode == 0, res.stderr


def test_drift_of_a_procedure_the_device_has_none_of_names_it(tmp_path):
    """`drift ID --procedure compass` of a unit with accepted P1 calibrations said "no accepted
    calibrations yet", as if it had none at all."""
    from solvers.simulate import simulate
    from station.capture import write_capture
    from tests.station_run import capture_of

    path = tmp_path / "p1.csv"
    write_capture(str(path), capture_of(simulate("accel-tabletop", seed=3)))
    db = tmp_path / "s.db"
    res = run_station("--db", db, "calibrate", path, "--save", "--device", "IMU-3")
    assert res.returncode == 0, res.stderr
    res = run_station("--db", db, "drift", "IMU-3", "--procedure", "compass", "--no-plot")
    assert res.returncode == 0 and "no accepted compass calibrations" in res.stdout, res.stdout
    res = run_station("--db", db, "drift", "IMU-3", "--procedure", "compass", "--param", "B[0]")
    assert_one_line_refusal(res, "accepted compass calibrations")
    res = run_station("--db", db, "drift", "IMU-3", "--no-plot")
    assert "B[0]" in res.stdout


def test_a_compass_capture_in_the_wrong_field_unit_is_warned_about(tmp_path):
    """A compass capture in µT declared `mag_unit: nT` (a field of 54 "nT" where IGRF gives
    54,989 nT) calibrated with no word: a soft iron of 1000 nT/nT, saved as accepted. Now the
    text warns that the raw field is 0.001x IGRF's and names the unit that would fit (uT);
    the same capture declared in µT gets no such warning."""
    from solvers.simulate import simulate
    from station.capture import write_capture
    from tests.station_run import capture_of

    cap = capture_of(simulate("compass", seed=4))
    assert cap.meta["mag_unit"] == "uT"
    right = tmp_path / "right.csv"
    write_capture(str(right), cap)
    cap.meta["mag_unit"] = "nT"
    wrong = tmp_path / "wrong.csv"
    write_capture(str(wrong), cap)
    res = run_station("calibrate", wrong)
    assert res.returncode == 0, res.stderr
    line = next((x for x in res.stdout.splitlines() if "mag_unit right" in x), "")
    assert "as uT" in line and "IGRF" in line, res.stdout
    res = run_station("calibrate", right)
    assert res.returncode == 0 and "mag_unit right" not in res.stdout, res.stdout


def test_headless_compass_demo_tilts_with_the_front_end_the_tui_uses():
    """`station demo --headless --procedure compass` wrote its capture without the simulated
    accelerometer's front end (the data sheet's zero and sensitivity, which the TUI's compass
    screen writes): the result said "accel_unit 'V' has no physical factor: no tilt, no
    heading". Now it carries the same front end, and the result its tilts and headings."""
    res = run_station("demo", "--headless", "--procedure", "compass", "--speed", "20", "--no-save")
    assert res.returncode == 0, res.stderr
    assert "no tilt, no heading" not in res.stdout, res.stdout
    assert "heading" in res.stdout and "pitch" in res.stdout, res.stdout


def test_diagnose_says_the_bound_it_uses(tmp_path):
    """`station diagnose` (and the TUI's Diagnose screen) said candidates are selected when
    "deviance / serial-correlation inflation > F·χ²_k(1 − 0.05/m)"; the bound is the exact F
    test's on the degrees of freedom left (docs/diagnose.md, engine.deviance_quantile), which
    on a 60-row P2 table is not the χ² quantile."""
    from solvers.simulate import simulate
    from station.capture import write_capture
    from tests.station_run import capture_of

    path = tmp_path / "p2.csv"
    write_capture(str(path), capture_of(simulate("accel-centrifuge", seed=2)))
    res = run_station("diagnose", path, "--no-plots")
    assert res.returncode == 0, res.stderr
    line = " ".join(next(x for x in res.stdout.split("\ncandidates")[1:2]).split("\n  ")[0].split())
    assert "F test" in line and "degrees of freedom" in line, line
    assert "inflation > F·χ²_k" not in line, line


def test_an_ldv_record_of_a_parked_vehicle_is_refused(tmp_path):
    """P5 `f` (finish now) two seconds after the start, the vehicle still parked: the beams'
    and the reference's noise, in random directions, made a "well enough conditioned" set
    (cond 2.4) and a result of δK = -0.73 ± 0.65, NO TOLERANCE, savable as accepted. The same
    capture through `calibrate`. Now refused with the reason: the vehicle did not move."""
    import numpy as np

    from solvers.simulate import simulate
    from station.capture import write_capture
    from tests.station_run import capture_of

    cap = capture_of(simulate("ldv", seed=3))
    rng = np.random.default_rng(3)
    n = len(cap.columns["vl1"])
    for c in [c for c in cap.columns if c in ("vx", "vy", "vz", "vn", "ve", "vd", "vl1", "vl2", "vl3")]:
        cap.columns[c] = 0.01 * rng.standard_normal(n)  # parked: noise only
    path = tmp_path / "parked.csv"
    write_capture(str(path), cap)
    res = run_station("calibrate", path)
    assert_one_line_refusal(res, "parked.csv", "hardly moved", "0 of")
    # a drive is calibrated as before
    write_capture(str(tmp_path / "drive.csv"), capture_of(simulate("ldv", seed=3)))
    assert run_station("calibrate", tmp_path / "drive.csv").returncode == 0


def test_every_procedure_names_its_simulator():
    """`station simulate` lists a procedure's options from the simulator the registry names:
    each is the function solvers.simulate dispatches that procedure to."""
    import solvers.simulate
    from station.procedures import registry

    for p in registry.PROCEDURES:
        function = getattr(solvers.simulate, p.simulator)
        assert solvers.simulate._SIMULATORS[p.name] is function, p.name


def test_a_centrifuge_table_in_the_wrong_accel_unit_is_warned_about(tmp_path):
    """A P2 table in g declared `accel_unit: m/s^2` (or mg) calibrated with no word: scale factors
    of 1.25 "m/s² per g" where an accelerometer in m/s² reads 9.8 per g. Now the text warns and
    names the unit the outputs look like; the same table declared in g gets no such warning."""
    from solvers.simulate import simulate
    from station.capture import write_capture
    from tests.station_run import capture_of

    cap = capture_of(simulate("accel-centrifuge", seed=3))
    assert cap.meta["accel_unit"] == "g"
    right = tmp_path / "right.csv"
    write_capture(str(right), cap)
    for unit in ("m/s^2", "mg"):
        cap.meta["accel_unit"] = unit
        wrong = tmp_path / "wrong.csv"
        write_capture(str(wrong), cap)
        res = run_station("calibrate", wrong)
        assert res.returncode == 0, res.stderr
        line = next((x for x in res.stdout.splitlines() if "accel_unit right" in x), "")
        assert "look like g" in line, (unit, res.stdout)
    res = run_station("calibrate", right)
    assert res.returncode == 0 and "accel_unit right" not in res.stdout, res.stdout


def test_a_capture_dated_before_the_year_1000_is_stored_with_an_iso_date(tmp_path):
    """The stored time is `YYYY-MM-DDTHH:MM:SSZ`; a capture dated 0999-06-01 (a typo for 1999,
    read as the ISO date it is) was formatted '999-06-01T00:00:00Z' by strftime and the save
    failed with "station: date '999-06-01T00:00:00Z' is not an ISO 8601 date", a date the
    capture does not hold and no line. It is stored as written, with four digits."""
    from db.params import iso, parse_time

    assert iso(parse_time("0999-06-01")) == "0999-06-01T00:00:00Z"
    cap = tmp_path / "g.csv"
    assert run_station("simulate", "--procedure", "gyro-drift", "--out", cap, "--seed", "400901").returncode == 0
    text = cap.read_text(encoding="utf-8")
    cap.write_text(
        "\n".join("# date: 0999-06-01" if ln.startswith("# date:") else ln for ln in text.splitlines()) + "\n"
    )
    db = tmp_path / "s.db"
    res = run_station("calibrate", cap, "--save", "--device", "OLD-1", "--db", db)
    assert res.returncode == 0, res.stderr
    hist = run_station("history", "OLD-1", "--json", "--db", db)
    # a date alone saved on a later day: its day's last second (db.params.capture_time)
    assert hist.returncode == 0 and '"0999-06-01T23:59:59Z"' in hist.stdout, hist.stdout[:300]


def test_a_capture_without_a_procedure_says_how_to_name_one(tmp_path):
    """A capture `station record` wrote without --procedure is refused by calibrate and diagnose;
    the line said only "say which procedure", not how or which there are."""
    path = tmp_path / "rec.csv"
    rows = ["# station-capture: 1", "# device: X", "# sample_rate_hz: 100", "t,ax,ay,az"]
    rows += [f"{i / 100},0,0,9.8" for i in range(20)]
    path.write_text("\n".join(rows) + "\n")
    for command in ("calibrate", "diagnose"):
        res = run_station(command, path)
        assert_one_line_refusal(res, "no 'procedure'", "# procedure: P", "accel-tabletop", "ldv", "--procedure")
