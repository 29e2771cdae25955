"""Bad input on the command line: one line `station: ...` on stderr, exit 2, never a traceback.

Each case here was a traceback (or a silent acceptance) found by running the station as a
bench engineer would; real files in tmp_path, real SQLite files, the real CLI.
"""

from __future__ import annotations

import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from station.capture import Capture, read_capture, write_capture
from station.cli import main
from tests.station_run import assert_one_line_refusal, run_station
from tests.station_run import run_main as run

ROOT = Path(__file__).resolve().parents[1]


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("station: ") and "Traceback" not in err
    return lines[0]


def station_subprocess(*argv) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "station", *map(str, argv)], cwd=ROOT, capture_output=True, text=True, timeout=120
    )


@pytest.fixture(scope="module")
def ldv_capture(tmp_path_factory) -> Path:
    """A short simulated LDV capture (5 min at 10 Hz), written once per module."""
    from solvers.simulate import simulate

    sim = simulate("ldv", seed=3, duration_s=300.0)
    path = tmp_path_factory.mktemp("ldv") / "ldv.csv"
    write_capture(path, Capture(meta=sim.meta, columns=sim.columns, path=path))
    return path


# --- calibrate --save: the database is the bad input -----------------------------------


def test_calibrate_save_into_a_file_that_is_not_a_database(tmp_path, capsys, ldv_capture):
    db = tmp_path / "notes.db"
    db.write_text("these are my notes, not a database\n" * 100)
    before = db.read_bytes()
    code, out, err = run(capsys, "--db", db, "calibrate", ldv_capture, "--save")
    assert code == 2 and out == ""
    line = one_line(err)
    assert str(db) in line and "not a database" in line
    assert db.read_bytes() == before  # refused, not overwritten


@pytest.mark.parametrize(
    "argv",
    [["calibrate", "{cap}", "--save", "--device", "D"], ["devices", "add", "E"], ["devices", "list"], ["verify"]],
    ids=["save", "devices-add", "devices-list", "verify"],
)
def test_a_database_of_a_newer_station_is_refused_and_left_as_it_was(tmp_path, capsys, ldv_capture, argv):
    """A database a newer station migrated (a schema step this version does not have) was read
    and written as if it were this version's: a save skipped what the newer schema keeps and
    anchors, verify passed it. Every command refuses it in one line and leaves it as it was."""
    import sqlite3

    db = tmp_path / "station.db"
    assert run(capsys, "--db", db, "devices", "add", "D")[0] == 0
    raw = sqlite3.connect(db)
    with raw:
        raw.execute(
            "INSERT INTO _sqlite_migrations (migration_set, name, applied_at) VALUES ('station', '0099_future', 'x')"
        )
    raw.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    raw.close()
    before = db.read_bytes()
    code, out, err = run(capsys, "--db", db, *[a.format(cap=ldv_capture) for a in argv])
    assert code == 2 and out == ""
    line = one_line(err)
    assert str(db) in line and "newer" in line and "0099_future" in line, line
    assert db.read_bytes() == before


def test_calibrate_save_into_a_directory(tmp_path, capsys, ldv_capture):
    folder = tmp_path / "adir"
    folder.mkdir()
    code, _, err = run(capsys, "--db", folder, "calibrate", ldv_capture, "--save")
    assert code == 2 and str(folder) in one_line(err)


def test_calibrate_save_with_a_blank_device_id(tmp_path, capsys, ldv_capture):
    code, _, err = run(capsys, "--db", tmp_path / "s.db", "calibrate", ldv_capture, "--save", "--device", "  ")
    assert code == 2 and "device id" in one_line(err)


# --- export / simulate: the output path is the bad input ------------------------------


@pytest.fixture
def db_with_calibration(tmp_path, capsys, ldv_capture) -> Path:
    db = tmp_path / "station.db"
    code, _, err = run(capsys, "--db", db, "calibrate", ldv_capture, "--save")
    assert code == 0, err
    return db


@pytest.mark.parametrize("where", ["missing-folder", "directory"])
def test_export_to_an_unwritable_place(tmp_path, capsys, db_with_calibration, where):
    target = tmp_path / "no" / "such" / "x.json" if where == "missing-folder" else tmp_path / "adir"
    if where == "directory":
        target.mkdir()
    code, out, err = run(capsys, "--db", db_with_calibration, "export", "1", "--format", "json", "-o", target)
    assert code == 2 and out == ""
    assert one_line(err).startswith(f"station: {target}: cannot write")
    assert not [p for p in tmp_path.rglob(".export-*")]  # no temp file left behind


@pytest.mark.parametrize("where", ["missing-folder", "directory"])
def test_simulate_truth_to_an_unwritable_place(tmp_path, capsys, where):
    target = tmp_path / "no" / "t.json" if where == "missing-folder" else tmp_path / "adir"
    if where == "directory":
        target.mkdir()
    code, _, err = run(
        capsys, "simulate", "--procedure", "accel-centrifuge", "--out", tmp_path / "c.csv", "--truth", target
    )
    assert code == 2
    assert one_line(err).startswith(f"station: {target}: cannot write")
    assert not [p for p in tmp_path.rglob(".truth-*")]
    assert not (tmp_path / "c.csv").exists()  # was: the capture written, the truth refused after it


@pytest.mark.parametrize(
    ("out", "says"),
    [("{tmp}/", "cannot write: is a folder"), ("{tmp}/new/", "cannot write: is a folder"), ("", "empty file name")],
    ids=["folder-slash", "missing-folder-slash", "empty"],
)
@pytest.mark.parametrize("command", ["simulate", "export-capture", "report"])
def test_an_output_that_names_a_folder_says_so(tmp_path, capsys, monkeypatch, db_with_calibration, out, says, command):
    """--out DIR/ said 'cannot write: Not a directory' about a directory; --out '' said
    'cannot write: No such file or directory' naming nothing (report wrote its default name)."""
    monkeypatch.chdir(tmp_path)  # a default-named file would appear here
    target = out.format(tmp=tmp_path)
    argv = {
        "simulate": ["simulate", "--procedure", "accel-centrifuge", "--out", target],
        "export-capture": ["export-capture", "1", "-o", target],
        "report": ["report", "1", "-o", target],  # -o '' wrote calibration-1.html in the current folder
    }[command]
    before = sorted(os.listdir(tmp_path))
    code, stdout, err = run(capsys, "--db", db_with_calibration, *argv)
    assert code == 2 and stdout == "" and says in one_line(err), err
    assert sorted(os.listdir(tmp_path)) == before


def test_an_output_named_twice_or_the_input_is_refused_and_nothing_replaced(tmp_path, capsys):
    """`simulate --out c.csv --truth ./c.csv` wrote the capture, then the truth over it (a JSON
    file where the capture was, exit 0); `noise rec.csv --format kalibr --out rec.csv`
    replaced the record with its imu.yaml. Both refused before anything is written."""
    out = tmp_path / "c.csv"
    code, stdout, err = run(
        capsys, "simulate", "--procedure", "gyro-drift", "--out", out, "--truth", tmp_path / "." / "c.csv"
    )
    assert code == 2 and stdout == ""
    assert "--truth is the --out file" in one_line(err)
    assert not out.exists()
    code, _, err = run(capsys, "simulate", "--procedure", "gyro-drift", "--out", out, "--seed", "400002")
    assert code == 0, err
    before = out.read_bytes()
    (tmp_path / "link.csv").symlink_to(out)
    for target in (out, tmp_path / "link.csv"):
        code, stdout, err = run(capsys, "noise", out, "--format", "kalibr", "--out", target)
        assert code == 2 and stdout == ""
        assert one_line(err) == f"station: {target}: --out is the input file: choose another name"
    assert out.read_bytes() == before


@pytest.mark.parametrize(
    "procedure, option, says",
    [
        ("accel-tabletop", "hold_s=-1", "must be positive"),  # was: ValueError traceback
        ("accel-tabletop", "noise_mps2=nan", "finite"),  # was: accepted, NaN capture
        ("accel-tabletop", "extra_positions=-3", "whole number >= 0"),  # was: silently 0
        ("accel-tabletop", "averages=maybe", "expected 0 or 1"),  # was: silently True
        ("accel-centrifuge", "noise_g=-1", "must not be negative"),  # was: ValueError traceback
        ("compass", "n_orientations=0", "whole number >= 1"),  # was: IndexError traceback
        ("gyro-drift", "duration_s=0", "must be positive"),  # was: RuntimeWarnings, then exit 2
        ("ldv", "maneuver=bogus", "choose varied or straight"),  # was: silently 'varied'
        ("ldv", "reference=bogus", "choose body or nav"),  # was: silently 'body'
        ("ldv", "duration_s=1e12", "more samples than fit in memory"),  # was: MemoryError traceback
        ("accel-tabletop", "hold_s=1e308", "more samples than fit in memory"),  # was: the catch-all, OverflowError
        ("compass", "site=x", "not settable"),
    ],
)
def test_simulate_bad_option(tmp_path, capsys, procedure, option, says):
    out_file = tmp_path / "x.csv"
    code, _, err = run(capsys, "simulate", "--procedure", procedure, "--out", out_file, "--option", option)
    assert code == 2 and says in one_line(err)
    assert not out_file.exists()


def test_simulate_a_count_no_bench_has_is_refused_not_run(tmp_path):
    """extra_positions=1e308 drew positions one by one, for ever (in a subprocess: a hang fails)."""
    from tests.station_run import assert_one_line_refusal, run_station

    out_file = tmp_path / "x.csv"
    args = ["simulate", "--procedure", "accel-tabletop", "--out", out_file, "--option", "extra_positions=1e308"]
    assert_one_line_refusal(run_station(*args, subprocess_run=True), "extra_positions=1e+308: at most 1000")
    assert not out_file.exists()


def test_simulate_non_finite_effect(tmp_path, capsys):
    code, _, err = run(
        capsys, "simulate", "--procedure", "ldv", "--out", tmp_path / "x.csv", "--effect", "time_delay=inf"
    )
    assert code == 2 and "not a finite number" in one_line(err)


def test_simulate_good_options_still_work(tmp_path, capsys):
    out_file = tmp_path / "t.csv"
    simulate = ("simulate", "--procedure", "accel-tabletop", "--out", out_file)
    code, out, err = run(
        capsys, *simulate, "--option", "averages=1", "--option", "extra_positions=2", "--option", "table_tilt_deg=-0.5"
    )
    assert code == 0, err
    cap = read_capture(out_file)
    assert not cap.is_time_series and cap.n_rows == 14
    code, out, err = run(capsys, *simulate, "--option", "label_positions=0", "--option", "hold_s=5")
    assert code == 0, err
    cap = read_capture(out_file)
    assert cap.is_time_series and "position" not in cap.columns


def test_simulate_unlabelled_table_is_refused(tmp_path, capsys):
    code, _, err = run(
        capsys,
        "simulate",
        "--procedure",
        "accel-tabletop",
        "--out",
        tmp_path / "t.csv",
        "--option",
        "averages=1",
        "--option",
        "label_positions=0",
    )  # was: labels kept silently
    assert code == 2 and "label_positions=0 applies to time series" in one_line(err)


# --- degenerate data: refused with a reason, no numpy noise on stderr ------------------


def _tabletop_table(path: Path, rows: np.ndarray) -> Path:
    cols = {
        "position": np.array([str(k + 1) for k in range(len(rows))], dtype=object),
        "ax": rows[:, 0],
        "ay": rows[:, 1],
        "az": rows[:, 2],
    }
    write_capture(
        path,
        Capture(
            meta={"station-capture": "1", "procedure": "accel-tabletop", "accel_unit": "V"}, columns=cols, path=path
        ),
    )
    return path


def test_all_zero_tabletop_is_refused_as_one_orientation(tmp_path, capsys):
    path = _tabletop_table(tmp_path / "zero.csv", np.zeros((12, 3)))  # was: LinAlgError traceback
    code, _, err = run(capsys, "calibrate", path)
    assert code == 2 and "1 distinct orientation in 12 static positions" in one_line(err)


def test_one_position_is_counted_in_the_singular(tmp_path, capsys):
    """A still PX4 log imported for P1 was refused as "1 distinct orientations in 1 static
    positions"."""
    path = _tabletop_table(tmp_path / "one.csv", np.full((1, 3), 1.65))
    code, _, err = run(capsys, "calibrate", path)
    assert code == 2 and "1 distinct orientation in 1 static position;" in one_line(err)


def test_single_position_no_runtime_warning_on_stderr(tmp_path):
    path = _tabletop_table(tmp_path / "one.csv", np.array([[1.0, 2.0, 3.0]]))
    proc = station_subprocess("calibrate", path)
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0, proc.stderr  # was: a RuntimeWarning and its source line
    assert "1 distinct orientation in 1 static position" in proc.stderr and "Warning" not in proc.stderr


def test_absurd_values_fail_with_a_reason_not_a_traceback(tmp_path, capsys, ldv_capture):
    cap = read_capture(ldv_capture)
    cols = {k: (v * 1e300 if k in ("vl1", "vl2", "vl3", "vx", "vy", "vz") else v) for k, v in cap.columns.items()}
    path = tmp_path / "huge.csv"
    write_capture(path, Capture(meta=dict(cap.meta), columns=cols, path=path))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        code, _, err = run(capsys, "calibrate", path)  # was: LinAlgError traceback
    assert code == 2
    line = one_line(err)
    assert f"{path}:" in line and "column 'vl1'" in line and "beyond" in line  # file, line, column, reason


def test_orientation_clusters_zero_vectors_are_one_orientation():
    from solvers.tabletop import orientation_clusters

    A = np.array([[0.0, 0, 0], [0, 0, 0], [0, 0, 9.8], [0, 0, 9.8], [9.8, 0, 0], [0, 0, 0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        labels = orientation_clusters(A)
    assert labels.tolist() == [0, 0, 1, 1, 2, 0]


# --- files that are not captures (these already worked; kept so they stay that way) ---


@pytest.mark.parametrize("command", ["calibrate", "inspect"])
@pytest.mark.parametrize(
    "kind, says",
    [
        ("missing", "no such file"),
        ("directory", "is a directory"),
        ("empty", "empty file"),
        ("binary", "binary data"),
        ("text", "not a station capture file"),
    ],
)
def test_not_a_capture(tmp_path, capsys, command, kind, says):
    path = tmp_path / f"{kind}.csv"
    if kind == "directory":
        path.mkdir()
    elif kind == "empty":
        path.write_bytes(b"")
    elif kind == "binary":
        path.write_bytes(bytes(range(256)) * 8)
    elif kind == "text":
        path.write_text("hello\n")
    code, out, err = run(capsys, command, path)
    assert code == 2 and out == ""
    line = one_line(err)
    assert str(path) in line and says in line


def test_capture_of_another_procedure_for_a_method(tmp_path, capsys, ldv_capture):
    code, _, err = run(capsys, "calibrate", ldv_capture, "--method", "six-position")
    assert code == 2 and "ldv: unknown method 'six-position'" in one_line(err)


def test_unknown_ids_in_the_database(tmp_path, capsys, db_with_calibration):
    for argv, says in [
        (("history", "NOPE"), 'no device "NOPE"'),
        (("drift", "NOPE"), 'no device "NOPE"'),
        (("export", "99", "--format", "json"), "no calibration 99"),
        (("recompute", "99"), "no calibration 99"),
        (("export-capture", "99"), "no capture 99"),
    ]:
        code, _, err = run(capsys, "--db", db_with_calibration, *argv)
        assert code == 2 and says in one_line(err), argv
    assert os.path.getsize(db_with_calibration) > 0


# --- missing values: used data may shrink, but never silently --------------------------


def _with_holes(src: Path, dst: Path, column: str) -> Path:
    cap = read_capture(src)
    cols = {k: v.copy() for k, v in cap.columns.items()}
    cols[column][::2] = np.nan  # every other row loses one value
    write_capture(dst, Capture(meta=dict(cap.meta), columns=cols, path=dst))
    return dst


def test_tabletop_rows_with_missing_values_are_counted_in_warnings(tmp_path, capsys):
    from solvers.simulate import simulate

    sim = simulate("accel-tabletop", seed=4, hold_s=5.0)
    src = tmp_path / "p1.csv"
    write_capture(src, Capture(meta=sim.meta, columns=sim.columns, path=src))
    path = _with_holes(src, tmp_path / "holes.csv", "ay")
    code = main(["calibrate", str(path), "--json"])
    out = capsys.readouterr()
    assert code == 0, out.err
    n = read_capture(path).n_rows
    import json

    warnings_ = json.loads(out.out)["warnings"]
    assert f"{(n + 1) // 2} of {n} rows with a missing accelerometer value left out" in warnings_  # was: none


def test_ldv_rows_with_a_missing_beam_are_counted_in_warnings(tmp_path, capsys, ldv_capture):
    import json

    path = _with_holes(ldv_capture, tmp_path / "holes.csv", "vl2")
    code = main(["calibrate", str(path), "--json"])
    out = capsys.readouterr()
    assert code == 0, out.err
    d = json.loads(out.out)
    n = read_capture(path).n_rows
    assert f"{(n + 1) // 2} LDV rows with a missing beam value or time left out" in d["warnings"]  # was: none
    assert d["n_positions"] == n // 2


def test_gyro_drift_with_a_dead_accelerometer_is_refused(tmp_path, capsys):
    from solvers.simulate import simulate

    sim = simulate("gyro-drift", seed=5, duration_s=60.0)
    cols = dict(
        sim.columns,
        ax=np.zeros_like(sim.columns["ax"]),
        ay=np.zeros_like(sim.columns["ay"]),
        az=np.zeros_like(sim.columns["az"]),
    )
    path = tmp_path / "dead.csv"
    write_capture(path, Capture(meta=sim.meta, columns=cols, path=path))
    code, out, err = run(capsys, "calibrate", path)  # was: exit 0, roll -180°, drift with null σ
    assert code == 2 and out == ""
    assert "accelerometer reads zero" in one_line(err)


def test_gyro_drift_single_row_says_what_is_missing(tmp_path, capsys):
    path = tmp_path / "one.csv"
    path.write_text("# station-capture: 1\n# procedure: gyro-drift\n# gyro_unit: rad/s\nt,gx,gy,gz\n0,1,2,3\n")
    code, _, err = run(capsys, "calibrate", path)  # was: "needs a time series ('t' column ...)" with a t column
    assert code == 2 and "at least two increasing times" in one_line(err)


def test_no_command_keeps_the_global_db_option(tmp_path, monkeypatch):
    """`station --db X` starts the TUI on X (was: the options were dropped and the TUI opened the default
    database). The TUI itself is not started here: its handler is replaced by a recorder of its args."""
    import station.commands.tui as tui

    seen = {}
    monkeypatch.setattr(tui, "run", lambda args: seen.setdefault("db", getattr(args, "db", None)) and 0)
    db = str(tmp_path / "bench.db")
    monkeypatch.setattr(sys, "argv", ["station", "--db", db])
    assert main() == 0
    assert seen["db"] == db


def test_corrupt_stored_capture_is_one_line(tmp_path, capsys, db_with_calibration):
    import sqlite3

    con = sqlite3.connect(db_with_calibration)
    with con:
        con.execute("UPDATE capture_columns SET data = zeroblob(10) WHERE capture_id = 1 AND name = 'vl1'")
    con.close()
    for argv in (("recompute", "1"), ("export-capture", "1")):  # was: zlib.error traceback
        code, _, err = run(capsys, "--db", db_with_calibration, *argv)
        assert code == 2 and "capture 1, column 'vl1': stored column is corrupt" in one_line(err), argv
    code, out, _ = run(capsys, "--db", db_with_calibration, "verify")
    assert code == 1 and "capture changed" in out


def test_record_edited_into_invalid_json_is_named(tmp_path, capsys, db_with_calibration):
    import sqlite3

    con = sqlite3.connect(db_with_calibration)
    with con:
        con.execute("UPDATE calibrations SET params = 'not json' WHERE id = 1")
    con.close()
    for argv in (("export", "1", "--format", "json"), ("recompute", "1")):  # was: "Expecting value: line 1 ..."
        code, _, err = run(capsys, "--db", db_with_calibration, *argv)
        assert code == 2 and "not valid JSON" in one_line(err) and "station verify" in err, argv


def _read_only(db: str):
    """Make ``db`` unwritable for this user (chattr +i for root) and return what undoes it;
    skip where that cannot be done."""
    import shutil

    if os.geteuid() != 0:
        os.chmod(db, 0o444)
        return lambda: os.chmod(db, 0o644)
    if shutil.which("chattr") and subprocess.run(["chattr", "+i", db], capture_output=True).returncode == 0:
        return lambda: subprocess.run(["chattr", "-i", db], check=True)
    pytest.skip("cannot make a file read-only for root here")


def test_read_only_database_is_one_line(tmp_path, capsys, db_with_calibration):
    """A database the user may read but not write: reads work, writes are one line and exit 2."""
    db = str(db_with_calibration)  # its -wal and -shm stay writable, as in a shared read-only install
    undo = _read_only(db)
    try:
        code, out, err = run(capsys, "--db", db, "history", "SIM-LDV-0003")
        assert code == 0 and "1 calibration" in out, err
        code, _, err = run(capsys, "--db", db, "devices", "add", "NEW-1")  # was: sqlite3 traceback
        assert code == 2 and "readonly" in one_line(err).replace("read-only", "readonly")
    finally:
        undo()


def test_the_console_refuses_a_read_only_database_before_it_starts(tmp_path, capsys, db_with_calibration):
    """`station tui` on a database this user may read but not write started, and every F5 on
    Connect said "Cannot connect: attempt to write a readonly database" (a device that was fine;
    found at 80x24 in tmux). It is refused before the screen is drawn, in one line saying what
    to do; nothing in it changes. A writable one goes on to the console (here: no terminal).
    So is `station demo` unless --no-save: it failed after its whole run."""
    db = str(db_with_calibration)
    code, _, err = run(capsys, "--db", db, "tui")  # writable: past the database, to the terminal check
    assert code == 2 and "needs a terminal" in one_line(err)
    before = Path(db).read_bytes()
    undo = _read_only(db)
    try:
        code, out, err = run(capsys, "--db", db, "tui")
        # the demo saved only after its whole run: 'cannot process this input (OperationalError: ...)'
        demo = run(capsys, "--db", db, "demo", "--headless")
    finally:
        undo()
    line = one_line(err)
    assert code == 2 and out == ""
    assert line.startswith(f"station: {db}: cannot write the station database: attempt to write a readonly database")
    assert "make it writable, or give --db another file" in line
    code, out, err = demo
    assert code == 2 and out == "" and "cannot write the station database" in one_line(err) and "--no-save" in err
    assert Path(db).read_bytes() == before


@pytest.mark.parametrize("value", ["-1", "0", "nan", "inf"])
def test_calibrate_accuracy_must_be_positive(tmp_path, capsys, value):
    path = tmp_path / "g.csv"
    path.write_text("# station-capture: 1\n# procedure: gyro-drift\n# gyro_unit: rad/s\nt,gx,gy,gz\n0,1,2,3\n")
    code, _, err = run(capsys, "calibrate", path, "--accuracy", value)  # was: -1 accepted, a nonsense warning
    assert code == 2 and "--accuracy must be a positive number" in one_line(err)


@pytest.mark.parametrize(
    "argv",
    [
        ("simulate", "--procedure", "ldv", "--out", "{tmp}/x.csv", "--seed", "-1"),  # was: ValueError traceback
        ("walkthrough", "--procedure", "ldv", "--seed", "-1"),  # was: ValueError traceback
        ("devices", "add", "Y", "--kind", "bogus"),  # was: stored silently
        # was: "cannot process this input (ValueError: expected non-negative integer)", the catch-all
        ("demo", "--headless", "--no-save", "--seed", "-1"),
        ("sim-device", "--seed", "-1", "--seconds", "1"),
        ("tui", "--sim", "--seed", "-1"),
    ],
)
def test_argument_errors_exit_2(tmp_path, capsys, argv):
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    with pytest.raises(SystemExit) as exc:
        main(["--db", str(tmp_path / "s.db"), *argv])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "error: argument" in err and "Traceback" not in err
    assert err.count("\n") == 1 and "usage:" not in err, err  # was: the whole usage block first
    assert not (tmp_path / "x.csv").exists()


@pytest.mark.parametrize(
    "argv, needle",
    [
        (("calibrate", "--procedure", "foo", "x.csv"), "invalid choice: 'foo'"),
        (("calibrate",), "required: file"),
        (("frob",), "invalid choice: 'frob'"),
    ],
)
def test_usage_errors_are_one_line_naming_the_help(argv, needle):
    res = run_station(*argv, subprocess_run=True)  # was: 5-12 lines of usage before the error
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr.count("\n") == 1 and needle in res.stderr and "--help'" in res.stderr, res.stderr


@pytest.mark.parametrize("command", ["history", "drift"])
def test_unknown_procedure_filter_is_an_error(tmp_path, capsys, db_with_calibration, command):
    with pytest.raises(SystemExit) as exc:  # was: exit 0 with '0 calibrations of nope'
        main(["--db", str(db_with_calibration), command, "SIM-LDV-0003", "--procedure", "nope"])
    assert exc.value.code == 2 and "invalid choice: 'nope'" in capsys.readouterr().err


def test_record_out_a_folder_or_missing_folder_is_one_line_before_recording(tmp_path):
    import subprocess
    import sys

    for out, needle in ((tmp_path, "is a folder"), (tmp_path / "no" / "x.csv", "no folder")):
        r = subprocess.run(
            [sys.executable, "-m", "station", "record", "--port", "loop://", "--seconds", "1", "--out", str(out)],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert r.returncode == 2 and needle in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


@pytest.mark.parametrize("value", ["inf", "nan", "-1", "0"])
@pytest.mark.parametrize(
    "argv, option",
    [
        (("record", "--port", "/dev/null", "--out", "{tmp}/x.csv", "--seconds"), "--seconds"),
        (("record", "--port", "/dev/null", "--protocol", "mavlink", "--out", "{tmp}/x.csv", "--mavlink-rate"), None),
        (("sim-device", "--seconds"), "--seconds"),
        (("sim-device", "--hold"), "--hold"),
        (("demo", "--headless", "--no-save", "--average-s"), "--average-s"),
    ],
)
def test_a_duration_or_rate_that_is_no_positive_number_is_refused_before_anything_runs(tmp_path, argv, option, value):
    """`record --seconds inf` went on to open the port and record until killed, `sim-device
    --seconds nan` streamed forever, `--mavlink-rate nan` was sent to the flight controller, and
    `demo --average-s inf` would never finish a position: now one line naming the option, exit 2,
    before a port is opened (here /dev/null, which no port opens: the old code said so instead)."""
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    option = option or argv[-1]
    if option == "--mavlink-rate" and value == "0":
        value = "-0.5"  # 0 is documented: ask the flight controller for nothing
    res = run_station(*argv, value, subprocess_run=True)
    assert_one_line_refusal(res, f"{option} must be a positive number", f"got {value}")
    assert not (tmp_path / "x.csv").exists()


def _gyro_capture(tmp_path, rows: int | None = None, zero_accel: bool = False):
    from solvers.simulate import simulate
    from station.capture import Capture, write_capture

    sim = simulate("gyro-drift", seed=4, duration_s=20.0)
    cols = {k: v[:rows] if rows else v.copy() for k, v in sim.columns.items()}
    if zero_accel:
        for k in ("ax", "ay", "az"):
            cols[k] = cols[k] * 0.0
    path = tmp_path / "g.csv"
    write_capture(path, Capture(meta=sim.meta, columns=cols, path=str(path)))
    return path


@pytest.mark.parametrize("kind,needle", [("short", "static samples"), ("zero", "reads zero")])
def test_diagnose_degenerate_gyro_captures_are_one_line(tmp_path, kind, needle):
    import subprocess
    import sys

    path = _gyro_capture(tmp_path, rows=3 if kind == "short" else None, zero_accel=kind == "zero")
    r = subprocess.run([sys.executable, "-m", "station", "diagnose", str(path)], capture_output=True, text=True)
    assert r.returncode == 2 and needle in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


def test_an_unexpected_error_is_still_one_line(monkeypatch, capsys):
    """The CLI's last line of defence: a bug inside a command is one line and exit 2, and
    STATION_DEBUG=1 brings the traceback back for a developer."""
    import station.commands.walkthrough as wt
    from station.cli import main

    def boom(args):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(wt, "run", boom)
    monkeypatch.delenv("STATION_DEBUG", raising=False)
    assert main(["walkthrough"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "ZeroDivisionError" in err and "STATION_DEBUG" in err
    monkeypatch.setenv("STATION_DEBUG", "1")
    with pytest.raises(ZeroDivisionError):
        main(["walkthrough"])


def test_text_arguments_that_are_not_utf8_are_refused_naming_the_argument(tmp_path, ldv_capture):
    """`--device $'ab\\xff'` (a byte that is no UTF-8 character, from a script or a serial
    number read raw) failed inside SQLite's encoder and the line blamed the database: "cannot
    read the station database: 'utf-8' codec can't encode ...". Now the argument is named,
    its bytes shown escaped, and no database is made. A file name may hold such bytes."""
    import os

    db = tmp_path / "s.db"
    cases = [
        ([b"calibrate", os.fsencode(ldv_capture), b"--save", b"--device", b"ab\xff\x1b"], "--device 'ab\\xff\\x1b'"),
        ([b"devices", b"add", b"X\xfe"], "id 'X\\xfe'"),
        ([b"devices", b"add", b"X", b"--limit", b"dr\xffift=1:2"], "--limit 'dr\\xffift=1:2'"),
    ]
    for argv, says in cases:
        res = subprocess.run(
            [os.fsencode(sys.executable), b"-m", b"station", *argv, b"--db", os.fsencode(db)],
            cwd=ROOT,
            capture_output=True,
            timeout=120,
        )
        err = res.stderr.decode("utf-8")
        assert res.returncode == 2 and res.stdout == b"" and err.count("\n") == 1, err
        assert err.startswith(f"station: {says}: not UTF-8 text (byte 0x"), err
        assert "database" not in err and not db.exists()
    odd = tmp_path / os.fsdecode(b"n\xffame.csv")
    odd.write_bytes(ldv_capture.read_bytes())
    res = subprocess.run(
        [sys.executable, "-m", "station", "calibrate", str(odd)], cwd=ROOT, capture_output=True, timeout=120
    )
    assert res.returncode == 0, res.stderr


@pytest.mark.parametrize(
    "argv",
    [
        ("calibrate", "{tmp}/c.csv", "--device", ""),  # was: the capture's device, without a word
        ("calibrate", "{tmp}/c.csv", "--device", "  "),
        ("history", ""),
        ("devices", "add", " "),
    ],
)
def test_an_empty_device_id_is_refused(tmp_path, argv):
    path = tmp_path / "c.csv"
    path.write_text(
        "# station-capture: 1\n# procedure: gyro-drift\n# device: G-1\n# gyro_unit: rad/s\nt,gx,gy,gz\n0,1,2,3\n"
    )
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    assert_one_line_refusal(run_station("--db", tmp_path / "s.db", *argv), "a device id must be non-empty text")
    assert not (tmp_path / "s.db").exists() or "G-1" not in (tmp_path / "s.db").read_bytes().decode("latin-1")


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (
            [
                "simulate",
                "--procedure",
                "ldv",
                "--out",
                "{out}",
                "--option",
                "duration_s=10",
                "--option",
                "duration_s=20",
            ],
            "--option: duration_s given twice",
        ),
        (
            ["simulate", "--procedure", "ldv", "--out", "{out}", "--effect", "offset=1", "--effect", " offset=5"],
            "--effect: offset given twice",
        ),
        (["devices", "add", "D", "--tolerance", "B=1", "--tolerance", "B=2"], "--tolerance: B given twice"),
        (["devices", "add", "D", "--limit", "B=1:2", "--limit", "B=3:4"], "--limit: B given twice"),
    ],
    ids=["simulate-option", "simulate-effect", "devices-tolerance", "devices-limit"],
)
def test_a_name_given_twice_is_refused_as_import_refuses_it(tmp_path, capsys, argv, says):
    """`--option duration_s=10 --option duration_s=20` simulated 20 s, `--tolerance B=1
    --tolerance B=2` stored 2, without a word (the last one won); import's --map, --unit and
    --topic refuse a name given twice. So do these, before anything is written."""
    out = tmp_path / "sim.csv"
    code, stdout, err = run(capsys, "--db", tmp_path / "station.db", *[a.format(out=out) for a in argv])
    assert code == 2 and stdout == "" and says in one_line(err), err
    assert sorted(os.listdir(tmp_path)) == []


@pytest.mark.parametrize(
    "argv", [["calibrate", "{cap}", "--save", "--device", "D"], ["devices", "add", "E"]], ids=["save", "devices-add"]
)
def test_a_database_another_connection_holds_is_named_as_such_and_left_as_it_was(
    tmp_path, capsys, ldv_capture, monkeypatch, argv
):
    """A second connection holding a write transaction (another station saving, a sqlite3
    shell left in BEGIN) past the busy wait gave 'database is locked', which read as a
    damaged file. The line says another process held it, for how long, and that nothing was
    written; the holder's transaction and the file are untouched. (The 30 s wait is shortened.)"""
    import sqlite3

    import db.store

    db_file = tmp_path / "station.db"
    assert run(capsys, "--db", db_file, "devices", "add", "D")[0] == 0
    monkeypatch.setattr(db.store, "BUSY_TIMEOUT_S", 0.2)
    holder = sqlite3.connect(db_file, isolation_level=None)
    holder.execute("BEGIN IMMEDIATE")  # the write lock, as a save in progress holds it
    try:
        code, out, err = run(capsys, "--db", db_file, *[a.format(cap=ldv_capture) for a in argv])
    finally:
        holder.execute("ROLLBACK")
        holder.close()
    assert code == 2 and out == ""
    line = one_line(err)
    assert str(db_file) in line and "another process held it" in line and "nothing written" in line, line
    code, out, _ = run(capsys, "--db", db_file, "verify")
    assert code == 0, out


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full on this system")
@pytest.mark.parametrize("command", ["calibrate", "calibrate-json", "export-capture", "inspect"])
def test_a_full_standard_output_is_named_not_blamed_on_the_input(tmp_path, ldv_capture, db_with_calibration, command):
    """`station export-capture 1 > cap.csv` on a full disk said 'ldv.csv: cannot process this
    input (OSError: No space left on device)', blaming the capture; a short result failed only
    at exit, with Python's 'Exception ignored' lines. One line names standard output."""
    argv = {
        "calibrate": ["calibrate", ldv_capture],
        "calibrate-json": ["calibrate", ldv_capture, "--json"],
        "export-capture": ["--db", db_with_calibration, "export-capture", "1"],
        "inspect": ["inspect", ldv_capture],
    }[command]
    with open("/dev/full", "w") as full:
        res = subprocess.run(
            [sys.executable, "-m", "station", *map(str, argv)],
            stdout=full,
            stderr=subprocess.PIPE,
            text=True,
            timeout=120,
        )
    assert res.returncode == 2, res.stderr
    assert res.stderr == "station: cannot write standard output: No space left on device\n", res.stderr


def _subparsers(parser):
    """(name, parser) of every subcommand of ``parser``, nested ones too (`devices add`)."""
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield name, sub
                for inner, subsub in _subparsers(sub):
                    yield f"{name} {inner}", subsub


def test_every_help_fits_an_80_column_terminal(monkeypatch, capsys):
    """`station history --help` and five others printed a usage line of 91–105 columns
    (argparse lists --procedure's choices there unwrapped): at 80x24 over SSH it wrapped into
    the next line's column. Every command's help is at most 80 columns; the choices are in
    the option's help, which wraps."""
    from station.cli import build_parser

    monkeypatch.setenv("COLUMNS", "80")
    parser = build_parser()
    wide = {}
    for name, sub in [("station", parser), *_subparsers(parser)]:
        lines = [line for line in sub.format_help().splitlines() if len(line) > 80]
        if lines:
            wide[name] = lines
    assert not wide, wide
    # a wrong name is still answered with the names to choose from
    with pytest.raises(SystemExit) as exc:
        main(["simulate", "--procedure", "p9", "--out", "x.csv"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "accel-tabletop" in err and "ldv" in err


def test_no_help_shows_a_doubled_percent_sign(monkeypatch):
    """argparse %-formats an option's help but not a description unless it holds '%(prog)':
    `station noise --help` said '68 %% confidence intervals'."""
    from station.cli import build_parser

    monkeypatch.setenv("COLUMNS", "80")
    parser = build_parser()
    doubled = {name: sub.format_help() for name, sub in [("station", parser), *_subparsers(parser)]}
    assert not {name: text for name, text in doubled.items() if "%%" in text}
    assert "68 % confidence" in " ".join(doubled["noise"].split())


def test_help_names_the_database_this_machine_uses(tmp_path, monkeypatch):
    """`--db`'s help said ~/.local/share/station/station.db whatever XDG_DATA_HOME said: it
    gives the rule and the path it comes to here."""
    monkeypatch.delenv("STATION_DB", raising=False)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    res = run_station("--help", subprocess_run=True)
    assert res.returncode == 0
    assert str(tmp_path / "data" / "station" / "station.db") in " ".join(res.stdout.split()).replace("- ", "-")
