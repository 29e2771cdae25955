"""Hostile text never reaches a terminal raw (issue 16): ESC/CSI/OSC, BEL, CR, C1 bytes and
bidi overrides in device ids, models, notes and a capture's ``# device:`` line are shown
escaped by every command and in the TUI tables, and a newline inside a field cannot forge
a table row. The command tests read the bytes a real pseudo-terminal receives."""

from __future__ import annotations

import asyncio
import json
import os
import pty
import select
import subprocess
import sys
import time

import pytest

from station.textsafe import safe, safe_json_text
from tests.station_run import ROOT, run_station

HOSTILE_ID = "EVIL\x1b]0;pwned\x07-\x1b[2J\rX\u202e"
HOSTILE_MODEL = "M\x9b31mred\x85"
HOSTILE_NOTES = "line1\nFAKE-ROW  forged  0  -\x1b[31m"

# Bytes a terminal acts on (after the pty's own LF -> CRLF translation is undone).
RAW = (
    [b"\x1b", b"\x07", b"\r", b"\x08"]
    + [("\x80" if k == 0 else chr(0x80 + k)).encode() for k in range(32)]
    + ["\u202e".encode()]
)


def test_safe_escapes_what_a_terminal_acts_on_and_keeps_the_rest():
    assert safe("IMU-7") == "IMU-7"
    kept = "Größe ✓ 'quoted' \"x\" C:\\path 日本 🙂 [b]"
    assert safe(kept) == kept
    assert safe("a\x1b[31mb") == "a\\x1b[31mb"
    assert safe("bell\x07 cr\r nl\n tab\t") == "bell\\x07 cr\\r nl\\n tab\\t"
    assert safe("c1\x9b del\x7f") == "c1\\x9b del\\x7f"
    assert safe("bidi\u202e ls\u2028 zw\u200b") == "bidi\\u202e ls\\u2028 zw\\u200b"
    assert safe("two\nlines\tok", keep_newlines=True) == "two\nlines\tok"
    assert safe(None) == "None" and safe(3) == "3"


def test_json_escapes_keep_the_document_valid_and_the_value_exact():
    value = {"id": HOSTILE_ID + HOSTILE_MODEL + "\x7f\u2029🙂"}
    text = safe_json_text(json.dumps(value, ensure_ascii=False))
    assert json.loads(text) == value
    assert not any(ch in text for ch in "\x1b\x07\x9b\x85\x7f\u202e\u2029")


def _pty_run(*args, env=None) -> tuple[int, bytes]:
    """Run the real CLI with stdout and stderr on a real pty; every byte the terminal got."""
    master, slave = pty.openpty()
    proc = subprocess.Popen(
        [sys.executable, "-m", "station", *map(str, args)],
        cwd=ROOT,
        stdin=subprocess.DEVNULL,
        stdout=slave,
        stderr=slave,
        env=env,
        close_fds=True,
    )
    os.close(slave)
    chunks = []
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        r, _, _ = select.select([master], [], [], 1.0)
        if r:
            try:
                data = os.read(master, 65536)
            except OSError:  # EIO: the child closed its side
                break
            if not data:
                break
            chunks.append(data)
        elif proc.poll() is not None:
            break
    os.close(master)
    rc = proc.wait(timeout=60)
    return rc, b"".join(chunks).replace(b"\r\n", b"\n")


@pytest.fixture(scope="module")
def hostile_db(tmp_path_factory):
    d = tmp_path_factory.mktemp("hostile")
    db = d / "station.db"
    cap = d / "p2.csv"
    assert run_station("simulate", "--procedure", "accel-centrifuge", "--out", cap, "--seed", 5).returncode == 0
    clean = cap.read_text()
    # the capture's own # device: line is hostile too (the reader refuses it, in one escaped line)
    text = clean.replace("# device: SIM-CFG-0005", "# device: CAP\x1b[5mBLINK\x9d8;;http://x\x9c", 1)
    assert "CAP\x1b" in text
    cap.write_text(text)
    r = run_station(
        "devices",
        "add",
        HOSTILE_ID,
        "--model",
        HOSTILE_MODEL,
        "--notes",
        HOSTILE_NOTES,
        "--interval-days",
        "1",
        "--tolerance",
        "S=1e-9",
        "--db",
        db,
    )
    assert r.returncode == 0, r.stderr
    for date in ("2024-01-01", "2024-06-01"):
        dated = d / f"p2-{date}.csv"
        dated.write_text(clean.replace("# radius_m:", f"# date: {date}\n# radius_m:", 1))
        r = run_station("calibrate", dated, "--save", "--device", HOSTILE_ID, "--db", db)
        assert r.returncode == 0, r.stderr
    return db, cap


@pytest.mark.parametrize(
    "args",
    [
        ("devices", "list"),
        ("devices", "show", HOSTILE_ID),
        ("history", HOSTILE_ID),
        ("due",),
        ("drift", HOSTILE_ID, "--no-plot"),
        ("drift", HOSTILE_ID),
        ("verify",),
        ("recompute", HOSTILE_ID),
        ("devices", "show", "NO\x1b[31mSUCH"),
        ("devices", "list", "--json"),
        ("history", HOSTILE_ID, "--json"),
    ],
    ids=lambda a: "-".join(x for x in a if x.isascii() and x.isprintable()) or "x",
)
def test_database_text_reaches_a_real_terminal_escaped(hostile_db, args):
    db, _ = hostile_db
    rc, out = _pty_run(*args, "--db", db)
    assert rc in (0, 1, 2), out[-400:]
    for raw in RAW:
        assert raw not in out, (raw, out[:600])
    if "--json" not in args:
        assert b"\nFAKE-ROW" not in out  # the newline in the notes cannot start a row
        if rc != 2 and args[0] in ("devices", "history", "drift", "recompute"):
            assert b"EVIL\\x1b]0;pwned\\x07" in out  # shown, escaped, not dropped
    else:
        json.loads(out.decode())


@pytest.mark.parametrize("command", ["inspect", "calibrate"])
def test_a_capture_device_line_reaches_a_real_terminal_escaped(hostile_db, command):
    _, cap = hostile_db
    rc, out = _pty_run(command, cap)
    assert rc == 2, out[-400:]  # refused on its line, as `import --device` refuses the same text
    for raw in RAW:
        assert raw not in out, (raw, out[:600])
    assert b"CAP\\x1b[5mBLINK\\x9d8;;http://x\\x9c" in out


def test_history_screen_shows_hostile_ids_escaped_one_row_each(hostile_db):
    from station.app import make_app

    db, _ = hostile_db

    async def story():
        app = make_app(str(db), start="history")
        async with app.run_test(size=(120, 40)) as pilot:

            def painted():
                lines = [strip.text for strip in app.screen._compositor.render_strips()]
                return (
                    type(app.screen).__name__ == "HistoryScreen"
                    and app.screen.query_one("#calibrations").row_count == 2
                    and "EVIL" in "\n".join(lines)  # the rows are painted a refresh after row_count
                )

            t_end = time.monotonic() + 120  # a safety net for a hung app, not a pace
            while not painted():
                assert time.monotonic() < t_end, "the History screen never showed the two calibrations"
                await pilot.pause(0.05)
            devices = app.screen.query_one("#devices")
            lines = [strip.text for strip in app.screen._compositor.render_strips()]
            return devices.row_count, lines

    n_rows, lines = asyncio.run(story())
    assert n_rows == 1
    screen = "\n".join(lines)
    assert not any(ch in screen for ch in "\x1b\x07\r\x9b\x85\u202e")
    assert "EVIL\\x1b]0;pwned" in screen


@pytest.mark.parametrize(
    "text",
    ["rfc2217://[::1: Invalid IPv6 URL", "q [::1]:5 [", "ends with [", "a [b] c [/] d", "[red]x[/red]", "C:\\[x]"],
)
def test_tui_markup_keeps_every_bracket_as_text_inside_a_style(text):
    """Textual's escape() left a '[' that looks like no tag ('[::1'), and its parser then took
    the style's closing tag for text: Connect showed 'Cannot connect: ... Invalid IPv6 URL[/]'."""
    from textual.content import Content

    from station.textsafe import tui_markup

    content = Content.from_markup(f"[b red]{tui_markup(text)}[/] and [b]more[/]")
    assert content.plain == f"{text} and more"


@pytest.mark.parametrize("text", ["C:\\dir\\", "a\\", "two\\\\", "\\", "x\\[y]\\"])
def test_tui_markup_keeps_a_trailing_backslash_literal(text):
    """A trailing backslash made Textual read the closing tag after it as text: 'C:\\dir\\'
    showed as 'C:\\dir[/] and more' with the style running on. Now the backslash is shown, the
    style ends where it should, and the screen shows no other character (zero cells)."""
    from rich.cells import cell_len
    from textual.content import Content

    from station.textsafe import tui_markup

    content = Content.from_markup(f"[b red]{tui_markup(text)}[/] and [b]more[/]")
    shown = content.plain.replace("\u200b", "")
    assert shown == f"{text} and more"
    assert cell_len(content.plain) == len(shown)
    styled = {content.plain[s.start : s.end].replace("\u200b", "") for s in content.spans}
    assert styled == {text, "more"}


def test_a_device_id_ending_in_a_backslash_on_screen(tmp_path):
    """The limits box's title, '[b]Limits of {id}[/]: absolute, ...', read 'Limits of BENCH\\[/]:'
    for a device called 'BENCH\\' on the real screen."""
    from station.app import make_app
    from station.screens.limits import LimitsScreen
    from tests.test_tui import SIZE, screen_name, text_of, wait_for

    async def story():
        app = make_app(str(tmp_path / "s.db"), device_id="BENCH\\")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(LimitsScreen("BENCH\\"))
            await wait_for(
                pilot, lambda: screen_name(app) == "LimitsScreen" and "reading" not in text_of(app, "#current")
            )
            return text_of(app, "#head")

    head = asyncio.run(story())
    assert "Limits of BENCH\\: absolute, in the units shown" in head.replace("\u200b", ""), head
    assert "[/]" not in head
