"""One atomic file write for the whole station: a temporary file beside the target, then a rename.

Readers see the old file or the new one, never half of either: the new content goes to a
hidden temporary file in the target's folder (``.<name>.<pid>-<random>.tmp``), is flushed and
fsynced, and only then renamed over the target (``os.replace``, atomic on POSIX and on one
Windows volume). Any exception on the way, ``KeyboardInterrupt`` included, removes the
temporary file and leaves the target as it was; a temporary that a killed write left behind
(SIGKILL, a power cut) is removed by the next write of the same file.

Reading goes through :func:`open_input` (or, for a library that opens the path itself,
:func:`check_input` first): a path that is not a regular file (a named pipe, a device, a
socket) is refused before anything opens it, since reading one can block for ever or never
end.

A symbolic link is written through: its target gets the new content and the link stays (the
rename had replaced the link by a file, ``/dev/stdout`` included, where the folder allowed it).

Permissions: a file that already exists keeps its mode; a new one gets what ``open()`` would
give it (0o666 less the umask), not ``tempfile.mkstemp``'s 0o600. Newlines: as ``open()``
with the same ``newline`` argument (binary modes write the bytes as given).
"""

from __future__ import annotations

import io
import json
import os
import re
import stat
import time
from collections.abc import Iterator
from contextlib import contextmanager

from station.errors import InputError


@contextmanager
def atomic_open(path, mode: str = "w", *, encoding: str = "utf-8", newline: str | None = None) -> Iterator:
    """Open a file object to write ``path``'s new content; it replaces ``path`` when the
    ``with`` block ends without an exception. ``mode`` is ``"w"`` (text) or ``"wb"``.

    Raises OSError as ``open()`` would (no folder, no permission, disk full); see
    :func:`cannot_write` for the operator's one line. A target that exists and is not a
    regular file (a named pipe, a device such as /dev/null) is an InputError: the rename would
    replace it.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open: mode {mode!r} (use 'w' or 'wb')")
    path = os.fspath(path)
    st = check_output(path)  # through a link: a pipe or terminal behind /dev/stdout is refused here
    if os.path.islink(path):  # write the file it names: the rename replaced the link itself (/dev/stdout too)
        path = os.path.realpath(path)
    folder = os.path.dirname(os.path.abspath(path))
    old_mode = stat.S_IMODE(st.st_mode) if st is not None and stat.S_ISREG(st.st_mode) else None
    with _new_beside(folder, os.path.basename(path)) as (fd, tmp):
        if old_mode is not None:
            os.chmod(tmp, old_mode)
        if mode == "wb":
            f = os.fdopen(fd, "wb")
        else:
            f = os.fdopen(fd, "w", encoding=encoding, newline=newline)
        with f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    _sync_folder(folder)


@contextmanager
def scratch_file(folder, name: str, text: str = "", *, encoding: str = "utf-8") -> Iterator[str]:
    """A new hidden file in ``folder`` holding ``text`` (``.<name>.<pid>-<random>.tmp``), for a
    check that needs a path; removed when the block ends, on an exception too. Its name is
    chosen before it is made, so a SIGTERM at any point leaves nothing behind."""
    with _new_beside(os.fspath(folder), name) as (fd, tmp):
        try:
            with os.fdopen(fd, "w", encoding=encoding) as f:
                f.write(text)
            yield tmp
        finally:
            _remove_quietly(tmp)


def atomic_write_text(path, text: str, *, encoding: str = "utf-8", newline: str | None = None) -> None:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_open`)."""
    with atomic_open(path, "w", encoding=encoding, newline=newline) as f:
        f.write(text)


def atomic_write_bytes(path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_open`)."""
    with atomic_open(path, "wb") as f:
        f.write(data)


def atomic_write_json(path, obj, *, indent: int | None = 2) -> None:
    """``json.dump(obj, indent=indent)`` to ``path`` atomically; an object json cannot
    write raises before ``path`` is touched."""
    atomic_write_text(path, json.dumps(obj, indent=indent))


@contextmanager
def cannot_write(path, what: str = "") -> Iterator[None]:
    """Turn an OSError inside the block into the operator's one line,
    ``<path>: cannot write[ what]: <reason>`` (an InputError: exit status 2)."""
    try:
        yield
    except OSError as exc:
        label = f"cannot write {what}" if what else "cannot write"
        raise InputError(path, None, f"{label}: {exc.strerror or exc}") from None


_KINDS = (
    (stat.S_ISFIFO, "a named pipe (FIFO)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def _refuse_kind(path, mode: int, what: str, folder: bool, why: str = "reading it could block or never end") -> None:
    if stat.S_ISREG(mode) or (folder and stat.S_ISDIR(mode)):
        return
    if stat.S_ISDIR(mode):
        raise InputError(path, None, f"is a directory, not {what}")
    kind = next((name for test, name in _KINDS if test(mode)), "not a file")
    raise InputError(path, None, f"{kind}, not a regular file: refused ({why})")


def check_input(path, what: str = "a capture file", *, folder: bool = False) -> None:
    """Refuse ``path`` as input unless it is a regular file (or, with ``folder``, a directory):
    InputError ``<path>: a named pipe (FIFO), not a regular file ...``, ``<path>: no such
    file``, ``<path>: permission denied``. ``os.stat`` follows links and never blocks; call
    this before a library opens the path itself (:func:`open_input` calls it too)."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise InputError(path, None, "no such file") from None
    except PermissionError:
        raise InputError(path, None, "permission denied") from None
    except (OSError, ValueError) as exc:  # a name too long, a loop of links, a NUL in the name
        raise InputError(path, None, f"cannot open: {getattr(exc, 'strerror', None) or exc}") from None
    _refuse_kind(path, mode, what, folder)


def same_file(a, b) -> bool:
    """Whether paths ``a`` and ``b`` name one file: the same file when both exist (links,
    ``./``), else the same resolved path (one output named twice before it exists)."""
    try:
        if os.path.exists(a) and os.path.exists(b):
            return os.path.samefile(a, b)
        return os.path.realpath(a) == os.path.realpath(b)
    except (OSError, ValueError):
        return False


def check_output(path) -> os.stat_result | None:
    """Refuse an output ``path`` that exists and is no regular file (a named pipe, a device):
    the atomic rename would replace it; and one that names a folder or lies in none (the
    rename said 'Not a directory' of a folder). Returns its stat (None when it does not
    exist). ``-`` is refused too: to the operator it is standard output (``report -o -``),
    which a file write never is; a file named so is ``./-``."""
    path = os.fspath(path)
    if path == "-":
        raise InputError(
            None,
            None,
            "'-' as an output file: standard output is not written here; name a file (./- for one named '-')",
        )
    if not path:
        raise InputError(None, None, "cannot write: an empty file name")
    if path.endswith(("/", os.sep)) or os.path.isdir(path):
        raise InputError(path, None, "cannot write: is a folder; give a file name")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise InputError(path, None, f"cannot write: no folder {folder}")
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    if not stat.S_ISDIR(st.st_mode):
        _refuse_kind(path, st.st_mode, "a file", False, "the new file would replace it")
    return st


def open_input(path, what: str = "a capture file") -> io.BufferedReader:
    """``open(path, "rb")`` for input, refusing what :func:`check_input` refuses.

    The file is opened without blocking (``O_NONBLOCK``: a FIFO swapped in after the check
    does not hang the open) and checked again on the open descriptor, so the check and the
    reading see the same file. ``what``: the words for a directory (``is a directory, not
    <what>``)."""
    check_input(path, what)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise InputError(path, None, "no such file") from None
    except IsADirectoryError:
        raise InputError(path, None, f"is a directory, not {what}") from None
    except PermissionError:
        raise InputError(path, None, "permission denied") from None
    except OSError as exc:
        raise InputError(path, None, f"cannot open: {exc.strerror or exc}") from None
    try:
        _refuse_kind(path, os.fstat(fd).st_mode, what, False)
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return os.fdopen(fd, "rb")


# a binary log's first bytes: ULog's file magic, a DataFlash message header (HEAD1, HEAD2)
LOG_MAGIC = ((b"ULog\x01\x12\x35", "px4", "a PX4 ULog file"), (b"\xa3\x95", "ardupilot", "an ArduPilot DataFlash log"))


def log_kind(head: bytes) -> tuple[str, str] | None:
    """(format, words) of the binary log whose first bytes are ``head``, or None."""
    return next(((fmt, words) for magic, fmt, words in LOG_MAGIC if head.startswith(magic)), None)


def looks_utf16(raw: bytes) -> bool:
    """Whether bytes from a file's start are UTF-16 text (a spreadsheet's "Unicode text"):
    its byte-order mark, or ASCII characters with a NUL byte beside each (no mark)."""
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        return True
    head = raw[: 64 - len(raw[:64]) % 2]
    if len(head) < 4:
        return False
    even, odd = head[0::2], head[1::2]
    return any(
        not nul.strip(b"\0") and all(32 <= b < 127 or b in (9, 10, 13) for b in text)
        for text, nul in ((even, odd), (odd, even))
    )


STALE_TMP_S = 10.0  # a temporary untouched this long, of a process that is gone, is left over


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return pid > 0  # another user's process (or a number no process has: not alive)
    return True


def remove_stale_temporaries(folder: str, name: str) -> list[str]:
    """Remove the temporaries of ``name`` that a killed write left in ``folder`` (SIGKILL, a
    power cut: no handler ran): ``.<name>.<pid>-<random>.tmp`` whose process is gone and that
    nothing has written to for ``STALE_TMP_S``. Returns the paths removed."""
    pattern = re.compile(r"\." + re.escape(name) + r"\.(\d+)-[0-9a-f]{8}\.tmp")
    removed = []
    try:
        entries = os.listdir(folder)
    except OSError:
        return removed
    for entry in entries:
        m = pattern.fullmatch(entry)
        if m is None or _pid_alive(int(m.group(1))):
            continue
        path = os.path.join(folder, entry)
        try:
            st = os.lstat(path)
            if stat.S_ISREG(st.st_mode) and time.time() - st.st_mtime > STALE_TMP_S:
                os.unlink(path)
                removed.append(path)
        except OSError:
            pass
    return removed


# a new file only (never one another writer made), mode 0o666 so that the umask applies as to open()
_CREATE_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0) | getattr(os, "O_CLOEXEC", 0)


@contextmanager
def _new_beside(folder: str, name: str) -> Iterator[tuple[int, str]]:
    """A new hidden file beside ``name`` in ``folder`` (``_names_beside``, ``O_EXCL``): yields
    (descriptor, path); the file is removed if the block raises anything (``KeyboardInterrupt``, a
    SIGTERM raised as an exception). Its name is chosen before the file is made, inside the
    block that removes it: a SIGTERM that landed between the creation and that block left it."""
    tmp = None
    try:
        for tmp in _names_beside(folder, name):
            try:
                fd = os.open(tmp, _CREATE_FLAGS, 0o666)
                break
            except FileExistsError:
                tmp = None
        yield fd, tmp
    except BaseException:
        _remove_quietly(tmp)
        raise


def _remove_quietly(path: str | None) -> None:
    """Remove ``path`` if it is there."""
    if path is not None:
        try:
            os.unlink(path)
        except FileNotFoundError:
            pass


def _names_beside(folder: str, name: str) -> Iterator[str]:
    """Names for a new hidden file beside ``name`` in ``folder``, tried in turn (``O_EXCL``):
    each carries the writer's pid, so that a later write can tell a killed writer's leftover
    (``remove_stale_temporaries``), and no other process makes a file of that name."""
    remove_stale_temporaries(folder, name)
    for _ in range(100):
        yield os.path.join(folder, f".{name}.{os.getpid()}-{os.urandom(4).hex()}.tmp")
    raise FileExistsError(f"no free temporary name beside {name} in {folder}")


def _sync_folder(folder: str) -> None:
    """fsync the folder so the rename itself survives a power cut (where the OS allows it)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
