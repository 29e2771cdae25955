"""Importers and captures as the world writes them (s28-io).

- A capture a spreadsheet saved as "Text (tab delimited)" is refused in one line at the line
  where the tabs are met, saying how to save it (the format is comma-separated:
  ../shared/spec/capture-format.md, "Comma-separated, `.` as decimal mark").
- A headerless file whose corrupt first row ends in the numbers 0 to n-2 (``abc,0,1,2,3``) under
  ``--map ax=1,...``: before, read as pandas' header of numbered columns with its index named
  'abc', --map's numbers then took other columns than the ones asked for (exit 0, a warning).

The rows are real: Wang & Li's centrifuge table and the imucal Ferraris session
(``shared/data``); the files are written by the csv module and pandas.
"""

from __future__ import annotations

import csv
import os

import numpy as np
import pytest

from tests.station_run import assert_one_line_refusal, run_station

SHARED = os.environ.get("STATION_SHARED") or os.path.join(os.path.dirname(__file__), "..", "..", "shared")
FERRARIS = os.path.join(SHARED, "data", "imucal_ferraris", "original", "example_ferraris_session.csv")
TABLE1 = os.path.join(SHARED, "data", "wang2021_centrifuge", "table1.capture.csv")
needs_shared = pytest.mark.skipif(not os.path.exists(FERRARIS), reason="../shared/data is not beside this clone")
RATE_HZ = 102.4  # imucal_ferraris/SOURCE.md


# ------------------------------------------------------------- 1. a capture saved tab-separated


def _as_spreadsheet_saves_it(src, dst, keep=lambda row: True) -> int:
    """``src`` opened as a spreadsheet opens a CSV (split at its commas) and saved as "Text (tab
    delimited)": the csv module's reader and its writer with a tab. Returns the header's line."""
    with open(src, newline="") as fh:
        rows = [r for r in csv.reader(fh) if keep(r)]
    with open(dst, "w", newline="") as fh:
        csv.writer(fh, delimiter="\t", lineterminator="\r\n").writerows(rows)
    return next(i for i, r in enumerate(rows, 1) if not r[0].startswith("#"))


@needs_shared
@pytest.mark.parametrize("command", ["calibrate", "diagnose", "inspect"])
def test_a_tab_separated_capture_is_refused_in_one_line_saying_how_to_save_it(tmp_path, command):
    """Without the table's '# source:' line (whose commas became tabs) the header is the first
    line met with tabs. Before: the line said what is wrong but not how to mend it."""
    src = tmp_path / "table1.txt"
    header_line = _as_spreadsheet_saves_it(TABLE1, src, keep=lambda r: not r[0].startswith("# source"))
    res = run_station(command, src)
    assert_one_line_refusal(
        res,
        f"{src}:{header_line}: the header's columns are separated by tabs: a capture's are separated by commas",
        "save it from the spreadsheet as 'CSV (comma delimited)'",
    )


@needs_shared
def test_a_tab_separated_capture_with_commas_in_its_metadata_is_refused_at_that_line(tmp_path):
    src = tmp_path / "table1.txt"
    _as_spreadsheet_saves_it(TABLE1, src)
    with open(TABLE1) as fh:
        at = next(i for i, line in enumerate(fh, 1) if line.startswith("# source"))
    res = run_station("calibrate", src)
    assert_one_line_refusal(res, f"{src}:{at}: metadata 'source'", "A capture is comma-separated: save the file as CSV")


# ------------------------------------------ 2. a corrupt first row is no pandas numbered header


@needs_shared
@pytest.mark.parametrize("first", ["abc,0,1,2,3", "n,0,1,2,3", "abc,0,1,2"])
@pytest.mark.parametrize("mapping", ["ax=1,ay=2,az=3", "ax=2,ay=3,az=4"])
def test_a_corrupt_first_row_ending_in_0_to_n_is_refused_on_its_line(tmp_path, first, mapping):
    """A headerless file (pandas, header=False) of the session's ax, ay, az, a counter and a
    flag, its first row corrupt. Before: read as pandas' header with its index named 'abc' and
    --map's numbers as its names: ay, az and the counter imported as ax, ay, az, exit 0."""
    import pandas as pd

    acc = pd.read_csv(FERRARIS).head(500)[["acc_x", "acc_y", "acc_z"]].to_numpy()
    n_fields = len(first.split(","))
    extra = [np.arange(len(acc)) % 7, np.ones(len(acc))][: n_fields - 3]
    src = tmp_path / "headerless.csv"
    pd.DataFrame(np.column_stack([acc, *extra])).to_csv(src, header=False, index=False)
    src.write_text(first + "\n" + src.read_text().split("\n", 1)[1])
    out = tmp_path / "out.capture.csv"
    res = run_station(
        "import", src, "--procedure", "accel-tabletop", "--out", out, "--map", mapping, "--rate", str(RATE_HZ),
        "--unit", "accel=m/s^2",
    )  # fmt: skip
    bad = first.split(",")[0]
    assert_one_line_refusal(res, f"{src}:1: field 1: '{bad}' is not a number")
    assert not out.exists()
