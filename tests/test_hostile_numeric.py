"""Valid-but-extreme input (issue 16, "What was measured"): nothing hangs, nothing reaches
stdout but the result, every refusal is one line with a reason (never the CLI's last-resort
``cannot process this input``), and results the data cannot support are refused.

Each case starts from a capture written by the station's own simulator (realistic noise,
placement and timing), changes what a careless or hostile user would, and runs the real CLI.
The hang and the stdout cases run in a subprocess with a timeout: a hang fails the test
instead of stalling the suite, and stdout is the real file descriptor 1.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time

import numpy as np
import pytest

from solvers import linalg
from solvers.errors import NotFinite
from station.capture import read_capture, write_capture
from tests.station_run import ROOT, run_station

LAST_RESORT = "cannot process this input"


def _sim(tmp_path_factory, procedure: str, *options: str, seed: int = 3):
    out = tmp_path_factory.mktemp("sim") / f"{procedure}.csv"
    args = ["simulate", "--procedure", procedure, "--out", out, "--seed", seed]
    for o in options:
        args += ["--option", o]
    r = run_station(*args)
    assert r.returncode == 0, r.stderr
    return out


@pytest.fixture(scope="module")
def sims(tmp_path_factory):
    made = {}

    def get(procedure, *options):
        key = (procedure, options)
        if key not in made:
            made[key] = _sim(tmp_path_factory, procedure, *options)
        return made[key]

    return get


def _mutated(src, dst, fn):
    c = read_capture(src)
    fn(c)
    c.path = None
    write_capture(dst, c)
    edit = getattr(fn, "text_edit", None)  # what the writer itself refuses to write
    if edit is not None:
        dst.write_text(edit(dst.read_text()))
    return dst


def _set(col: str, row: int, value: float):
    def fn(c):
        c.columns[col] = np.array(c.columns[col], dtype=float)
        c.columns[col][row] = value

    return fn


def _cli(*args, timeout=180):
    """The real CLI in a subprocess: (rc, stdout, stderr); a hang raises TimeoutExpired."""
    r = subprocess.run(
        [sys.executable, "-m", "station", *map(str, args)], cwd=ROOT, capture_output=True, text=True, timeout=timeout
    )
    return r.returncode, r.stdout, r.stderr


# --------------------------------------------------------------------------- the hang


@pytest.mark.parametrize("command", ["calibrate", "diagnose", "inspect"])
def test_one_cell_of_1e200_in_a_p2_table_is_refused_at_once_naming_line_and_column(sims, tmp_path, command):
    src = sims("accel-centrifuge")
    c = read_capture(src)
    bad = _mutated(src, tmp_path / "p2.csv", _set("ax", 2, 1e200))
    line = c.header_line + 1 + 2
    rc, out, err = _cli(command, bad, "--json", timeout=120)  # used to never return
    assert rc == 2
    assert out == ""  # LAPACK's "** On entry to DLASCL" used to land here
    assert err.count("\n") == 1
    assert f"p2.csv:{line}: column 'ax'" in err and "1e+200" in err


def test_lstsq_refuses_non_finite_input_at_once():
    a = np.ones((6, 3))
    a[2, 1] = np.inf
    t0 = time.monotonic()
    with pytest.raises(NotFinite):
        linalg.lstsq(a, np.ones(6))
    with pytest.raises(NotFinite):
        linalg.lstsq(np.ones((6, 3)), np.full(6, np.nan))
    assert time.monotonic() - t0 < 60  # not a speed target: only "it returned"


def test_dependency_prints_at_fd_level_are_caught_not_written():
    code = (
        "import ctypes, sys\n"
        "from station.guard import quiet_stdout\n"
        "with quiet_stdout() as lines:\n"
        "    ctypes.CDLL(None).printf(b' ** On entry to DLASCL parameter number  4 had an illegal value\\n')\n"
        "    print('Warning: You provided date(s) not covered by coefficient file')\n"
        "print('RESULT', lines)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("RESULT ")  # nothing before the program's own output
    assert "DLASCL" in r.stdout and "coefficient file" in r.stdout  # ... but both were caught as lines
    assert r.stdout.count("\n") == 1


# --------------------------------------------------------------------------- IGRF coverage


@pytest.mark.parametrize("date,years", [("2031-06-01", "1.4"), ("1897-03-01", "2.8")])
def test_compass_outside_igrf_coverage_warns_in_the_result_and_stdout_is_only_json(sims, tmp_path, date, years):
    src = sims("compass")
    dst = tmp_path / "compass.csv"

    def redate(c):
        c.meta["date"] = date

    _mutated(src, dst, redate)
    rc, out, err = _cli("calibrate", dst, "--json")
    assert rc == 0, err
    result = json.loads(out)  # ppigrf's "Warning: You provided date(s)..." used to precede the JSON
    notes = [w for w in result["warnings"] if "outside the IGRF coverage" in w]
    assert len(notes) == 1 and f"({years} years away" in notes[0]
    assert result["igrf_anchored"] is True


def test_compass_far_outside_igrf_coverage_is_refused_on_the_date_line(sims, tmp_path):
    src = sims("compass")
    dst = tmp_path / "compass.csv"

    def redate(c):
        c.meta["date"] = "1850-06-01"

    _mutated(src, dst, redate)
    line = read_capture(dst).meta_lines["date"]
    rc, out, err = _cli("calibrate", dst, "--json")
    assert rc == 2 and out == ""
    assert f"compass.csv:{line}: metadata 'date'" in err and "outside the IGRF coverage" in err


def test_igrf_date_policy():
    from solvers.geomag import MAX_EXTRAPOLATION_YEARS, igrf_coverage, igrf_date

    first, last = igrf_coverage()
    assert first.year == 1900 and last.year >= 2030  # IGRF-14 (ppigrf's shipped file)
    assert igrf_date("2020-05-05")[1] is None
    used, note = igrf_date(f"{last.year + 2}-01-01")
    assert used == last and "outside the IGRF coverage" in note
    with pytest.raises(ValueError):
        igrf_date(f"{last.year + int(MAX_EXTRAPOLATION_YEARS) + 1}-01-02")


# --------------------------------------------------------------------------- last-resort errors -> reasons


def _col_nan(col):
    def fn(c):
        c.columns[col] = np.full(c.n_rows, np.nan)

    return fn


def _scale(col, k):
    def fn(c):
        c.columns[col] = np.asarray(c.columns[col], dtype=float) * k

    return fn


def _meta(key, value):
    """Metadata the writer refuses: written as a placeholder, then edited in the text."""

    def fn(c):
        c.meta[key] = "0"

    fn.text_edit = lambda text: text.replace(f"# {key}: 0\n", f"# {key}: {value}\n", 1)
    return fn


CASES = [
    # (id, procedure, simulator options, mutation, what the one line must say)
    ("p1-one-sample-1e308", "accel-tabletop", (), _set("ax", 400, 1e308), "column 'ax': 1e+308 is beyond"),
    (
        "p4a-one-sample-1e308",
        "gyro-drift",
        ("mode=reference",),
        _set("gx", 400, 1e308),
        "column 'gx': 1e+308 is beyond",
    ),
    ("altitude-1e308", "accel-tabletop", (), _meta("altitude_m", "1e308"), "metadata 'altitude_m'"),
    ("empty-magnetometer-column", "compass", (), _col_nan("mx"), "column 'mx' is empty in every row"),
    ("ldv-nav-empty-attitude", "ldv", ("reference=nav",), _col_nan("roll_deg"), "column 'roll_deg' is empty"),
    ("p1-time-x1e300", "accel-tabletop", (), _scale("t", 1e300), "column 't':"),
    ("p4-time-x1e300", "gyro-drift", (), _scale("t", 1e300), "column 't':"),
    ("p5-time-x1e300", "ldv", (), _scale("t", 1e300), "column 't':"),
    ("p3-time-x1e300", "compass", (), _scale("t", 1e300), "column 't':"),
    ("ldv-dead-beam", "ldv", (), _scale("vl2", 0.0), "beam 'vl2' reads 0 m/s in every row"),
    ("ldv-beam-x1e200", "ldv", (), _scale("vl3", 1e200), "column 'vl3'"),
    ("p4a-gyro-x1e200", "gyro-drift", ("mode=reference",), _scale("gy", 1e200), "column 'gy'"),
    ("time-frozen", "gyro-drift", (), _scale("t", 0.0), "time axis does not advance"),
]


@pytest.mark.parametrize("command", ["calibrate", "diagnose", "inspect"])
@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_extreme_input_gets_a_reason_not_the_last_resort_error(sims, tmp_path, case, command):
    _, procedure, options, fn, expect = case
    bad = _mutated(sims(procedure, *options), tmp_path / "bad.csv", fn)
    r = run_station(command, bad, "--json")
    assert r.returncode == 2, r.stdout[:300]
    assert r.stdout == ""
    assert LAST_RESORT not in r.stderr
    assert r.stderr.count("\n") == 1 and "bad.csv" in r.stderr
    assert expect in r.stderr


def test_a_result_with_a_null_parameter_is_refused_not_returned():
    from station.capture import Capture
    from station.errors import UnsupportedError
    from station.guard import check_result

    cap = Capture({"procedure": "ldv"}, {"t": np.arange(3.0)}, "x.csv")
    with pytest.raises(UnsupportedError, match=r"beam1\.alpha_deg"):
        check_result(cap, {"params": {"beam1": {"dK": -1.0, "alpha_deg": None}}, "uncertainty": {}})
    with pytest.raises(UnsupportedError, match="uncertainty"):
        check_result(cap, {"params": {"drift": [0.1, 0.2, 0.3]}, "uncertainty": {"drift": [None, None, None]}})
    check_result(
        cap, {"params": {"drift": [0.1, 0.2, 0.3], "mode": "reference"}, "uncertainty": {"drift": [0.01, 0.01, 0.01]}}
    )


# --------------------------------------------------------------------------- reader memory


def test_reader_memory_is_bounded_whatever_the_first_line_length(tmp_path):
    """A 400 KB first data line made the reader ask for 65,536 x 400 KB = 26 GB at once
    (MemoryError on a 433 KB file). Under a 1 GiB address-space limit it now reads or refuses."""
    path = tmp_path / "long.csv"
    pad = " " * 400_000
    rows = [f"0{pad},1,1.0,2.0,3.0"] + [f"{k * 0.01:.2f},1,1.0,2.0,3.0" for k in range(1, 2000)]
    path.write_text("# station-capture: 1\n# procedure: accel-tabletop\nt,position,ax,ay,az\n" + "\n".join(rows) + "\n")
    code = (
        "import resource, sys\n"
        "resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30))\n"
        "from station.capture import read_capture\n"
        f"c = read_capture({str(path)!r})\n"
        "print(c.n_rows)\n"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert "MemoryError" not in r.stderr
    assert r.returncode == 0, r.stderr[-500:]
    assert r.stdout.strip() == "2000"


def test_a_data_line_longer_than_the_limit_is_refused_with_its_number(tmp_path):
    from station.capture import _MAX_DATA_LINE
    from station.errors import InputError

    path = tmp_path / "huge.csv"
    with open(path, "w") as f:
        f.write("# station-capture: 1\n# procedure: accel-tabletop\nt,ax,ay,az\n")
        for k in range(100):
            f.write(f"{k * 0.01:.2f},1,2,3\n")
        f.write("1.00,1,2," + "3" * (_MAX_DATA_LINE + 10) + "\n")
        f.write("1.01,1,2,3\n")
    with pytest.raises(InputError) as e:
        read_capture(path, rows=10)
    assert e.value.line == 104 and "longer than" in e.value.message


def test_every_least_squares_run_is_bounded(sims, tmp_path, monkeypatch):
    """A P2 table whose `az` and `elapsed_s` headers were swapped (found by the fuzz harness:
    diagnose ran eight fits of thousands of evaluations each, minutes on a loaded machine):
    every fit now stops within 20 (p + 1) evaluations."""
    import solvers.fit as fitmod

    src = sims("accel-centrifuge")
    text = src.read_text()
    header = next(line for line in text.splitlines() if line.startswith("position,"))
    names = header.split(",")
    i, j = names.index("az"), names.index("elapsed_s")
    names[i], names[j] = names[j], names[i]
    bad = tmp_path / "swapped.csv"
    bad.write_text(text.replace(header, ",".join(names), 1))
    runs = []
    real = fitmod.least_squares

    def counting(fun, x0, **kw):
        sol = real(fun, x0, **kw)
        runs.append((len(x0), sol.nfev))
        return sol

    monkeypatch.setattr(fitmod, "least_squares", counting)
    r = run_station("diagnose", bad, "--json")
    assert r.returncode in (0, 2) and LAST_RESORT not in r.stderr
    assert runs and all(nfev <= fitmod.MAX_NFEV_PER_PARAM * (p + 1) for p, nfev in runs), runs


def test_a_short_static_gyro_record_is_diagnosed_not_the_last_resort(sims):
    """Found by the fuzz harness: a P4 static record of 100 rows (under the 400-row block
    budget) made one-row blocks, all dropped, and diagnose fell to the last-resort error. 40 s:
    under 30 s diagnose refuses the record, as calibrate does (test_gyrodrift)."""
    src = sims("gyro-drift", "duration_s=40", "rate_hz=2.5")
    r = run_station("diagnose", src, "--json")
    assert LAST_RESORT not in r.stderr
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["procedure"] == "gyro-drift"


# ----------------------------------------------------- a procedure's own metadata keys


@pytest.mark.parametrize(
    ("procedure", "options", "key", "value", "says"),
    [
        # a negative or absurd 1-sigma was used as given: a result with null uncertainties (1e300)
        ("gyro-drift", (), "heading_sigma_deg", "-3", "must be positive and at most 180"),
        ("gyro-drift", (), "heading_sigma_deg", "1e300", "must be positive and at most 180"),
        # --accuracy 0 is refused on the command line; the same value in the file gave nulls
        ("gyro-drift", (), "accuracy_deg_h", "0", "must be positive"),
        # 'nan' read by float(): every row NaN, refused as '0 samples is too short'
        ("gyro-drift", (), "accel_offset", "nan,nan,nan", "give three numbers"),
        ("gyro-drift", ("mode=reference",), "reference_drift_deg_h", "-1", "must be zero or positive"),
        ("gyro-drift", ("mode=reference",), "reference_drift_deg_h", "1e300", "must be zero or positive"),
        ("ldv", (), "reference_sigma_mps", "-1", "must be zero or positive"),
        ("ldv", (), "reference_attitude_sigma_deg", "-0.02", "must be zero or positive and at most 90"),
    ],
)
def test_a_procedure_key_no_bench_could_mean_is_refused_on_its_line(
    sims, tmp_path, procedure, options, key, value, says
):
    src = sims(procedure, *options)
    text = src.read_text().split("\n")
    text.insert(1, f"# {key}: {value}")
    path = tmp_path / f"{key}.csv"
    path.write_text("\n".join(text))
    res = run_station("calibrate", path, "--json")
    assert res.returncode == 2 and res.stdout == "", res.stdout[:300]
    assert res.stderr.count("\n") == 1 and f"{path}:2: " in res.stderr and says in res.stderr, res.stderr
