"""Plain CSV files an outside tester feeds `station import`, where the capture reader's own
checks do not reach: each is refused with one line naming the file and line, exit status 2,
nothing written.
"""

from __future__ import annotations

import pytest

from tests.station_run import run_station


def _one_line_refusal(res, *needles):
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    assert res.stdout == ""
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("station: "), res.stderr
    assert "cannot process this input" not in res.stderr, res.stderr
    for n in needles:
        assert n in res.stderr, res.stderr


@pytest.mark.parametrize("mapping", [("--map", "t=time_s,ax=ax,ay=ay,az=az"), ()])
def test_import_refuses_a_mapped_column_name_that_appears_twice(tmp_path, mapping):
    """Two header columns named 'ax': the first was taken without a word. Now the line of the
    header and both column numbers are named (map it by number instead)."""
    rows = ["time_s,ax,ax,ay,az"] + [f"{i * 0.01:.2f},0.01,5.0,0.02,1.0" for i in range(400)]
    if not mapping:
        rows[0] = "t,ax,ax,ay,az"
    src = tmp_path / "dup.csv"
    src.write_text("\n".join(rows) + "\n")
    out = tmp_path / "out.csv"
    res = run_station("import", src, "--procedure", "accel-tabletop", *mapping, "--unit", "accel=g,t=s", "--out", out)
    _one_line_refusal(res, f"{src}:1: ", "'ax'", "columns 2 and 3")
    assert not out.exists()
