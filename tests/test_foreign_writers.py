"""Captures and CSV files as other people's tools write them: a spreadsheet's save, pandas and
numpy writers with their own separators and line ends, a writer killed mid-line. Each is read
correctly, or refused with one line naming the file, the line and what is wrong (exit 2,
nothing on stdout, no output file). What the older hostile-input tests already cover
(test_hostile_*.py, test_capture_variants.py, test_capture.py) is not repeated here.
"""

from __future__ import annotations

import csv
import io
import json

import pytest

from tests.station_run import run_station


@pytest.fixture(scope="module")
def gyro_capture(tmp_path_factory):
    """A short P4 capture as the station writes it, and its calibration."""
    folder = tmp_path_factory.mktemp("p4")
    path = folder / "p4.csv"
    made = run_station("simulate", "--procedure", "gyro-drift", "--out", path, "--seed", "400417")
    assert made.returncode == 0, made.stderr
    res = run_station("calibrate", path, "--json")
    assert res.returncode == 0, res.stderr
    return path, json.loads(res.stdout)


def spreadsheet_save(text: str) -> str:
    """What a spreadsheet (Excel, LibreOffice Calc) writes after opening a CSV and saving it as
    CSV: every row padded with empty cells to the widest row, CRLF line ends."""
    rows = list(csv.reader(io.StringIO(text)))
    width = max(len(r) for r in rows)
    out = io.StringIO()
    csv.writer(out, lineterminator="\r\n").writerows(r + [""] * (width - len(r)) for r in rows)
    return out.getvalue()


def test_a_capture_saved_again_by_a_spreadsheet_reads_as_the_capture(tmp_path, gyro_capture):
    """The metadata lines come back as '# device: SIM-GYR,,,,,,,' (one cell, padded to the
    table's width). Before: refused on line 1 as "unsupported capture version '1,,,,,,,'"."""
    path, result = gyro_capture
    saved = tmp_path / "saved.csv"
    saved.write_text(spreadsheet_save(path.read_text()), newline="")
    assert saved.read_text().splitlines()[0].startswith("# station-capture: 1,,")
    res = run_station("calibrate", saved, "--json")
    assert res.returncode == 0, res.stderr
    again = json.loads(res.stdout)
    assert again["params"] == result["params"]
    assert again["device"] == result["device"]
