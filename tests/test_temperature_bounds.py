"""A temperature column that no thermometer can have read: below absolute zero, or hotter than
any sensor survives. Before, `temp_c` had no bound but the generic 1e20: a capture whose
temperature read -300 °C was calibrated and saved as accepted, and `diagnose` fitted a
temperature bias to it. Now the reader refuses it on its line, as it refuses an acceleration
no accelerometer reports (README: numbers no instrument produces). An outside tester's finding
(branch qa-s24b)."""

from __future__ import annotations

import sqlite3

import pytest

from station.capture import read_capture
from tests.station_run import assert_one_line_refusal, run_station


def _table(tmp_path, temps: list[str]):
    """A P1 table of averages (12 positions, simulated) with ``temps`` as its temp_c column."""
    src = tmp_path / "p1.csv"
    res = run_station(
        "simulate", "--procedure", "accel-tabletop", "--out", src, "--seed", "5", "--option", "averages=1"
    )
    assert res.returncode == 0, res.stderr
    lines = src.read_text().splitlines()
    h = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    k = lines[h].split(",").index("temp_c")
    for i, temp in zip(range(h + 1, len(lines)), temps):
        cells = lines[i].split(",")
        cells[k] = temp
        lines[i] = ",".join(cells)
    out = tmp_path / "temps.csv"
    out.write_text("\n".join(lines) + "\n")
    return out, h + 2  # the file and the line number of its first data row (h: the header, 0-based)


@pytest.mark.parametrize(
    ("bad", "says"),
    [
        ("-300", "-300 °C is below absolute zero (-273.15 °C)"),
        ("-273.5", "-273.5 °C is below absolute zero (-273.15 °C)"),
        ("20000", "20000 °C is beyond what any thermometer on a sensor reports"),
    ],
)
@pytest.mark.parametrize("command", ["calibrate", "diagnose"])
def test_a_temperature_no_thermometer_reads_is_refused_on_its_line(tmp_path, bad, says, command):
    temps = ["24.5"] * 12
    temps[3] = bad
    capture, first = _table(tmp_path, temps)
    db = tmp_path / "station.db"
    assert run_station("--db", db, "devices", "add", "BENCH-1").returncode == 0
    with sqlite3.connect(db) as con:
        before = con.execute("select count(*) from calibrations").fetchone()[0]
    extra = ("--save", "--db", db) if command == "calibrate" else ()
    res = run_station(command, capture, "--json", *extra)
    assert_one_line_refusal(res, f"{capture}:{first + 3}: column 'temp_c': {says}")
    with sqlite3.connect(db) as con:
        assert con.execute("select count(*) from calibrations").fetchone()[0] == before


def test_the_bounds_themselves_and_a_cold_or_hot_bench_read(tmp_path):
    """Absolute zero itself, a cold chamber at -55 °C and a soak at 125 °C (the military range
    of parts) are temperatures; so is an empty cell."""
    temps = ["-273.15", "-55", "125", "", "10000"] + ["24.5"] * 7
    capture, _ = _table(tmp_path, temps)
    got = read_capture(capture).columns["temp_c"]
    assert got[0] == -273.15 and got[1] == -55 and got[2] == 125 and got[4] == 10000


def test_an_imported_temperature_no_thermometer_reads_is_left_empty_with_a_warning(tmp_path):
    """A plain CSV (or a log) whose temperature field holds a driver's 'no reading' value:
    the IMU samples are kept, those temperature cells are left empty and counted in a warning."""
    rows = ["time_s,ax,ay,az,temp"] + [f"{i * 0.01:.2f},0.1,-0.2,9.8,{-300 if i == 7 else 24.5}" for i in range(200)]
    src = tmp_path / "bench.csv"
    src.write_text("\n".join(rows) + "\n")
    out = tmp_path / "bench.capture.csv"
    res = run_station(
        "import", src, "--procedure", "accel-tabletop", "--map", "t=time_s,ax=ax,ay=ay,az=az,temp_c=temp",
        "--unit", "accel=m/s^2,t=s", "--out", out,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "1 temperature sample below absolute zero or above 10000 °C (the first -300): left empty" in res.stderr
    temp = read_capture(out).columns["temp_c"]
    assert len(temp) == 200 and temp[7] != temp[7] and (temp[:7] == 24.5).all()
