"""The three contracts of ../shared/spec, checked as an outside tester would: the real `station`
command in a subprocess, its stdout and stderr and exit status, read by ``spec_checker`` (a
reading of the spec's text that shares no code with the station).

- capture-format.md: every capture `station simulate` writes (all five procedures, the
  variants the spec names: P1 table of averages, P4 mode A, P5 navigation-frame reference)
  and every real capture in ../shared/data.
- calibrate.md and diagnose.md: `--json` is one JSON object on stdout with the fields, types
  and shapes the spec lists, and the parameters mean what the spec's equations say on the
  capture's own rows (units included); exit 0 on a result, else exit 2 with one line on
  stderr and nothing on stdout.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests import spec_checker as S
from tests.station_run import run_station

ROOT = Path(__file__).resolve().parents[1]

SIMULATED = {
    "accel-tabletop": ["--option", "hold_s=5"],
    "accel-tabletop-averages": ["--option", "averages=1"],
    "accel-centrifuge": [],
    "compass": [],
    "gyro-drift": [],
    "gyro-drift-reference": ["--option", "mode=reference", "--option", "duration_s=60"],
    "ldv": [],
    "ldv-nav": ["--option", "reference=nav"],
}


def station(*args, in_process: bool = False) -> subprocess.CompletedProcess:
    """The real CLI in a subprocess (what reaches file descriptors 1 and 2 is what is checked);
    ``in_process``: through ``station.cli.main`` in this process (the same code path, faster)."""
    if in_process:
        return run_station(*args)
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    env.pop("STATION_DEBUG", None)
    return subprocess.run(
        [sys.executable, "-m", "station", *map(str, args)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )


def contract_of_run(res: subprocess.CompletedProcess, check, procedure: str, raw: bytes | None = None) -> list[str]:
    """calibrate.md / diagnose.md on one run: exit 0 and a JSON object keeping the spec, or exit 2
    with one line on stderr naming the file and nothing on stdout."""
    if res.returncode == 2:
        lines = res.stderr.splitlines()
        problems = [] if res.stdout == "" else ["exit 2 with output on stdout"]
        if len(lines) != 1:
            problems.append(f"exit 2 with {len(lines)} lines on stderr: {res.stderr!r}")
        return problems
    if res.returncode != 0:
        return [f"exit status {res.returncode}: {res.stderr[-300:]}"]
    d, problems = S.one_json_object(res.stdout)
    if d is None:
        return problems
    problems = check(d, procedure)
    if raw is not None and check is S.check_calibrate and not problems:
        problems = S.check_calibrate_equations(d, raw)
    return problems


@pytest.fixture(scope="module")
def simulated(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("simulated")
    out = {}
    for name, options in SIMULATED.items():
        procedure = name if name in S.PROCEDURES else name.rsplit("-", 1)[0]
        path = folder / f"{name}.csv"
        res = station("simulate", "--procedure", procedure, "--out", path, "--seed", "400321", *options)
        assert res.returncode == 0, res.stderr
        out[name] = path
    return out


@pytest.mark.parametrize("name", list(SIMULATED))
def test_simulated_capture_keeps_the_capture_format(simulated, name):
    raw = simulated[name].read_bytes()
    assert S.check_capture(raw) == []


@pytest.mark.parametrize("name", list(SIMULATED))
def test_calibrate_and_diagnose_of_a_simulated_capture_keep_their_contracts(simulated, name):
    raw = simulated[name].read_bytes()
    procedure = S.parse_capture(raw)[0]["procedure"]
    cal = station("calibrate", simulated[name], "--json")
    assert cal.returncode == 0, cal.stderr  # a simulated capture supports its procedure
    assert contract_of_run(cal, S.check_calibrate, procedure, raw) == []
    diag = station("diagnose", simulated[name], "--json", "--no-plots")
    assert diag.returncode == 0, diag.stderr
    assert contract_of_run(diag, S.check_diagnose, procedure) == []


def test_without_latitude_the_drift_is_the_plain_mean_with_a_warning(simulated, tmp_path):
    """calibrate.md, gyro-drift: "with no latitude_deg the Earth rate cannot be removed: drift is
    the plain mean and a warning says so"."""
    text = simulated["gyro-drift"].read_text()
    path = tmp_path / "no-latitude.csv"
    path.write_text("".join(ln for ln in text.splitlines(keepends=True) if not ln.startswith("# latitude_deg")))
    res = station("calibrate", path, "--json")
    assert contract_of_run(res, S.check_calibrate, "gyro-drift", path.read_bytes()) == []
    d = S.one_json_object(res.stdout)[0]
    meta, cols = S.columns(path.read_bytes())
    scale = {"rad/s": 1.0, "deg/s": 3.141592653589793 / 180}[meta["gyro_unit"]]
    for i, k in enumerate(("gx", "gy", "gz")):
        mean = sum(cols[k]) / len(cols[k]) * scale
        assert abs(d["params"]["drift"][i] - mean) <= 1e-9 + 1e-6 * abs(mean)
    assert any("latitude" in w for w in d["warnings"])


def _real_captures() -> list[Path]:
    data = ROOT.parent / "shared" / "data"
    return sorted(data.glob("*/*.capture.csv"))


@pytest.mark.slow
@pytest.mark.parametrize("path", _real_captures(), ids=lambda p: p.name)
def test_real_capture_keeps_the_capture_format_and_the_commands_their_contracts(path):
    raw = path.read_bytes()
    assert S.check_capture(raw, written_by_station=False) == []
    procedure = S.parse_capture(raw)[0]["procedure"]
    cal = station("calibrate", path, "--json", in_process=True)
    assert contract_of_run(cal, S.check_calibrate, procedure, raw) == []
    diag = station("diagnose", path, "--json", "--no-plots", in_process=True)
    assert contract_of_run(diag, S.check_diagnose, procedure) == []


def _real_logs() -> list[Path]:
    return sorted((ROOT.parent / "shared" / "data").glob("*/original/*.ulg"))


@pytest.mark.slow
@pytest.mark.parametrize("path", _real_logs(), ids=lambda p: p.name)
def test_a_real_log_read_directly_keeps_the_contracts(path):
    """README: calibrate and diagnose take a .ulg directly with --procedure; the result (or the
    refusal: these are flights, not calibration recordings) keeps the same contract."""
    cal = station("calibrate", path, "--procedure", "gyro-drift", "--json", in_process=True)
    assert contract_of_run(cal, S.check_calibrate, "gyro-drift") == []
    diag = station("diagnose", path, "--procedure", "gyro-drift", "--json", "--no-plots", in_process=True)
    assert contract_of_run(diag, S.check_diagnose, "gyro-drift") == []


@pytest.mark.parametrize(
    "name, key, columns, unit, factor",
    [
        ("compass", "mag_unit", ("mx", "my", "mz"), "gauss", 0.01),
        ("compass", "mag_unit", ("mx", "my", "mz"), "nT", 1000.0),
        ("gyro-drift", "gyro_unit", ("gx", "gy", "gz"), "deg/s", 180 / 3.141592653589793),
    ],
    ids=["compass-gauss", "compass-nT", "gyro-deg-s"],
)
def test_the_parameters_units_follow_the_captures_declared_unit(simulated, tmp_path, name, key, columns, unit, factor):
    """calibrate.md: compass `hard_iron` in the capture's `mag_unit` and `soft_iron` from it to nT;
    gyro-drift's `drift` in rad/s whatever `gyro_unit` says. The simulated capture's raw columns
    rescaled into another unit the spec names, its unit key changed to say so: the equations must
    still hold on the rows, and the result be the same quantity."""
    meta, cols = S.columns(simulated[name].read_bytes())
    old_unit = meta[key]
    lines = simulated[name].read_text().splitlines()
    header_at = next(i for i, ln in enumerate(lines) if not ln.startswith("#"))
    header = lines[header_at].split(",")
    out = [ln.replace(f"# {key}: {old_unit}", f"# {key}: {unit}") for ln in lines[:header_at]] + [lines[header_at]]
    for ln in lines[header_at + 1 :]:
        cells = ln.split(",")
        for j, c in enumerate(header):
            if c in columns:
                cells[j] = repr(float(cells[j]) * factor)
        out.append(",".join(cells))
    path = tmp_path / f"{unit.replace('/', '_')}.csv"
    path.write_text("\n".join(out) + "\n")
    raw = path.read_bytes()
    res = station("calibrate", path, "--json", in_process=True)
    assert contract_of_run(res, S.check_calibrate, meta["procedure"], raw) == []
    d = S.one_json_object(res.stdout)[0]
    if name == "gyro-drift":
        base = S.one_json_object(station("calibrate", simulated[name], "--json", in_process=True).stdout)[0]
        assert d["params"]["drift"] == pytest.approx(base["params"]["drift"], rel=1e-9, abs=1e-15)
