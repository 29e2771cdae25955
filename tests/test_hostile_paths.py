"""Paths that are not plain files, given where a command reads a file: a named pipe (FIFO)
blocked every reading command for ever, a character device was read as if it were data.
Each is refused before anything opens it: one line on stderr naming the path, exit status 2,
nothing on stdout, nothing written. The real CLI in a subprocess, with a timeout, so a
command that blocks fails the test instead of hanging it.
"""

from __future__ import annotations

import os
import stat
import subprocess
import sys

import pytest

from tests.station_run import ROOT, assert_one_line_refusal, run_station

GYRO_CSV = ("--procedure", "gyro-drift", "--map", "t=time_s,gx=gx,gy=gy,gz=gz", "--unit", "gyro=rad/s,t=s")


def _station(*args, timeout: float = 120) -> subprocess.CompletedProcess:
    try:
        return subprocess.run(
            [sys.executable, "-m", "station", *map(str, args)],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=timeout,
            stdin=subprocess.DEVNULL,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"station {' '.join(map(str, args))}: still running after {timeout} s (blocked on its input)")


# (command before the file, command after it, the file's name): every way a file is read
READERS = [
    (["calibrate"], [], "x.csv"),
    (["diagnose"], ["--no-plots"], "x.csv"),
    (["inspect"], [], "x.csv"),
    (["noise"], ["--no-plot"], "x.csv"),
    (["import"], [*GYRO_CSV, "--out", "{out}"], "x.csv"),
    (["import"], ["--procedure", "gyro-drift", "--out", "{out}"], "x.csv"),
    (["import"], ["--procedure", "gyro-drift", "--format", "euroc", "--out", "{out}"], "data.csv"),
    (["calibrate"], ["--procedure", "compass"], "x.bin"),
    (["calibrate"], ["--procedure", "compass"], "x.tlog"),
    (["calibrate"], ["--procedure", "compass"], "x.ulg"),
    (["inspect"], ["--procedure", "compass"], "x.bag"),
    (["record", "--recover"], [], "x.csv.partial"),
]


@pytest.mark.parametrize(("before", "after", "name"), READERS, ids=lambda v: " ".join(v) if isinstance(v, list) else v)
def test_a_named_pipe_is_refused_not_waited_on(tmp_path, before, after, name):
    fifo = tmp_path / name
    os.mkfifo(fifo)
    out = tmp_path / "out.csv"
    res = _station(*before, fifo, *[a.format(out=out) for a in after], timeout=60)
    assert_one_line_refusal(res, f"{fifo}: ", "named pipe (FIFO), not a regular file")
    assert not out.exists()


@pytest.mark.parametrize("command", [["inspect"], ["noise", "--no-plot"], ["import", *GYRO_CSV, "--out", "{out}"]])
def test_a_character_device_is_refused_by_what_it_is(tmp_path, command):
    """/dev/null reads as an empty file and /dev/zero as endless NUL bytes: neither is a capture
    or a log, and a serial port or a terminal given by mistake would block; all are refused
    by their kind before they are opened."""
    out = tmp_path / "out.csv"
    for dev in ("/dev/null", "/dev/zero"):
        res = _station(command[0], dev, *[a.format(out=out) for a in command[1:]], timeout=60)
        assert_one_line_refusal(res, f"{dev}: ", "character device, not a regular file")
    assert not out.exists()


@pytest.mark.parametrize("command", [["inspect"], ["calibrate"], ["noise"], ["import", *GYRO_CSV, "--out", "{out}"]])
def test_a_path_with_a_newline_keeps_the_refusal_on_one_line(tmp_path, command):
    """The file name is part of the one line: its newline (or any control character) is shown
    escaped, so the refusal stays one line a script can read."""
    path = tmp_path / "bad\nname\x1b[31m.csv"
    path.write_text("not a capture\n")
    out = tmp_path / "out.csv"
    res = _station(command[0], path, *[a.format(out=out) for a in command[1:]])
    assert_one_line_refusal(res, "bad\\nname\\x1b[31m.csv")
    assert not out.exists()


@pytest.mark.parametrize(
    ("suffix", "says"),
    [
        (".bin", "no IMU, ACC/GYR, ISBH/ISBD or MAG messages"),
        (".tlog", "no RAW_IMU / SCALED_IMU / HIGHRES_IMU messages"),
        (".bag", "not a ROS 1 bag"),
    ],
)
def test_a_2_gib_sparse_file_of_zeros_as_a_log_is_refused_at_once(tmp_path, suffix, says):
    """2 GiB of NUL bytes named as a log: pymavlink searched it byte by byte for a message
    (more than 2 minutes, 3 GB of memory), the ROS bag reader took 75 s and 4 GB to say "File
    magic is invalid"; a log that does not start as its format says is refused before."""
    log = tmp_path / f"zeros{suffix}"
    with open(log, "wb") as f:
        f.truncate(2 << 30)
    out = tmp_path / "out.csv"
    res = _station("import", log, "--procedure", "gyro-drift", "--out", out, timeout=60)
    assert_one_line_refusal(res, f"{log}: ", says, "first 1 MiB" if suffix != ".bag" else "#ROSBAG V2.0")
    assert not out.exists()


@pytest.mark.parametrize(
    "command",
    [
        ["simulate", "--procedure", "compass", "--seed", "1", "--out", "{target}"],
        ["import", "{src}", *GYRO_CSV, "--out", "{target}"],
        ["noise", "{still}", "--format", "kalibr", "--no-plot", "--out", "{target}"],
    ],
    ids=["simulate", "import", "noise-kalibr"],
)
def test_an_output_path_that_is_no_regular_file_is_refused_not_replaced(tmp_path, shared_data, command):
    """The atomic write renames its new file over the target: a named pipe (or, for root,
    /dev/null) given as --out was replaced by a regular file without a word. It is refused and
    left as it was."""
    target = tmp_path / "out.fifo"
    os.mkfifo(target)
    src = tmp_path / "in.csv"
    src.write_text("time_s,gx,gy,gz\n" + "".join(f"{i * 0.01:.2f},0.01,0.02,-0.01\n" for i in range(400)))
    still = shared_data / "sunsided_marg" / "sunsided_unmoved_x_forward.capture.csv"
    res = _station(*[a.format(target=target, src=src, still=still) for a in command], timeout=60)
    assert_one_line_refusal(res, f"{target}: ", "named pipe (FIFO), not a regular file")
    assert stat.S_ISFIFO(os.stat(target).st_mode)
    assert sorted(os.listdir(tmp_path)) == ["in.csv", "out.fifo"]


def test_a_file_name_with_a_newline_is_one_field_in_a_result(tmp_path):
    """A result names its file in one field: inspect's 'file:' line, import's and simulate's
    summary line; a newline in the name is shown escaped instead of forging a line."""
    sim = tmp_path / "sim\nname.csv"
    res = _station("simulate", "--procedure", "gyro-drift", "--seed", "1", "--out", sim)
    assert res.returncode == 0, res.stderr
    assert res.stdout.count("\n") == 1 and "sim\\nname.csv" in res.stdout, res.stdout
    res = _station("inspect", sim)
    assert res.returncode == 0, res.stderr
    assert res.stdout.splitlines()[0].endswith("sim\\nname.csv") and res.stdout.splitlines()[1].startswith("procedure:")
    src = tmp_path / "bench\nfile.csv"
    src.write_text("time_s,gx,gy,gz\n" + "".join(f"{i * 0.01:.2f},0.01,0.02,-0.01\n" for i in range(400)))
    out = tmp_path / "out\nfile.csv"
    res = _station("import", src, *GYRO_CSV, "--out", out)
    assert res.returncode == 0, res.stderr
    assert res.stdout.count("\n") == 1 and "out\\nfile.csv" in res.stdout, res.stdout


def test_record_refuses_an_output_that_is_no_regular_file_before_recording(tmp_path):
    """record writes its capture only at the end (atomically): a named pipe as --out was found
    out after the whole recording. It is refused before the port is opened."""
    target = tmp_path / "out.fifo"
    os.mkfifo(target)
    res = _station("record", "--port", tmp_path / "no-such-port", "--seconds", "1", "--out", target, timeout=60)
    assert_one_line_refusal(res, f"{target}: ", "named pipe (FIFO), not a regular file")
    assert stat.S_ISFIFO(os.stat(target).st_mode)


@pytest.mark.parametrize(
    "command",
    [
        ["simulate", "--procedure", "gyro-drift", "--seed", "1", "--out", "-"],
        ["simulate", "--procedure", "gyro-drift", "--seed", "1", "--out", "{sim}", "--truth", "-"],
        ["import", "{src}", *GYRO_CSV, "--out", "-"],
        ["noise", "{still}", "--format", "kalibr", "--no-plot", "--out", "-"],
        ["record", "--port", "{port}", "--seconds", "1", "--out", "-"],
    ],
    ids=["simulate", "simulate-truth", "import", "noise-kalibr", "record"],
)
def test_dash_as_an_output_file_is_refused_not_written_as_a_file_named_dash(tmp_path, shared_data, command):
    """'-' is standard output to the operator (report -o -, export -o -); these commands write
    only files and made one named '-' in the current folder (simulate --truth - beside a
    complete capture). Refused before anything runs; a file named '-' is still ./-."""
    src = tmp_path / "in.csv"
    src.write_text("time_s,gx,gy,gz\n" + "".join(f"{i * 0.01:.2f},0.01,0.02,-0.01\n" for i in range(400)))
    still = shared_data / "sunsided_marg" / "sunsided_unmoved_x_forward.capture.csv"
    sim = tmp_path / "sim.csv"
    args = [a.format(src=src, still=still, sim=sim, port=tmp_path / "no-such-port") for a in command]
    res = subprocess.run(
        [sys.executable, "-m", "station", *args], cwd=tmp_path, capture_output=True, text=True, timeout=120
    )
    assert_one_line_refusal(res, "'-'", "standard output")
    assert sorted(os.listdir(tmp_path)) == ["in.csv"]


def _signal_while_writing(tmp_path, signum):
    """`station simulate --out tmp_path/s.csv` (a long capture) sent ``signum`` once its
    hidden temporary is there: (process, stdout, stderr) after it ends; the test is skipped
    when the write finished before the signal arrived."""
    import time

    proc = subprocess.Popen(
        [sys.executable, "-m", "station", "simulate", "--procedure", "accel-tabletop", "--option", "hold_s=400",
         "--out", str(tmp_path / "s.csv")],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    deadline = time.monotonic() + 120
    while not any(p.name.endswith(".tmp") for p in tmp_path.iterdir()) and proc.poll() is None:
        assert time.monotonic() < deadline, "no temporary file appeared"
        time.sleep(0.01)
    proc.send_signal(signum)
    stdout, stderr = proc.communicate(timeout=120)
    if proc.returncode == 0:  # the write finished first: nothing to test on this machine this time
        pytest.skip("the capture was written before the signal arrived")
    return proc, stdout, stderr


def test_sigterm_while_an_output_is_written_leaves_neither_it_nor_its_temporary(tmp_path):
    """kill, timeout(1) and systemd stop a command with SIGTERM, which ended Python at once:
    the atomic write's hidden temporary (tens of MB, .s.csv.<random>.tmp) stayed beside the
    output for good. SIGTERM now unwinds like Ctrl-C: the temporary is removed, the output
    is absent, one line says so, exit status 143 (128 + SIGTERM)."""
    import signal

    proc, stdout, stderr = _signal_while_writing(tmp_path, signal.SIGTERM)
    assert proc.returncode == 143, (proc.returncode, stderr)
    assert stdout == "" and stderr == "station: terminated\n", stderr
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("option", ["--unit", "--topic", "--map"])
@pytest.mark.parametrize("value", ["", " ", ","])
def test_an_empty_import_option_is_refused_not_taken_as_left_out(tmp_path, shared_data, option, value):
    """`--unit "$UNITS"` with the variable unset: an empty value was read as no option at all,
    and a PX4 log (whose units come from the file, where --unit is refused) was imported as if
    nothing had been asked. Refused in one line naming the option; nothing written."""
    log = shared_data / "px4_ulog" / "original" / "sample.ulg"
    out = tmp_path / "c.csv"
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "station",
            "import",
            str(log),
            "--procedure",
            "gyro-drift",
            option,
            value,
            "--out",
            str(out),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert_one_line_refusal(res, option, "empty")
    assert not out.exists()


@pytest.mark.parametrize("kind", ["fifo", "device", "loop"])
@pytest.mark.parametrize("command", ["devices", "save"])
def test_a_database_path_that_is_no_regular_file_is_named_by_what_it_is(tmp_path, kind, command):
    """--db naming a named pipe or a device was 'disk I/O error' from SQLite, and a loop of
    symbolic links 'no station database here' (reading) or 'unable to open database file'
    (saving): none said what the path is."""
    db = tmp_path / "station.db"
    if kind == "fifo":
        os.mkfifo(db)
        says = "a named pipe (FIFO), not a database file"
    elif kind == "device":
        db = os.devnull
        says = "a character device, not a database file"
    else:
        os.symlink(tmp_path / "other.db", tmp_path / "other.db.link")
        os.symlink(tmp_path / "other.db.link", tmp_path / "other.db")
        os.symlink(tmp_path / "other.db", db)
        says = "Too many levels of symbolic links"
    if command == "devices":
        res = _station("--db", db, "devices")
    else:
        capture = tmp_path / "p1.csv"
        made = _station("simulate", "--procedure", "accel-tabletop", "--option", "averages=1", "--out", capture)
        assert made.returncode == 0, made.stderr
        res = _station("--db", db, "calibrate", capture, "--save")
    assert_one_line_refusal(res, f"{db}: ", says)
    if kind == "fifo":
        assert stat.S_ISFIFO(os.stat(db).st_mode)


def test_a_killed_writes_temporary_is_removed_by_the_next_write_of_the_file(tmp_path):
    """SIGKILL (the OOM killer, a power cut) runs no handler: the atomic write's hidden
    temporary stayed beside the output for good. Its name carries the writer's pid now, and
    the next write of the same file removes a temporary whose process is gone; a live writer's
    is left alone."""
    import signal
    import time

    from station import fileio

    out = tmp_path / "s.csv"
    proc, _, _ = _signal_while_writing(tmp_path, signal.SIGKILL)
    (left,) = [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    assert left.name.startswith(f".s.csv.{proc.pid}-")
    live = tmp_path / f".s.csv.{os.getpid()}-0123abcd.tmp"  # a write of this process, under way
    live.write_text("x")
    old = time.time() - 2 * fileio.STALE_TMP_S
    for p in (left, live):
        os.utime(p, (old, old))
    res = run_station("simulate", "--procedure", "accel-tabletop", "--out", out)
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([live.name, "s.csv"])
