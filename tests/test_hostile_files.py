"""Hostile files an outside tester feeds the commands that take a file, where the
capture reader's own checks (tests/test_cli_errors.py, tests/test_hostile_numeric.py,
tests/fuzzkit.py) do not reach: the plain-CSV importer, `station noise`, logs that warn and
then fail. Each one: one line on stderr naming the file (and line), exit status 2, nothing on
stdout, nothing written.
"""

from __future__ import annotations

import resource
import subprocess
import sys

import pytest

from tests.station_run import ROOT, run_station

SMALL = "\n".join(["time_s,gx,gy,gz"] + [f"{i * 0.01:.2f},0.01,0.02,-0.01" for i in range(400)]) + "\n"
IMPORT = ("--procedure", "gyro-drift", "--map", "t=time_s,gx=gx,gy=gy,gz=gz", "--unit", "gyro=rad/s,t=s")


def _one_line_refusal(res, *needles):
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    assert res.stdout == ""
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("station: "), res.stderr
    assert "cannot process this input" not in res.stderr, res.stderr
    for n in needles:
        assert n in res.stderr, res.stderr


def _limit_memory():  # the child's address space: far above what a 1 MB CSV needs, far below "all of it"
    resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))


def test_import_of_an_endless_stream_of_nul_bytes_stops_at_once(tmp_path):
    """`/dev/zero` as a CSV: read whole before any check, it filled the memory (6 GB in
    seconds); now the first block's NUL byte refuses it."""
    out = tmp_path / "out.csv"
    res = subprocess.run(
        [sys.executable, "-m", "station", "import", "/dev/zero", *IMPORT, "--out", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=_limit_memory,
    )
    _one_line_refusal(res, "/dev/zero:1:", "NUL byte")
    assert not out.exists()


def test_import_of_a_file_without_line_ends_is_refused_by_line_length(tmp_path):
    src = tmp_path / "one_line.csv"
    src.write_bytes(b"time_s,gx,gy,gz," + b"7" * (3 << 20))
    out = tmp_path / "out.csv"
    _one_line_refusal(run_station("import", src, *IMPORT, "--out", out), f"{src}:1:", "line longer than")
    assert not out.exists()


def test_import_of_a_field_over_the_csv_modules_limit_names_the_line(tmp_path):
    """A 500 kB field: within the line limit, over the csv module's 128 kB field limit (its
    csv.Error reached the CLI's last-resort message)."""
    src = tmp_path / "long_field.csv"
    lines = SMALL.splitlines()
    lines[7] = lines[7] + "9" * 500_000
    src.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out.csv"
    _one_line_refusal(run_station("import", src, *IMPORT, "--out", out), f"{src}:8:", "field larger than field limit")
    assert not out.exists()


@pytest.mark.parametrize("where", ["first", "late"])
def test_import_nul_byte_is_named_by_its_line(tmp_path, where):
    lines = SMALL.splitlines()
    k = 1 if where == "first" else 350
    lines[k] = lines[k].replace("0.02", "0.0\0")
    src = tmp_path / "nul.csv"
    src.write_text("\n".join(lines) + "\n")
    _one_line_refusal(run_station("import", src, *IMPORT, "--out", tmp_path / "o.csv"), f"{src}:{k + 1}:", "NUL")


def test_import_of_a_good_file_still_reads_every_row(tmp_path):
    src = tmp_path / "good.csv"
    src.write_text(SMALL)
    out = tmp_path / "out.csv"
    res = run_station("import", src, *IMPORT, "--out", out)
    assert res.returncode == 0, res.stderr
    from station.capture import read_capture

    assert read_capture(out).n_rows == 400
