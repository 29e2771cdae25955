"""`station record --recover FILE.partial`: the rows a killed recording left become a capture
the station reads, or the file is refused on the line that is wrong and nothing is written.

Every partial file here starts as the real bytes of `station record` on `station sim-device`,
killed with SIGKILL, then cut or damaged the way a kill or a power cut leaves a file: a row
written part-way (no line end), a tail of NUL bytes (blocks the file system had allotted but
never written), a row broken in the middle. The real CLI reads them; `read_capture` and
`station inspect` read what it wrote.
"""

from __future__ import annotations

import fcntl
import os
import signal
import subprocess
import sys
import termios
from pathlib import Path

import numpy as np
import pytest

from station.capture import read_capture
from tests.station_run import ROOT, assert_one_line_refusal, popen_station, run_station, sim_device, wait_for_rows

HEADER = b"t,segment,ax,ay,az,gx,gy,gz,mx,my,mz,temp_c\n"


@pytest.fixture(scope="module")
def sim_port():
    """One `station sim-device` (500 Hz, seed 7) for the module's recordings."""
    with sim_device("--rate", "500", "--seed", "7") as sim:
        yield sim.port
    assert sim.returncode == 0, sim.stderr


@pytest.fixture(scope="module")
def killed(sim_port, tmp_path_factory) -> bytes:
    """The partial file of a `station record` killed with SIGKILL: its head and whole rows
    (whatever the kill left after the last line end is cut off here, so each test makes its
    own tail)."""
    out = tmp_path_factory.mktemp("killed") / "k.csv"
    partial = Path(str(out) + ".partial")
    rec = popen_station("record", "--port", sim_port, "--out", str(out))
    wait_for_rows(partial, 40_000)
    rec.kill()
    rec.wait(10)
    rec.stdout.close()
    rec.stderr.close()
    assert not out.exists()
    data = partial.read_bytes()
    data = data[: data.rfind(b"\n") + 1]
    assert b"# complete: false\n" in data and HEADER in data and data.count(b"\n") > 200
    return data


def _layout(data: bytes) -> tuple[int, int]:
    """(the header's line number, the byte offset where the data rows start)."""
    start = data.index(HEADER) + len(HEADER)
    return data[:start].count(b"\n"), start


def _recover(tmp_path: Path, content: bytes):
    partial = tmp_path / "k.csv.partial"
    partial.write_bytes(content)
    return partial, run_station("record", "--recover", partial)


def _assert_recovered(res, partial: Path, rows: list[bytes]) -> None:
    """Exit 0, the capture beside the partial holds exactly ``rows`` (and nothing else),
    reads back with the station's reader and `inspect`, and the partial is gone."""
    out = partial.with_suffix("")
    assert res.returncode == 0, res.stderr
    assert res.stdout == f"recovered {partial} -> {out}: {len(rows)} rows\n"
    assert not partial.exists()
    text = out.read_bytes()
    assert text.endswith(HEADER + b"".join(rows))
    cap = read_capture(out)
    assert cap.meta["complete"] == "false" and cap.meta["recovered"] == "true" and not cap.notes
    assert cap.n_rows == len(rows)
    np.testing.assert_array_equal(cap.columns["t"], [float(r.split(b",")[0]) for r in rows])
    assert run_station("inspect", out).returncode == 0


# where the kill cut the file, as (row the cut falls in, bytes of that row written)
CUTS = {
    "after a line end": (60, 0),
    "one byte of a row": (60, 1),
    "half a row": (60, None),
    "all but the line end": (60, -1),  # every field there, the last value maybe cut: dropped too
    "all but the last digit": (60, -2),  # '...,24' cut to '...,2': reads as a valid row
}


@pytest.mark.parametrize("cut", CUTS.values(), ids=CUTS.keys())
def test_a_row_cut_by_the_kill_is_dropped_on_its_line_and_every_whole_row_kept(killed, tmp_path, cut):
    header_line, start = _layout(killed)
    rows = killed[start:].splitlines(keepends=True)
    k, n = cut
    torn = rows[k][: len(rows[k]) // 2 if n is None else n]
    partial, res = _recover(tmp_path, killed[:start] + b"".join(rows[:k]) + torn)
    _assert_recovered(res, partial, rows[:k])
    if not torn:
        assert res.stderr == ""
        return
    line = header_line + k + 1
    assert res.stderr == (
        f"station record: {partial}:{line}: the last line has no line end (a row the recording was "
        f"writing when it stopped, {len(torn)} byte{'s' if len(torn) > 1 else ''}): dropped\n"
    )


@pytest.mark.parametrize("whole_rows", [True, False], ids=["after a line end", "inside a row"])
def test_a_tail_of_nul_bytes_left_by_a_power_cut_is_dropped_and_every_whole_row_kept(killed, tmp_path, whole_rows):
    """A power cut can leave the file's last blocks allotted but never written: the size says
    4096-byte blocks more, and they read as NUL bytes, with no line end among them."""
    header_line, start = _layout(killed)
    rows = killed[start:].splitlines(keepends=True)
    kept = killed[:start] + b"".join(rows[:80])
    torn = b"" if whole_rows else rows[80][:17]
    pad = b"\0" * (2 * 4096 - (len(kept) + len(torn)) % 4096)
    partial, res = _recover(tmp_path, kept + torn + pad)
    _assert_recovered(res, partial, rows[:80])
    assert res.stderr.count("\n") == 1, res.stderr
    assert res.stderr.startswith(f"station record: {partial}:{header_line + 81}: the last line has no line end (")
    assert (
        f"{len(pad)} NUL bytes" in res.stderr
        and ("a row cut short" in res.stderr) == bool(torn)
        and res.stderr.endswith(": dropped\n")
    )


def _swap(row: bytes, column: int, value: bytes) -> bytes:
    fields = row.split(b",")
    fields[column] = value
    return b",".join(fields)


# damage to the rows before the last one: (make the damaged data rows from the whole ones, the
# 0-based data row the refusal names, what it says)
BAD = {
    "a number that is not one": (
        lambda r: [*r[:50], _swap(r[50], 2, b"abc"), *r[51:]],
        50,
        "column 'ax': 'abc' is not a number",
    ),
    "the QA's row '1,abc' last, with its line end": (
        lambda r: [*r, b"1,abc\n"],
        -1,
        "too few fields: 2 where the header has 12 columns",
    ),
    "a row cut short, rows after it": (lambda r: [*r[:50], r[50][:30] + b"\n", *r[51:]], 50, "too few fields"),
    "a block of NUL bytes, rows after it": (
        lambda r: [*r[:50], b"\0" * 4096 + r[50], *r[51:]],
        50,
        "NUL byte at column 1: binary data",
    ),
    "t going backwards": (lambda r: [*r[:50], _swap(r[50], 0, b"0.000000"), *r[51:]], 50, "t goes backwards"),
    "a blank line": (lambda r: [*r[:50], b"\n", *r[50:]], 50, "blank line inside the data"),
}


@pytest.mark.parametrize("torn_tail", [False, True], ids=["", "and a cut last row"])
@pytest.mark.parametrize("damage", BAD.values(), ids=BAD.keys())
def test_a_partial_with_a_bad_row_before_its_end_is_refused_on_that_line_and_nothing_written(
    killed, tmp_path, damage, torn_tail
):
    """`1,abc` in a data row was 'recovered' with exit 0 into a capture `station inspect`
    refused. A row that is wrong before the last line is no cut the kill made: refused with
    the partial's own line number, the partial kept as it was, nothing written beside it."""
    header_line, start = _layout(killed)
    make, k, says = damage
    rows = make(killed[start:].splitlines(keepends=True))
    content = killed[:start] + b"".join(rows) + (b"12.0,0,2.49" if torn_tail else b"")
    partial, res = _recover(tmp_path, content)
    line = header_line + 1 + (k if k >= 0 else len(rows) + k)
    assert_one_line_refusal(res, f"station: {partial}:{line}: {says}")
    assert partial.read_bytes() == content and os.listdir(tmp_path) == ["k.csv.partial"]


@pytest.mark.parametrize(
    ("keep", "says"),
    [
        (lambda d, s: d[:s], "no complete data row to recover"),  # killed before the first row
        (lambda d, s: d[:s] + b"0.000000,0,2.4", "no complete data row to recover"),
        (lambda d, s: d[: s - 10], "no complete data row to recover"),  # the header row cut
        (lambda d, s: d[: s - 10] + b"\0" * 4096, "no complete data row to recover (the head is cut short on line"),
        (lambda d, s: d[: d.index(b"# source:") + 5], "no complete data row to recover (the head is cut short on line"),
    ],
    ids=["head only", "head and a cut row", "header row cut", "header row cut, NUL tail", "metadata line cut"],
)
def test_a_partial_without_a_whole_row_is_refused_and_nothing_written(killed, tmp_path, keep, says):
    _, start = _layout(killed)
    content = keep(killed, start)
    partial, res = _recover(tmp_path, content)
    assert_one_line_refusal(res, f"station: {partial}", says)
    assert partial.read_bytes() == content and os.listdir(tmp_path) == ["k.csv.partial"]


def test_recover_run_twice_keeps_the_capture_it_wrote(killed, tmp_path):
    """The second run finds no partial: one line saying so (and that the capture is there),
    exit 2, the capture untouched. A run stopped after writing the capture but before
    removing the partial (the partial still there) recovers it again into the same bytes."""
    content = killed + b"99.5,0,2.4"
    partial, res = _recover(tmp_path, content)
    assert res.returncode == 0, res.stderr
    out = partial.with_suffix("")
    written = out.read_bytes()
    again = run_station("record", "--recover", partial)
    assert_one_line_refusal(again, f"station: {partial}: no such file", f"{out} is there")
    assert out.read_bytes() == written and os.listdir(tmp_path) == ["k.csv"]
    partial.write_bytes(content)  # as if the first run had stopped before removing it
    third = run_station("record", "--recover", partial)
    assert third.returncode == 0, third.stderr
    assert out.read_bytes() == written and os.listdir(tmp_path) == ["k.csv"]


HUNG_UP = "station record: hang-up (SIGHUP: the terminal or SSH session closed): the recording ended as on Ctrl-C"


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=["SIGINT", "SIGTERM", "SIGHUP"])
def test_an_interrupted_recording_leaves_a_capture_and_nothing_for_recover_to_break(sim_port, tmp_path, sig):
    """Ctrl-C, SIGTERM or a hang-up (the SSH session dropped) ends a recording with its capture
    finished (no partial left); `--recover` afterwards says there is nothing to recover and
    leaves the capture as it was. A hang-up killed `record` where it stood (the rows left in
    FILE.partial for `--recover`); it is said on stderr, which is still there to write here."""
    out = tmp_path / "s.csv"
    partial = Path(str(out) + ".partial")
    rec = popen_station("record", "--port", sim_port, "--out", str(out))
    try:
        wait_for_rows(partial, 5000)
        rec.send_signal(sig)
        stdout, stderr = rec.communicate(timeout=60)
    finally:  # a recording left running holds its port's pty and the next test's reader hangs
        if rec.poll() is None:
            rec.kill()
            rec.communicate()
    assert rec.returncode == 0, stderr
    assert stdout.startswith("recorded ")
    assert stderr == (f"{HUNG_UP}; {out} is complete\n" if sig == signal.SIGHUP else ""), stderr
    assert not partial.exists()
    written = out.read_bytes()
    cap = read_capture(out)
    assert cap.meta["complete"] == "true" and cap.n_rows > 10 and not cap.notes
    assert f"{cap.n_rows} samples" in stdout
    res = run_station("record", "--recover", partial)
    assert_one_line_refusal(res, f"station: {partial}: no such file", f"{out} is there")
    assert out.read_bytes() == written and os.listdir(tmp_path) == ["s.csv"]


def test_a_hang_up_before_the_seconds_asked_keeps_the_rows_marked_incomplete_as_ctrl_c_does(sim_port, tmp_path):
    """`--seconds 120` cut short by a hang-up: as by Ctrl-C, every row kept in a finished capture
    that says it is shorter than asked, exit status 1."""
    out = tmp_path / "s.csv"
    partial = Path(str(out) + ".partial")
    rec = popen_station("record", "--port", sim_port, "--seconds", "120", "--out", str(out))
    try:
        wait_for_rows(partial, 5000)
        rec.send_signal(signal.SIGHUP)
        stdout, stderr = rec.communicate(timeout=60)
    finally:
        if rec.poll() is None:
            rec.kill()
            rec.communicate()
    assert rec.returncode == 1, stderr
    assert "INCOMPLETE: interrupted" in stdout and not partial.exists()
    assert stderr.endswith(f"{HUNG_UP}; {out} is complete: false (interrupted)\n"), stderr
    cap = read_capture(out)
    assert cap.meta["complete"] == "false" and cap.meta["incomplete"].startswith("interrupted ")
    assert cap.n_rows > 10 and not cap.notes


def test_a_recording_whose_ssh_session_drops_finishes_its_capture(sim_port, tmp_path):
    """The operator's SSH session drops (no tmux): the kernel hangs up the terminal `record`
    runs in, which sends SIGHUP to it and makes its stdout and stderr unwritable (EIO). Here
    the terminal is a real pty that is `record`'s controlling terminal (it leads its session,
    as a login shell's job does when the shell has gone), and closing its master side is the
    dropped connection. The recording was killed, its rows left in FILE.partial; it finishes
    its capture now, and exits as on SIGTERM (status 0) though nothing can be said."""
    out = tmp_path / "ssh.csv"
    partial = Path(str(out) + ".partial")
    master, slave = os.openpty()

    def own_terminal() -> None:  # in the child, after setsid: the pty becomes its terminal
        fcntl.ioctl(1, termios.TIOCSCTTY, 0)
        signal.signal(signal.SIGHUP, signal.SIG_DFL)  # as a login shell's job has it, under nohup too

    rec = subprocess.Popen(
        [sys.executable, "-m", "station", "record", "--port", sim_port, "--out", str(out)],
        cwd=ROOT,
        stdin=subprocess.DEVNULL,
        stdout=slave,
        stderr=slave,
        start_new_session=True,
        preexec_fn=own_terminal,  # noqa: PLW1509 - one call, no threads started in the child
    )
    os.close(slave)
    try:
        try:
            wait_for_rows(partial, 5000)
        finally:
            os.close(master)  # the connection drops: the terminal hangs up
        assert rec.wait(60) == 0
    finally:
        if rec.poll() is None:
            rec.kill()
            rec.wait()
    assert not partial.exists()
    cap = read_capture(out)
    assert cap.meta["complete"] == "true" and cap.n_rows > 10 and not cap.notes
    assert run_station("inspect", out).returncode == 0


def test_a_killed_recording_leaves_a_partial_that_recover_makes_readable(sim_port, tmp_path):
    """A kill (SIGKILL, or a power cut) ends the process where it stands: FILE.partial is left
    as it was, and `--recover` turns it, whatever its last bytes, into a capture holding every
    whole row."""
    out = tmp_path / "h.csv"
    partial = Path(str(out) + ".partial")
    rec = popen_station("record", "--port", sim_port, "--out", str(out))
    wait_for_rows(partial, 5000)
    rec.kill()
    rec.communicate(timeout=20)
    assert rec.returncode == -signal.SIGKILL
    assert not out.exists()
    data = partial.read_bytes()
    _, start = _layout(data)
    res = run_station("record", "--recover", partial)
    _assert_recovered(res, partial, data[start : data.rfind(b"\n") + 1].splitlines(keepends=True))


def test_recover_of_a_partial_a_running_recording_writes_is_refused_and_the_recording_ends_whole(sim_port, tmp_path):
    """`--recover` run (from another terminal) on the partial of a recording still running
    wrote a capture of the rows so far and removed the partial; the recording went on writing
    into the removed file and ended with 'k.csv.partial: no such file', exit 2, every row
    after that moment lost. The recording holds a lock on its partial file (which a kill or a
    power cut releases): `--recover` and a second recording into the same name are refused
    while it runs, and the recording ends with its capture."""
    out = tmp_path / "live.csv"
    partial = Path(str(out) + ".partial")
    rec = popen_station("record", "--port", sim_port, "--out", str(out))
    wait_for_rows(partial, 5000)
    res = run_station("record", "--recover", partial)
    assert_one_line_refusal(res, f"station: {partial}: a recording is writing it now")
    assert partial.exists() and not out.exists()
    second = run_station("record", "--port", sim_port, "--seconds", "1", "--out", out)
    assert_one_line_refusal(second, f"station: {partial}: a recording is writing it now")
    size = partial.stat().st_size
    wait_for_rows(partial, size + 5000)  # still recording
    rec.send_signal(signal.SIGINT)
    stdout, stderr = rec.communicate(timeout=20)
    assert rec.returncode == 0, stderr
    assert stdout.startswith("recorded ") and stderr == ""
    cap = read_capture(out)
    assert cap.meta["complete"] == "true" and not partial.exists()
    assert os.path.getsize(out) > size


def test_recover_into_another_existing_file_is_refused_unless_forced(killed, tmp_path):
    """`--recover PARTIAL --out X` wrote over an existing X without a word (QA s26): a capture
    recorded earlier, lost. Now refused in one line naming X, exit 2, nothing written and the
    partial kept; `--force` replaces X. Recovering into the recording's own name (what it was
    started to replace) needs no --force."""
    partial = tmp_path / "k.csv.partial"
    partial.write_bytes(killed)
    other = tmp_path / "earlier.csv"
    other.write_bytes(b"an earlier capture\n")
    res = run_station("record", "--recover", partial, "--out", other)
    assert_one_line_refusal(res, f"station: {other}: already exists", "--force")
    assert other.read_bytes() == b"an earlier capture\n" and partial.read_bytes() == killed
    assert sorted(os.listdir(tmp_path)) == ["earlier.csv", "k.csv.partial"]
    res = run_station("record", "--recover", partial, "--out", other, "--force")
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith(f"recovered {partial} -> {other}: ")
    assert read_capture(other).meta["recovered"] == "true" and not partial.exists()
    own = tmp_path / "k.csv"
    own.write_bytes(b"the capture the killed recording was to replace\n")
    partial.write_bytes(killed)
    res = run_station("record", "--recover", partial, "--out", own)
    assert res.returncode == 0, res.stderr
    assert read_capture(own).meta["recovered"] == "true"
    res = run_station("record", "--port", "loop://", "--out", tmp_path / "n.csv", "--force")
    assert_one_line_refusal(res, "--force applies to --recover only")
