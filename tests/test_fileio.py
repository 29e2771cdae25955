"""station.fileio: the one atomic write (temporary file beside the target, fsync, rename)."""

from __future__ import annotations

import json
import os
import stat

import pytest

from station.errors import InputError
from station.fileio import atomic_open, atomic_write_bytes, atomic_write_json, atomic_write_text, cannot_write


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def test_writes_the_text_and_leaves_only_the_file(tmp_path):
    path = tmp_path / "out.txt"
    atomic_write_text(path, "one\ntwo\n")
    assert path.read_bytes() == b"one\ntwo\n"
    assert os.listdir(tmp_path) == ["out.txt"]


def test_an_exception_inside_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "state.json"
    path.write_text("old content\n", encoding="utf-8")
    with pytest.raises(RuntimeError, match="half way"):
        with atomic_open(path) as f:
            f.write("new content that never lands\n" * 1000)
            f.flush()
            # a reader meanwhile sees the old file whole
            assert path.read_text(encoding="utf-8") == "old content\n"
            raise RuntimeError("half way")
    assert path.read_text(encoding="utf-8") == "old content\n"
    assert os.listdir(tmp_path) == ["state.json"]


def test_an_interrupt_inside_leaves_no_new_file(tmp_path):
    path = tmp_path / "report.html"
    with pytest.raises(KeyboardInterrupt):
        with atomic_open(path, "wb") as f:
            f.write(b"<html>")
            raise KeyboardInterrupt
    assert os.listdir(tmp_path) == []


def test_a_json_object_json_cannot_write_touches_nothing(tmp_path):
    path = tmp_path / "truth.json"
    path.write_text("{}", encoding="utf-8")
    with pytest.raises(TypeError):
        atomic_write_json(path, {"a": object()})
    assert path.read_text(encoding="utf-8") == "{}" and os.listdir(tmp_path) == ["truth.json"]


def test_json_is_what_json_dump_writes(tmp_path):
    obj = {"b": [1, 2.5, None], "a": {"x": "é"}}
    atomic_write_json(tmp_path / "a.json", obj, indent=1)
    with open(tmp_path / "b.json", "w", encoding="utf-8") as f:
        json.dump(obj, f, indent=1)
    assert (tmp_path / "a.json").read_bytes() == (tmp_path / "b.json").read_bytes()


def test_a_new_file_gets_the_mode_open_gives(tmp_path):
    """Not tempfile.mkstemp's 0o600: what an ordinary open() makes under this umask."""
    for umask in (0o022, 0o077, 0o002):
        old = os.umask(umask)
        try:
            ref = tmp_path / f"ref-{umask:o}"
            with open(ref, "w"):
                pass
            new = tmp_path / f"new-{umask:o}"
            atomic_write_text(new, "x")
        finally:
            os.umask(old)
        assert _mode(new) == _mode(ref), f"umask {umask:o}"


def test_an_existing_file_keeps_its_mode(tmp_path):
    path = tmp_path / "c.capture.csv"
    path.write_text("old", encoding="utf-8")
    for mode in (0o640, 0o600, 0o664, 0o444):
        path.chmod(mode)
        atomic_write_bytes(path, b"new %o" % mode)
        assert _mode(path) == mode and path.read_bytes() == b"new %o" % mode


def test_newlines_are_those_of_open_with_the_same_argument(tmp_path):
    text = "a\nb\r\nc\rd\n"
    for newline in (None, "", "\n", "\r\n"):
        atomic_write_text(tmp_path / "a", text, newline=newline)
        with open(tmp_path / "b", "w", encoding="utf-8", newline=newline) as f:
            f.write(text)
        assert (tmp_path / "a").read_bytes() == (tmp_path / "b").read_bytes(), repr(newline)
    atomic_write_bytes(tmp_path / "c", b"a\r\nb\n")
    assert (tmp_path / "c").read_bytes() == b"a\r\nb\n"


def test_text_is_utf8_unless_told(tmp_path):
    atomic_write_text(tmp_path / "u", "µ°")
    atomic_write_text(tmp_path / "l", "µ°", encoding="latin-1")
    assert (tmp_path / "u").read_bytes() == "µ°".encode() and (tmp_path / "l").read_bytes() == b"\xb5\xb0"


def test_no_folder_is_one_operator_line_and_creates_nothing(tmp_path):
    path = tmp_path / "missing" / "out.txt"
    with pytest.raises(InputError) as info:
        with cannot_write(path):
            atomic_write_text(path, "x")
    assert str(info.value) == f"{path}: cannot write: no folder {path.parent}"  # checked before anything is made
    assert os.listdir(tmp_path) == []


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root ignores folder permissions")
def test_a_read_only_folder_is_one_operator_line(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    (folder / "keep.txt").write_text("kept", encoding="utf-8")
    folder.chmod(0o555)
    try:
        with pytest.raises(InputError, match="cannot write the report: Permission denied"):
            with cannot_write(folder / "keep.txt", "the report"):
                atomic_write_text(folder / "keep.txt", "new")
        assert os.listdir(folder) == ["keep.txt"] and (folder / "keep.txt").read_text(encoding="utf-8") == "kept"
    finally:
        folder.chmod(0o755)


def test_only_whole_file_modes():
    with pytest.raises(ValueError):
        with atomic_open("x", "a"):
            pass


def test_a_symbolic_link_is_written_through_not_replaced(tmp_path):
    """The rename put the new file in place of a link: `export -o /dev/stdout` run as root
    replaced the /dev/stdout link by a regular file (every later `> /dev/stdout` of the machine
    wrote there), and `-o current.param` (a link to the board's file) left the board's file
    old and the link gone. The link's target gets the content; the link stays; a dangling
    link makes its target."""
    target = tmp_path / "real.param"
    target.write_text("old\n")
    link = tmp_path / "current.param"
    link.symlink_to(target.name)
    atomic_write_text(link, "new\n")
    assert link.is_symlink() and os.readlink(link) == target.name
    assert target.read_text() == "new\n"
    dangling = tmp_path / "next.param"
    dangling.symlink_to("made.param")
    atomic_write_text(dangling, "made\n")
    assert dangling.is_symlink() and (tmp_path / "made.param").read_text() == "made\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["current.param", "made.param", "next.param", "real.param"]


def test_cli_output_through_a_link_to_a_pipe_is_refused_as_the_pipe(tmp_path):
    """`-o /dev/stdout` with stdout a pipe: writing through links must not lose the check of
    what the link names; the pipe behind it is refused as one, before anything is written."""
    from tests.station_run import assert_one_line_refusal, run_station

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    link = tmp_path / "out.csv"
    link.symlink_to(fifo)
    res = run_station("simulate", "--procedure", "accel-centrifuge", "--out", link, subprocess_run=True)
    assert_one_line_refusal(res, "named pipe")
    assert link.is_symlink() and fifo.exists() and not fifo.is_file()


def test_a_scratch_file_holds_its_text_and_is_gone_after_the_block_even_on_an_interrupt(tmp_path):
    from station.fileio import scratch_file

    with scratch_file(tmp_path, "check", "# a: 1\n") as p:
        assert os.path.dirname(p) == str(tmp_path) and os.path.basename(p).startswith(".check.")
        assert open(p, encoding="utf-8").read() == "# a: 1\n"
    assert os.listdir(tmp_path) == []
    with pytest.raises(KeyboardInterrupt):
        with scratch_file(tmp_path, "check", "x") as p:
            raise KeyboardInterrupt
    assert os.listdir(tmp_path) == []


def test_a_scratch_file_a_killed_process_left_is_removed_by_the_next(tmp_path):
    import subprocess
    import sys

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    left = tmp_path / f".check.{int(dead.stdout)}-0badc0de.tmp"
    left.write_text("left by a SIGKILL", encoding="utf-8")
    from station.fileio import STALE_TMP_S, scratch_file

    old = os.stat(left).st_mtime - STALE_TMP_S - 60
    os.utime(left, (old, old))

    with scratch_file(tmp_path, "check") as p:
        assert os.listdir(tmp_path) == [os.path.basename(p)]
    assert os.listdir(tmp_path) == []
