"""The database commands end to end: devices, history, drift, due, verify (real files, real CLI)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np
import pytest
from db_testdata import accel_result, compass_result, small_capture

from db import Store
from station.cli import main
from station.textsafe import safe
from tests.station_run import run_main as run

ROOT = Path(__file__).resolve().parents[1]
NASTY_ID = 'IMU "7"; DROP TABLE devices; -- Ω温\nsecond line'
NASTY_NOTES = 'it\'s "fine"\n\tSELECT * FROM calibrations;\nüñí 🙂'


@pytest.fixture
def filled(db):
    with Store(db) as s:
        s.add_device("IMU-1", model="ADXL355", interval_days=365, tolerances={"B[0]": 0.01})
        meta, cols = small_capture(device="IMU-1")
        for k, date in enumerate(["2024-01-01", "2024-07-01", "2025-01-01"]):
            s.save_calibration(
                accel_result(B=(0.1 + 0.01 * k, 0.2, 0.3)),
                meta=dict(meta, date=date),
                columns=cols,
                software_version="0.1.0",
            )
        s.save_calibration(
            compass_result(device="IMU-1"), meta=dict(meta, date="2024-03-01", procedure="compass"), columns=cols
        )
    return db


# --- devices ---------------------------------------------------------------------------


def test_devices_alone_lists_them(capsys, filled):
    """`station devices` as the README's command table writes it: the list, not a usage error."""
    code, out, err = run(capsys, "devices", "--db", filled)
    assert code == 0 and err == ""
    assert out == run(capsys, "devices", "list", "--db", filled)[1] and "IMU-1" in out


@pytest.mark.parametrize(
    "argv",
    [
        ("export", "IMU-1", "--format", "json"),
        ("recompute", "IMU-1"),
        ("report", "IMU-1"),
        ("export-capture", "--calibration", "IMU-1"),
    ],
)
def test_a_device_id_where_a_calibration_number_goes_is_one_line(capsys, filled, argv):
    code, out, err = _usage(capsys, *argv, "--db", filled)
    assert code == 2 and out == "" and len(err.splitlines()) == 1
    assert "'IMU-1' is not a calibration number (the # that `station history DEVICE` lists)" in err


def _usage(capsys, *argv):
    """A usage error exits through argparse (SystemExit 2) before any handler runs."""
    with pytest.raises(SystemExit) as exc:
        main(list(argv))
    out = capsys.readouterr()
    return exc.value.code, out.out, out.err


def test_devices_add_list_show(capsys, db):
    code, out, _ = run(
        capsys,
        "devices",
        "add",
        "IMU-2",
        "--model",
        "BMI088",
        "--interval-days",
        "90",
        "--notes",
        "rack B",
        "--tolerance",
        "B=0.05",
        "--tolerance",
        "M[0][0]=0.001",
        "--db",
        db,
    )
    assert code == 0 and out == "added device IMU-2\n"
    code, out, _ = run(capsys, "devices", "add", "IMU-2", "--notes", "rack C", "--db", db)
    assert code == 0 and out == "updated device IMU-2\n"
    code, out, _ = run(capsys, "devices", "list", "--db", db)
    assert code == 0 and "IMU-2" in out and "BMI088" in out and "rack C" in out
    code, out, _ = run(capsys, "devices", "show", "IMU-2", "--json", "--db", db)
    d = json.loads(out)
    assert d["interval_days"] == 90 and d["tolerances"] == {"B": 0.05, "M[0][0]": 0.001} and d["notes"] == "rack C"
    code, out, _ = run(capsys, "devices", "list", "--json", "--db", db)
    assert [x["id"] for x in json.loads(out)] == ["IMU-2"]


def test_db_option_before_the_action_and_env(capsys, db, monkeypatch):
    assert run(capsys, "devices", "--db", db, "add", "A")[0] == 0
    assert run(capsys, "--db", db, "devices", "add", "B")[0] == 0
    monkeypatch.setenv("STATION_DB", db)
    code, out, _ = run(capsys, "devices", "list", "--json")
    assert [x["id"] for x in json.loads(out)] == ["A", "B"]


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["devices", "add", "X", "--tolerance", "B"], "--tolerance 'B'"),
        (["devices", "add", "X", "--tolerance", "B=-1"], "positive"),
        (["devices", "add", "X", "--interval-days", "0"], "--interval-days must be positive"),
        # no date lies that far: was the catch-all 'cannot process this input (OverflowError ...)'
        (["devices", "add", "X", "--interval-days", "inf"], "at most 36525 (100 years), got inf"),
        (["devices", "add", "X", "--interval-days", "1e308"], "at most 36525 (100 years), got 1e+308"),
        # an id beyond SQLite's INTEGER names no record (was the catch-all, OverflowError)
        (["export", "99999999999999999999", "--format", "json"], "no calibration 99999999999999999999"),
        (["report", "99999999999999999999"], "no calibration 99999999999999999999"),
        (["recompute", "99999999999999999999"], "no calibration 99999999999999999999"),
        (["export-capture", "99999999999999999999"], "no capture 99999999999999999999"),
        (["devices", "add", " "], "non-empty"),
        (["devices", "show", "nope"], 'no device "nope"'),
        (["history", "nope"], 'no device "nope"'),
        (["drift", "nope"], 'no device "nope"'),
        (["due", "--within", "-3"], "--within must not be negative"),
        # was "cannot convert float NaN to integer" and the catch-all OverflowError
        (["due", "--within", "nan"], "--within must be at most 36525 days (100 years), got nan"),
        (["due", "--within", "1e400"], "--within must be at most 36525 days (100 years), got inf"),
        (["due", "--within", "1e6"], "--within must be at most 36525 days (100 years), got 1e+06"),
    ],
)
def test_bad_input_one_line_exit_2(capsys, db, argv, needle):
    Store(db).close()  # an empty database: the refusal is about the argument, not a missing file
    code, out, err = run(capsys, *argv, "--db", db)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and needle in err and "Traceback" not in err


@pytest.mark.parametrize(
    "argv",
    [
        ["history", "IMU-1"],
        ["due"],
        ["devices", "add", "IMU-1"],  # a command that creates the database
        ["calibrate", "CAPTURE", "--save"],  # so does a save
        ["demo", "--headless"],  # and the scripted operator's run
        ["tui"],  # and the TUI's first save: refused before the screen is drawn
        ["report", "1", "-o", "OUT"],
    ],
)
def test_a_given_database_path_in_a_missing_folder_is_refused_and_nothing_made(capsys, tmp_path, argv, monkeypatch):
    """A mistyped --db or $STATION_DB in a folder that does not exist made that folder and a new
    empty database in it (devices add, calibrate --save, the TUI and the demo): now one line
    naming the path and its missing folder, exit 2, nothing written. Only the default location
    (XDG) gets its folder made."""
    capture = tmp_path / "p1.csv"
    if "CAPTURE" in argv:
        made = run(capsys, "simulate", "--procedure", "accel-tabletop", "--option", "averages=1", "--out", capture)
        assert made[0] == 0, made[2]
    argv = [str(capture) if a == "CAPTURE" else str(tmp_path / "r.html") if a == "OUT" else a for a in argv]
    before = sorted(tmp_path.rglob("*"))
    missing = tmp_path / "nosuchdir"
    for how in ("--db", "$STATION_DB"):
        db = missing / f"x{how[-2:]}.db"
        if how == "--db":
            monkeypatch.delenv("STATION_DB", raising=False)
            code, out, err = run(capsys, "--db", db, *argv)
        else:
            monkeypatch.setenv("STATION_DB", str(db))
            code, out, err = run(capsys, *argv)
        assert code == 2 and out == "", (how, code, out, err)
        said = f"no station database here: the folder {missing} does not exist (mistyped {how}?); nothing created"
        assert err == f"station: {db}: {said}\n"
        assert sorted(tmp_path.rglob("*")) == before  # no folder, no database, no report


def test_the_default_database_location_gets_its_folder(capsys, tmp_path, monkeypatch):
    """The built-in default, ${XDG_DATA_HOME}/station/station.db, is made with its folder by the
    first command that creates a database (a new machine has no station folder yet)."""
    monkeypatch.delenv("STATION_DB", raising=False)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    code, _, err = run(capsys, "devices", "add", "IMU-1")
    assert code == 0, err
    assert (tmp_path / "xdg" / "station" / "station.db").is_file()
    # a path given in a folder that exists is made as before
    code, _, err = run(capsys, "--db", tmp_path / "bench.db", "devices", "add", "IMU-1")
    assert code == 0 and (tmp_path / "bench.db").is_file(), err


def test_no_database_yet_names_what_named_the_path(capsys, tmp_path, monkeypatch):
    """A reading command with no database said "(mistyped --db or $STATION_DB?)" also where
    neither was given (the default location on a new machine): it names the one that was given,
    and the default as the default."""
    monkeypatch.delenv("STATION_DB", raising=False)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    default = tmp_path / "xdg" / "station" / "station.db"
    code, out, err = run(capsys, "history", "IMU-1")
    assert code == 2 and out == "", err
    assert err.startswith(f"station: {default}: no station database here (the default database, none made yet); "), err
    code, out, err = run(capsys, "--db", tmp_path / "nope.db", "history", "IMU-1")
    assert code == 2 and "(mistyped --db?)" in err, err
    monkeypatch.setenv("STATION_DB", str(tmp_path / "nope.db"))
    code, out, err = run(capsys, "history", "IMU-1")
    assert code == 2 and "(mistyped $STATION_DB?)" in err, err
    assert not default.exists() and not (tmp_path / "nope.db").exists()


def test_unusable_database_file_is_one_line(capsys, tmp_path):
    bad = tmp_path / "not-a-db"
    bad.write_text("hello, I am a text file, not SQLite\n" * 100)
    code, _, err = run(capsys, "devices", "list", "--db", str(bad))
    assert code == 2 and err.count("\n") == 1 and "cannot open the station database" in err


def test_nasty_id_and_notes_stored_verbatim_shown_with_control_characters_escaped(capsys, db):
    assert run(capsys, "devices", "add", NASTY_ID, "--notes", NASTY_NOTES, "--model", "m'x", "--db", db)[0] == 0
    code, out, _ = run(capsys, "devices", "show", NASTY_ID, "--db", db)
    # quotes, SQL and Unicode as they are; the newline and tab escaped so they cannot forge rows
    assert code == 0 and f"device: {safe(NASTY_ID)}\n" in out and f"notes: {safe(NASTY_NOTES)}\n" in out
    assert "\\nsecond line" in out and "\nsecond line" not in out
    code, out, _ = run(capsys, "devices", "list", "--db", db)
    assert safe(NASTY_ID) in out and safe(NASTY_NOTES) in out and len(out.splitlines()) == 2
    code, out, _ = run(capsys, "devices", "list", "--json", "--db", db)
    assert json.loads(out)[0]["id"] == NASTY_ID and json.loads(out)[0]["notes"] == NASTY_NOTES
    with Store(db) as s:
        meta, cols = small_capture(device=NASTY_ID)
        s.save_calibration(accel_result(device=NASTY_ID), meta=meta, columns=cols)
    code, out, _ = run(capsys, "history", NASTY_ID, "--db", db)
    assert code == 0 and out.startswith(f"device {safe(NASTY_ID)}: 1 calibration")
    code, out, _ = run(capsys, "history", NASTY_ID, "--json", "--db", db)
    assert json.loads(out)[0]["device_id"] == NASTY_ID


def test_nasty_id_verbatim_through_a_real_process(db):
    env = dict(os.environ, STATION_DB=db, PYTHONIOENCODING="utf-8")
    add = subprocess.run(
        [sys.executable, "-m", "station", "devices", "add", NASTY_ID, "--notes", NASTY_NOTES],
        cwd=ROOT,
        env=env,
        capture_output=True,
    )
    assert add.returncode == 0, add.stderr
    show = subprocess.run(
        [sys.executable, "-m", "station", "devices", "show", NASTY_ID], cwd=ROOT, env=env, capture_output=True
    )
    assert show.returncode == 0
    text = show.stdout.decode("utf-8")
    assert f"device: {safe(NASTY_ID)}\n" in text and f"notes: {safe(NASTY_NOTES)}\n" in text


# --- history ---------------------------------------------------------------------------


def test_history_json_oldest_first_with_required_fields(capsys, filled):
    code, out, _ = run(capsys, "history", "IMU-1", "--json", "--db", filled)
    records = json.loads(out)
    assert code == 0 and [r["time"][:10] for r in records] == ["2024-01-01", "2024-03-01", "2024-07-01", "2025-01-01"]
    for r in records:
        assert {"id", "time", "procedure", "params", "uncertainty"} <= set(r)
    assert records[0]["params"]["B"] == [0.1, 0.2, 0.3]
    code, out, _ = run(capsys, "history", "IMU-1", "--procedure", "compass", "--json", "--db", filled)
    assert [r["procedure"] for r in json.loads(out)] == ["compass"]


def test_history_text(capsys, filled):
    code, out, _ = run(capsys, "history", "IMU-1", "--procedure", "accel-tabletop", "--db", filled)
    lines = out.splitlines()
    assert code == 0 and lines[0] == "device IMU-1: 3 calibrations of accel-tabletop, oldest first"
    # a date alone, saved on a later day: its date's last second (db.params.capture_time)
    assert "2024-01-01T23:59:59Z  accel-tabletop  accepted, superseded by #2" in lines[1]
    assert lines[2].strip().startswith("B [m/s^2]: 0.1±0.01  0.2±0.01  0.3±0.01")


# --- drift -----------------------------------------------------------------------------


def test_drift_json_and_text_with_plot(capsys, filled):
    code, out, _ = run(capsys, "drift", "IMU-1", "--param", "B[0]", "--json", "--db", filled)
    [t] = json.loads(out)
    # 0.01 per half year: 0.02/year (2024-01-01 -> 2024-07-01 is 182 d, -> 2025-01-01 is 366 d)
    days = [0, 182, 366]
    years = [d / 365.25 for d in days]
    ym = sum(years) / 3
    rate = sum((y - ym) * (0.1 + 0.01 * k) for k, y in enumerate(years)) / sum((y - ym) ** 2 for y in years)
    assert t["rate_per_year"] == pytest.approx(rate, rel=1e-9) and t["param"] == "B[0]"
    # 0.02/year against sigmas of 0.01: rate sigma 0.01 / sqrt(sum (y - ym)^2), 1.4 sigma, not a drift to schedule by
    rate_sigma = 0.01 / sum((y - ym) ** 2 for y in years) ** 0.5
    assert t["rate_sigma_per_year"] == pytest.approx(rate_sigma, rel=1e-9)
    assert t["significance_sigmas"] == pytest.approx(rate / rate_sigma, rel=1e-9) and not t["significant"]
    assert t["tolerance"] == 0.01 and t["leaves_tolerance"] is None
    code, out, _ = run(capsys, "drift", "IMU-1", "--param", "B", "--db", filled)
    assert code == 0
    assert "accel-tabletop  B[0]" in out and "RATE/YEAR" in out
    assert "plot" in out and "year" in out  # the plotext figure follows the table
    assert "\x1b[" not in out  # no colour codes when not a terminal
    code, _, err = run(capsys, "drift", "IMU-1", "--param", "Q[9]", "--db", filled)
    assert code == 2 and "no coefficient named 'Q[9]'" in err


@pytest.mark.parametrize("json_flag", [[], ["--json"]])
def test_drift_of_an_empty_param_name_is_refused(capsys, filled, json_flag):
    """--param '' (an unset shell variable) said 'no accepted calibrations yet' (or printed [])
    with exit 0 about a device that has three; an empty name is no coefficient."""
    code, out, err = run(capsys, "drift", "IMU-1", "--param", "", *json_flag, "--db", filled)
    assert code == 2 and out == "" and err.count("\n") == 1 and "no coefficient named ''" in err


# --- due -------------------------------------------------------------------------------


def test_due_exit_status_for_cron(capsys, filled):
    # IMU-1 last accel calibration 2025-01-01 with a 365-day interval; its compass one 2024-03-01
    code, out, _ = run(capsys, "due", "--now", "2024-02-01", "--db", filled)
    assert code == 0 and out == "nothing due\n"
    # compass interval ends 2025-03-01; B[0]'s 0.02/year against a 0.01 tolerance is 1.4 sigma, not a
    # drift: accel due at its interval's end, 2026-01-01
    code, out, _ = run(capsys, "due", "--now", "2025-03-20", "--db", filled)
    # due at the end of 2025-03-01 (the compass capture's date alone is that day's last second)
    assert code == 1 and out.startswith("IMU-1: overdue by 18 d (due 2025-03-01)")
    assert "compass: 365-day interval" in out and "accel-tabletop" not in out
    code, out, _ = run(capsys, "due", "--now", "2025-08-01", "--json", "--db", filled)
    [e] = json.loads(out)
    assert code == 1 and e["device_id"] == "IMU-1" and e["status"] == "overdue"
    assert {r["procedure"]: r["kind"] for r in e["reasons"]} == {"compass": "interval"}
    code, out, _ = run(capsys, "due", "--now", "2026-01-02", "--json", "--db", filled)
    [e] = json.loads(out)
    [accel] = [r for r in e["reasons"] if r["procedure"] == "accel-tabletop"]
    assert accel["kind"] == "interval" and accel["due"] == "2026-01-01T23:59:59Z"
    assert "no significant drift over 3 calibrations (steepest B[0] +0.02 ± 0.014/year, 1.4σ < 3σ)" in accel["text"]
    assert run(capsys, "due", "--now", "2025-02-01", "--within", "20", "--db", filled)[0] == 0
    code, out, _ = run(capsys, "due", "--now", "2025-02-01", "--within", "40", "--db", filled)
    assert code == 1 and out.startswith("IMU-1: due in 29 d (2025-03-01)")


def test_due_real_process_exit_codes(tmp_path):
    db = str(tmp_path / "station.db")
    env = dict(os.environ, STATION_DB=db)
    missing = subprocess.run(
        [sys.executable, "-m", "station", "due"], cwd=ROOT, env=env, capture_output=True, text=True
    )
    assert missing.returncode == 2 and missing.stdout == "" and "no station database" in missing.stderr
    assert not os.path.exists(db)  # a mistyped path is not created
    Store(db).close()
    quiet = subprocess.run([sys.executable, "-m", "station", "due"], cwd=ROOT, env=env, capture_output=True, text=True)
    assert quiet.returncode == 0 and quiet.stdout == "nothing due\n"
    now = datetime.now(UTC)
    with Store(db) as s:
        s.add_device("OLD", interval_days=30)
        meta, cols = small_capture(device="OLD")
        s.save_calibration(accel_result(device="OLD"), meta=meta, columns=cols, time=now - timedelta(days=45))
    loud = subprocess.run([sys.executable, "-m", "station", "due"], cwd=ROOT, env=env, capture_output=True, text=True)
    assert loud.returncode == 1 and loud.stdout.startswith("OLD: overdue by 15 d")


def test_due_names_calibrated_devices_that_have_no_interval(capsys, db):
    """A device the TUI registered and calibrated has no interval: `station due` said only
    "nothing due", and the bench engineer expected a reminder that can never come. The
    devices that are never due are named on stderr with the way to set one; stdout, which
    cron reads, stays "nothing due"."""
    with Store(db) as s:
        s.add_device("SIM-ACC-0000")
        s.add_device("IMU-1", interval_days=365)
        for dev in ("SIM-ACC-0000", "IMU-1"):
            meta, cols = small_capture(device=dev)
            s.save_calibration(accel_result(dev), meta=meta, columns=cols)
    code, out, err = run(capsys, "due", "--db", db)
    assert code == 0 and out == "nothing due\n"
    assert err.count("\n") == 1 and "SIM-ACC-0000" in err and "IMU-1" not in err
    assert "--interval-days" in err
    code, out, err = run(capsys, "due", "--json", "--db", db)
    assert code == 0 and json.loads(out) == [] and err == ""


def test_drift_on_an_80_column_terminal_fits_with_every_figure_and_unit(db):
    """On an 80-column terminal (the bench over SSH) `station drift` printed one table 107+
    columns wide that the terminal wrapped mid-row; there it is one small table per procedure
    and unit under a heading naming both, every figure of the pipe's table in its row (a row
    still too wide breaks between cells), and into a pipe one line per coefficient as before."""
    import re

    from tests.test_terminal_safety import _pty_run

    rng = np.random.default_rng(400117)
    with Store(db) as s:
        # B in m/s^2 drifting past its tolerance (a LEAVES date), M per V, a compass whose
        # reference block has the longest names, one of them with a tolerance too
        s.add_device("IMU-80", interval_days=365, tolerances={"B": 0.02, "reference.declination_deg": 0.5})
        meta, cols = small_capture(device="IMU-80")
        for k, day in enumerate((0, 60, 120, 180)):
            B = [0.1 + 0.25 * day / 365.25, -0.2, 0.3] + rng.normal(0.0, 0.005, 3)
            when = (datetime(2025, 1, 6, tzinfo=UTC) + timedelta(days=day)).strftime("%Y-%m-%dT%H:%M:%SZ")
            s.save_calibration(
                accel_result(device="IMU-80", B=B), meta=meta, columns=cols, time=when, allow_duplicate=True
            )
            s.save_calibration(
                compass_result(device="IMU-80", hard_iron=(10.0 + k, -5.0, 2.0)),
                meta=dict(meta, procedure="compass"),
                columns=cols,
                time=when,
                allow_duplicate=True,
            )
    pipe = subprocess.run(
        [sys.executable, "-m", "station", "drift", "IMU-80", "--no-plot", "--db", db],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert pipe.returncode == 0, pipe.stderr
    rows = [re.split(r"\s{2,}", x.strip()) for x in pipe.stdout.splitlines() if x.startswith(("accel", "compass"))]
    assert len(rows) == 12 + 9 + 3 + 6 and all(len(r) == 10 for r in rows), pipe.stdout
    assert max(len(x) for x in pipe.stdout.splitlines()) > 80  # the defect's setting
    assert any(re.fullmatch(r"\d{4}-\d\d-\d\d", r[9]) for r in rows)  # B[0] leaves its tolerance

    env = {**os.environ, "COLUMNS": "80", "LINES": "24", "NO_COLOR": "1"}
    rc, out = _pty_run("drift", "IMU-80", "--db", db, env=env)
    text = out.decode("utf-8")
    lines = text.splitlines()
    assert rc == 0, text
    assert max(len(x) for x in lines) <= 80, max(lines, key=len)
    table = lines[: next(i for i, x in enumerate(lines) if x.startswith("plot"))]
    for proc, param, unit, *figures in rows:
        heading = table.index(
            f"{proc} [{unit}]"
            + ("" if any(r[8] != "-" for r in rows if r[:3:2] == [proc, unit]) else ", no tolerances set")
        )
        i = next(k for k in range(heading + 2, len(table)) if table[k].split()[:1] == [param])
        cells = re.split(r"\s{2,}", table[i].strip())
        for more in table[i + 1 :]:  # figures on the name's next line (or a row broken between cells), indented 6
            if not more.startswith("      "):
                break
            cells += re.split(r"\s{2,}", more.strip())
        with_tolerance = any("LEAVES" in x for x in table[heading + 1 : i])
        assert cells == [param, *(figures if with_tolerance else figures[:5])], (param, cells, figures)


def test_a_capture_dated_in_the_future_is_not_saved(tmp_path):
    """A capture dated 2062 (a typo for 2026) was saved as accepted and its device was not due
    until 2062: `station due --within 365` said "nothing due". A calibration's time is when the
    data were measured: more than a day ahead of now is refused in one line, exit 2, nothing
    stored; a date-only capture of today east of UTC (tomorrow's date in UTC+14) still saves."""
    from station.capture import read_capture, write_capture
    from tests.station_run import run_station

    db = tmp_path / "s.db"
    path = tmp_path / "p1.csv"
    assert run_station("simulate", "--procedure", "accel-tabletop", "--seed", "400321", "--out", path).returncode == 0
    assert run_station("devices", "add", "SIM-ACC-400321", "--interval-days", "30", "--db", db).returncode == 0
    cap = read_capture(path)
    cap.meta["date"] = "2062-11-21"
    write_capture(path, cap)
    res = run_station("calibrate", path, "--save", "--db", db)
    assert res.returncode == 2 and res.stdout == "" and res.stderr.count("\n") == 1, res.stderr
    assert "2062-11-21" in res.stderr and "in the future" in res.stderr
    assert json.loads(run_station("history", "SIM-ACC-400321", "--json", "--db", db).stdout) == []
    cap.meta["date"] = (datetime.now(UTC) + timedelta(hours=14)).strftime("%Y-%m-%d")
    write_capture(path, cap)
    res = run_station("calibrate", path, "--save", "--db", db)
    assert res.returncode == 0, res.stderr


def test_a_calibration_saved_to_a_device_registered_for_another_sensor_is_said(tmp_path):
    """`calibrate --save --device ACC-1` of a compass capture, ACC-1 registered as an
    accelerometer (`devices add --kind accel`), added mag to its kinds without a word: a
    mistyped --device put the compass into another unit's history unnoticed. It is still saved
    (a unit may carry several sensors: the README says so), with a warning on stderr naming the
    device, its kinds and the one added; stdout stays the result. A device registered with that
    kind, or with none (the TUI registers devices so), gets no warning."""
    from tests.station_run import run_station

    db, path = tmp_path / "s.db", tmp_path / "mag.csv"
    assert run_station("simulate", "--procedure", "compass", "--seed", "400322", "--out", path).returncode == 0
    for device, kinds in (("ACC-1", ["accel"]), ("MAG-1", ["mag", "accel"]), ("NEW-1", [])):
        args = [a for k in kinds for a in ("--kind", k)]
        assert run_station("devices", "add", device, *args, "--db", db).returncode == 0
    res = run_station("calibrate", path, "--save", "--device", "ACC-1", "--json", "--db", db)
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["calibration_id"] == 1  # stdout: the result alone
    warning = [line for line in res.stderr.splitlines() if "warning" in line]
    assert len(warning) == 1, res.stderr
    assert "device ACC-1 was registered for accel, not mag" in warning[0] and "--device" in warning[0]
    shown = json.loads(run_station("devices", "show", "ACC-1", "--json", "--db", db).stdout)
    assert shown["sensor_kinds"] == ["accel", "mag"]
    for i, device in enumerate(("MAG-1", "NEW-1")):
        cap = tmp_path / f"mag{i}.csv"
        assert (
            run_station("simulate", "--procedure", "compass", "--seed", str(400323 + i), "--out", cap).returncode == 0
        )
        res = run_station("calibrate", cap, "--save", "--device", device, "--db", db)
        assert res.returncode == 0 and "warning" not in res.stderr, res.stderr


def test_devices_add_kind_that_drops_a_kind_says_so(capsys, db):
    """`devices add ID --kind K` gives the whole list (README): `--kind mag` on a device
    registered as an accelerometer replaced accel by mag without a word. It still does (what
    the command table documents), and says which kinds are gone and how to keep them."""
    assert run(capsys, "devices", "add", "ACC-1", "--kind", "accel", "--db", db)[0] == 0
    code, out, err = run(capsys, "devices", "add", "ACC-1", "--kind", "mag", "--db", db)
    assert code == 0 and out == "updated device ACC-1\n"
    assert err.count("\n") == 1 and "sensor kinds are now mag, no longer accel" in err, err
    assert "--kind mag --kind accel" in err
    code, out, err = run(capsys, "devices", "add", "ACC-1", "--kind", "mag", "--kind", "accel", "--db", db)
    assert code == 0 and err == ""  # adding one drops none: nothing to say
    code, out, err = run(capsys, "devices", "add", "ACC-1", "--model", "ICM-20948", "--db", db)
    assert code == 0 and err == ""  # no --kind: the kinds stay
    assert json.loads(run(capsys, "devices", "show", "ACC-1", "--json", "--db", db)[1])["sensor_kinds"] == [
        "mag",
        "accel",
    ]


NOBODY = 65534


def _as_nobody(*argv, cwd):
    """``python -m station ARGV`` as user nobody (a root test run sees permissions only so)."""

    def drop():
        os.setgroups([])
        os.setgid(NOBODY)
        os.setuid(NOBODY)

    env = {k: v for k, v in os.environ.items() if k != "STATION_DB"}
    return subprocess.run(
        [sys.executable, *argv], cwd=cwd, env=env, preexec_fn=drop, capture_output=True, text=True, timeout=120
    )


def test_a_database_in_a_folder_this_user_cannot_write_says_so(tmp_path, capsys):
    """Every database command failed with "cannot open the station database: unable to open
    database file" (or "attempt to write a readonly database") on a database whose folder is
    read-only: SQLite makes the -wal and -shm files beside it, to read it too. The line now says
    the folder is not writable. Permissions bind a user other than root: run as root (a
    container's CI), the commands run as user nobody on a folder root owns (mode 755)."""
    import shutil
    import stat
    import tempfile

    if os.geteuid() != 0:
        folder = tmp_path / "ro"
        folder.mkdir()
        db = folder / "s.db"
        assert run(capsys, "devices", "add", "IMU-1", "--kind", "accel", "--db", str(db))[0] == 0
        folder.chmod(stat.S_IRUSR | stat.S_IXUSR)
        try:
            results = [run(capsys, *argv, "--db", str(db)) for argv in (("devices", "list"), ("due",))]
            results.append(run(capsys, "devices", "add", "X", "--db", str(folder / "new.db")))
        finally:
            folder.chmod(stat.S_IRWXU)
    else:
        folder = Path(tempfile.mkdtemp(prefix="station-ro-"))  # under the system's temporary folder: nobody reaches it
        try:
            folder.chmod(0o755)
            db = folder / "s.db"
            with Store(str(db)) as s:
                s.add_device("IMU-1", sensor_kinds=["accel"])
            db.chmod(0o666)  # the file is writable: only the folder is not
            probe = _as_nobody("-c", "import station.cli", cwd=folder)
            if probe.returncode != 0:
                pytest.skip(f"run as root, and user nobody cannot load the station here: {probe.stderr.strip()[-200:]}")
            results = [
                (r.returncode, r.stdout, r.stderr)
                for r in (
                    _as_nobody("-m", "station", "devices", "list", "--db", str(db), cwd=folder),
                    _as_nobody("-m", "station", "due", "--db", str(db), cwd=folder),
                    _as_nobody("-m", "station", "devices", "add", "X", "--db", str(folder / "new.db"), cwd=folder),
                )
            ]
        finally:
            shutil.rmtree(folder, ignore_errors=True)
    for code, out, err in results:
        assert code == 2 and out == "" and err.count("\n") == 1, err
        assert f"the folder {folder} is not writable" in err and "-wal and -shm" in err, err


def test_devices_show_says_when_the_device_falls_due(capsys, db):
    """`devices show` gave the interval but no date: the next due date was said only by `due`,
    and only within its window (`--within`), so a device due in a year had none anywhere;
    a calibrated device without an interval (the TUI registers them so) is never due."""
    now = datetime.now(UTC)
    with Store(db) as s:
        meta, cols = small_capture(device="IMU-1")
        ten_days_ago = (now - timedelta(days=10)).strftime("%Y-%m-%dT%H:%M:%SZ")
        s.save_calibration(accel_result(), meta=dict(meta, date=ten_days_ago), columns=cols)
        s.add_device("NEW-1", interval_days=30)

    def due_line(device):
        code, out, err = run(capsys, "devices", "show", device, "--db", db)
        assert code == 0, err
        return next(line for line in out.splitlines() if line.startswith("due: "))

    assert due_line("IMU-1") == "due: never (no recalibration interval: station devices add ID --interval-days N)"
    assert due_line("NEW-1") == "due: never calibrated"
    assert run(capsys, "devices", "add", "IMU-1", "--interval-days", "365", "--db", db)[0] == 0
    when = (now - timedelta(days=10) + timedelta(days=365)).date().isoformat()
    assert due_line("IMU-1") == f"due: in 355 d ({when})"
    code, out, _ = run(capsys, "due", "--db", db)  # outside `due`'s window: not listed there
    assert "IMU-1" not in out
