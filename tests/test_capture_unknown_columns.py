"""A table of averages with a column the capture format does not name (QA s26).

`tmperature_C` (a misspelt `temp_c`) or `temperature` in a table was read and then used by
nothing, without a word: the operator believed the temperature was in the fit's reach. The
spec (../shared/spec/capture-format.md) keeps unknown metadata keys and ignores them, and says
nothing makes an unknown column an error, so the capture is still read and calibrated, and the
reader says the column(s) in one warning line naming the file and the header's line.

The tables are Wang & Li 2021's Table 1 as the shared data holds it (real published values),
with columns added by Python's csv module.
"""

from __future__ import annotations

import csv
import json

import pytest

from station.capture import read_capture
from tests.station_run import run_station


def _with_columns(shared_data, path, extra: dict[str, list[str]]) -> None:
    """Table 1 with ``extra`` columns appended (name -> one cell per row), via the csv module."""
    lines = (shared_data / "wang2021_centrifuge" / "table1.capture.csv").read_text().splitlines()
    meta = [line for line in lines if line.startswith("#")]
    rows = list(csv.reader(line for line in lines if not line.startswith("#")))
    with open(path, "w", newline="") as f:
        f.write("\n".join(meta) + "\n")
        w = csv.writer(f, lineterminator="\n")
        w.writerow(rows[0] + list(extra))
        for k, row in enumerate(rows[1:]):
            w.writerow(row + [cells[k] for cells in extra.values()])


@pytest.mark.parametrize(
    ("extra", "said"),
    [
        (["tmperature_C"], "column 'tmperature_C' (did you mean 'temp_c'?)"),
        (
            ["temperature", "tmp_c_std"],
            "columns 'temperature' (did you mean 'temp_c'?), 'tmp_c_std' (did you mean 'temp_c_std'?)",
        ),
    ],
)
def test_an_unknown_column_in_a_table_of_averages_is_said_and_the_table_still_read(tmp_path, shared_data, extra, said):
    src = tmp_path / "table.csv"
    n_rows = read_capture(shared_data / "wang2021_centrifuge" / "table1.capture.csv").n_rows
    _with_columns(shared_data, src, {name: [f"{24.5 + k / 10:.1f}" for k in range(n_rows)] for name in extra})
    header_line = 9  # 8 metadata lines, then the header
    res = run_station("calibrate", src, "--json")
    assert res.returncode == 0, res.stderr
    assert res.stderr == (
        f"station: {src}: warning: line {header_line}: {said} of this table of averages: "
        "no column of a capture (capture-format.md), ignored\n"
    )
    same = run_station("calibrate", shared_data / "wang2021_centrifuge" / "table1.capture.csv", "--json")
    assert json.loads(res.stdout)["params"] == json.loads(same.stdout)["params"]  # the column changes nothing
    res = run_station("inspect", src)
    assert res.returncode == 0 and res.stderr.count("\n") == 1 and said in res.stderr, res.stderr


def test_a_table_of_known_columns_and_their_std_says_nothing(tmp_path, shared_data):
    """temp_c, n, <col>_std and P2's elapsed_s are known: no warning."""
    src = tmp_path / "table.csv"
    n_rows = read_capture(shared_data / "wang2021_centrifuge" / "table1.capture.csv").n_rows
    cols = {"temp_c": "24.5", "n": "100", "ax_std": "0.001", "ay_std": "0.001", "az_std": "0.001", "elapsed_s": "1"}
    _with_columns(shared_data, src, {name: [v] * n_rows for name, v in cols.items()})
    res = run_station("calibrate", src)
    assert res.returncode == 0 and res.stderr == "", res.stderr
    assert read_capture(src).notes == []
