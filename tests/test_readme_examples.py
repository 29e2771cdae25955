"""The README's and docs' example commands, run as a new user types them: each command line is
read from the text itself (so an edited example is the one tested), run through the real CLI
on the shared logs or on simulated captures, and the figures its comment promises are looked
for in what it prints.

Not here (run elsewhere, or too slow for this file): the TUI lines (tests/test_e2e_tmux.py,
tests/test_tui*.py), the 120 s `sim-device` + `record` example of docs/protocol.md
(tests/test_device_record.py), the import examples on files the project does not ship
(`00000042.BIN`, `flight.tlog`, `run.bag`: the importers' own tests write such files).
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from station_run import run_station

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _example(prefix: str, text: str = README) -> tuple[list[str], str]:
    """The one example line of ``text`` that starts with ``prefix`` (after its indent): its
    words (the shell's split, the comment left out) and its comment."""
    found = [ln.strip() for ln in text.splitlines() if ln.strip().startswith(prefix)]
    assert len(found) == 1, (prefix, found)
    command, _, comment = found[0].partition("#")
    return shlex.split(command), comment.strip()


def _shared(words: list[str], shared_data: Path) -> list[str]:
    """``../shared/data/...`` as this clone finds it ($STATION_SHARED for a worktree elsewhere)."""
    return [
        str(shared_data / w.removeprefix("../shared/data/")) if w.startswith("../shared/data/") else w for w in words
    ]


def test_readme_px4_import_example_prints_what_its_comment_says(shared_data, tmp_path, monkeypatch):
    """README, Import: `station import ...sample_log_small.ulg ... --out cube.csv`, then
    `station inspect cube.csv  # param.CAL_ACC0_XOFF: 0.15803528 ... corrected: false,
    sensor_device_id: 2424842`, then `station calibrate ...sample.ulg --procedure gyro-drift`."""
    monkeypatch.chdir(tmp_path)
    words, _ = _example("station import ../shared/data/px4_ulog/original/sample_log_small.ulg")
    res = run_station(*_shared(words[1:], shared_data))
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "cube.csv").is_file()

    words, comment = _example("station inspect cube.csv")
    res = run_station(*words[1:])
    assert res.returncode == 0, res.stderr
    promised = [p.strip() for p in re.split(r"\.\.\.|,", comment) if p.strip()]
    assert promised == ["param.CAL_ACC0_XOFF: 0.15803528", "corrected: false", "sensor_device_id: 2424842"]
    for text in promised:
        assert re.search(rf"^\s*{re.escape(text)}$", res.stdout, flags=re.M), text

    words, _ = _example("station calibrate ../shared/data/px4_ulog/original/sample.ulg")
    res = run_station(*_shared(words[1:], shared_data))
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith("procedure  gyro-drift (static)")


def test_readme_save_example_exit_statuses_and_lines(tmp_path, monkeypatch):
    """README, "Accepting a result": the `calibrate --save` example: a FAIL saves nothing
    (`verdict    FAIL`, `  - B[2] changed ... (tolerance 0.02 m/s^2)`, `saved      nothing (...)`,
    status 1); `--reject "..."` saves it as rejected (status 3, its stderr line); `--save --json`
    gives the id (status 0, `station: saved calibration N as accepted`)."""
    monkeypatch.chdir(tmp_path)
    block = README[README.index("$ station calibrate unit7.csv --save") :]
    block = block[: block.index("```")]
    db = str(tmp_path / "station.db")
    # unit7 and unit8 are two units of the simulator: unit8 is saved first as the reference
    for seed, name in ((1, "unit8.csv"), (3, "unit7.csv")):
        res = run_station("simulate", "--procedure", "accel-tabletop", "--seed", seed, "--out", name)
        assert res.returncode == 0, res.stderr
    assert run_station("--db", db, "devices", "add", "U", "--tolerance", "B=0.02").returncode == 0
    assert run_station("--db", db, "calibrate", "unit8.csv", "--save", "--device", "U").returncode == 0

    first = re.search(r"^\$ (station calibrate unit7\.csv --save) \|\|", block, flags=re.M).group(1)
    res = run_station("--db", db, *shlex.split(first)[1:], "--device", "U")
    assert res.returncode == 1 and "status 1" in block
    shown = [ln for ln in block.splitlines() if ln.startswith(("verdict", "saved", "  - B[2] changed"))]
    assert [re.sub(r"[+-][\d.]+ ", "X ", ln) for ln in shown] == [
        "verdict    FAIL",
        "  - B[2] changed X m/s^2 (tolerance 0.02 m/s^2)",
        "saved      nothing (FAIL: --reject REASON or --override NOTE decides)",
    ]
    for line in shown:
        pattern = re.escape(line).replace(r"\+0\.0412", r"[+-][\d.]+")
        assert re.search(rf"^{pattern}$", res.stdout, flags=re.M), line

    reject = re.search(r"^\$ (station calibrate unit7\.csv --save --reject .*?)\s+# status 3$", block, flags=re.M)
    res = run_station("--db", db, *shlex.split(reject.group(1))[1:], "--device", "U")
    assert res.returncode == 3
    assert re.fullmatch(r"station: saved calibration \d+ as rejected\n", res.stderr)

    res = run_station(
        "simulate", "--procedure", "accel-tabletop", "--seed", 1, "--option", "hold_s=21", "--out", "unit8b.csv"
    )
    assert res.returncode == 0
    res = run_station("--db", db, "calibrate", "unit8b.csv", "--save", "--json", "--device", "U")
    assert res.returncode == 0
    import json

    cal_id = json.loads(res.stdout)["calibration_id"]
    assert res.stderr == f"station: saved calibration {cal_id} as accepted\n"


def test_readme_noise_example_writes_the_yaml_it_shows(tmp_path, monkeypatch):
    """README, IMU noise: `station noise still.csv --format kalibr --out imu.yaml` prints the
    table's header lines and `wrote imu.yaml`, and imu.yaml holds the keys the README's `cat`
    shows, in that order."""
    monkeypatch.chdir(tmp_path)
    res = run_station("simulate", "--procedure", "gyro-drift", "--option", "duration_s=300", "--out", "still.csv")
    assert res.returncode == 0, res.stderr
    words, _ = _example("station noise still.csv")
    res = run_station(*words[1:])
    assert res.returncode == 0, res.stderr
    out = res.stdout.splitlines()
    for line in ("gyro          noise density           bias instability         random walk",
                 "accelerometer noise density           bias instability         random walk",
                 "wrote imu.yaml"):  # fmt: skip
        assert line in README and line in out, line
    shown = re.search(r"\$ cat imu\.yaml\n(.*?)\n\n", README, flags=re.S).group(1)
    keys_shown = [ln.strip().split(":")[0] for ln in shown.splitlines()]
    written = (tmp_path / "imu.yaml").read_text().splitlines()
    keys_written = [ln.split(":")[0] for ln in written if ln and not ln.startswith("#")]
    assert keys_written == keys_shown


def _listed(usage: str) -> list[str]:
    """The method names of a usage line: `--method a|b|c`, or `name: a (default) | b | c (...)`."""
    m = re.search(r"--method ([a-z0-9|-]+)", usage)
    parts = m.group(1).split("|") if m else usage.split(":", 1)[1].split("|")
    return sorted(p.split()[0] for p in parts)


@pytest.mark.parametrize(
    "doc, procedure, line",
    [("accel.md", "tabletop", "accel-tabletop:"), ("compass.md", "compass", "station calibrate CAPTURE.csv")],
)
def test_docs_method_lists_are_the_codes(doc, procedure, line):
    """docs/accel.md listed three P1 methods where `--method` takes four (`step8` was missing);
    each usage block names exactly the methods the procedure accepts."""
    import importlib

    text = (ROOT / "docs" / doc).read_text(encoding="utf-8")
    usage = next(ln for ln in text.splitlines() if ln.strip().startswith(line))
    methods = importlib.import_module(f"station.procedures.{procedure}").METHODS
    assert _listed(usage) == sorted(methods), usage


def test_headless_demo_line_of_the_readme_runs_twice(tmp_path):
    """README, Operator TUI: `station demo --headless` "for scripts": a script runs it more than
    once; the second run of the same seed is not an error."""
    words, _ = _example("station demo --headless")
    db = str(tmp_path / "station.db")
    for _ in range(2):
        res = run_station("--db", db, *words[1:])
        assert res.returncode == 0, res.stderr
    assert res.stdout.splitlines()[-1].startswith("already saved as calibration #1 in ")
