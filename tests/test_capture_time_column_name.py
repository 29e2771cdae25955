"""A time series whose time column is not named `t` (`time`, `T`, `t_s`, `timestamp`: what
loggers and spreadsheets write). The capture format reads a capture without `t` as a table of
averages, one row per position (capture-format.md), so such a file was calibrated as 28 400
"positions" of one sample each, `station calibrate --json` printing 11 MB and exit 0, and
`--save` stored it. It is refused on its header line, naming the column and `t`.
"""

from __future__ import annotations

import pytest

from tests.station_run import assert_one_line_refusal, run_station


@pytest.fixture(scope="module")
def series(tmp_path_factory):
    path = tmp_path_factory.mktemp("series") / "p1.csv"
    res = run_station("simulate", "--procedure", "accel-tabletop", "--out", path, "--seed", "4",
                      "--option", "hold_s=3", "--option", "move_s=1")  # fmt: skip
    assert res.returncode == 0, res.stderr
    return path.read_text()


@pytest.mark.parametrize("name", ["time", "T", "t_s", "timestamp", "Time_ms"])
@pytest.mark.parametrize("command", ["calibrate", "diagnose", "inspect"])
def test_a_time_column_named_otherwise_is_refused_on_the_header_line(tmp_path, series, name, command):
    lines = series.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("t,"))
    lines[at] = name + lines[at][1:]
    path = tmp_path / "renamed.csv"
    path.write_text("\n".join(lines) + "\n")
    db = tmp_path / "station.db"
    args = ("--db", db, command, path, "--save") if command == "calibrate" else (command, path)
    res = run_station(*args)
    assert_one_line_refusal(res, f"{path}:{at + 1}: ", f"column '{name}'", "'t'", "table of averages")
    assert not db.exists()


def test_a_table_of_averages_and_a_time_series_read_as_before(tmp_path, series):
    """A table without any time column (Wang & Li's Table 1 form) and the series as written."""
    path = tmp_path / "p1.csv"
    path.write_text(series)
    assert run_station("calibrate", path).returncode == 0
    table = tmp_path / "table.csv"
    res = run_station("simulate", "--procedure", "accel-tabletop", "--out", table, "--option", "averages=1")
    assert res.returncode == 0, res.stderr
    assert run_station("calibrate", table).returncode == 0


@pytest.mark.parametrize("command", ["calibrate", "diagnose", "inspect"])
def test_a_time_series_without_its_t_column_is_refused_at_its_first_hold(tmp_path, series, command):
    """The `t` column left out altogether (a spreadsheet's column deleted): each sample was a
    position of a table of averages, 28 400 for one P1 recording. A run of 100 rows holding one
    position is a hold's samples, not a table's rows: refused on the run's first line."""
    lines = series.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("t,"))
    lines[at:] = [line.split(",", 1)[1] for line in lines[at:] if line]
    path = tmp_path / "no_t.csv"
    path.write_text("\n".join(lines) + "\n")
    first_hold = next(i for i in range(at + 1, len(lines)) if lines[i].split(",")[0])
    res = run_station(command, path)
    assert_one_line_refusal(res, f"{path}:{first_hold + 1}: ", "'x_up'", "table of averages", "'t' column")
