"""Scripting: `station ports --json` against pyserial's own answer; NO_COLOR on a real terminal."""

from __future__ import annotations

import json
import os
import pty
import select
import subprocess
import sys
from pathlib import Path

import pytest
from db_testdata import accel_result, small_capture

from db import Store

ROOT = Path(__file__).resolve().parents[1]


def test_ports_json_is_what_pyserial_lists():
    from serial.tools import list_ports

    p = subprocess.run(
        [sys.executable, "-m", "station", "ports", "--json"],
        check=False,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert p.returncode == 0 and p.stderr == ""
    got = json.loads(p.stdout)  # a list even when empty, never the "no ports" sentence
    assert isinstance(got, list)
    assert sorted(x["device"] for x in got) == sorted(q.device for q in list_ports.comports())
    assert all(set(x) == {"device", "description", "hwid"} for x in got)


def _on_a_terminal(argv, env) -> bytes:
    """Run the station with stdout on a real pseudo-terminal; everything it wrote there."""
    master, slave = pty.openpty()
    try:
        p = subprocess.Popen(
            [sys.executable, "-m", "station", *argv],
            cwd=ROOT,
            stdout=slave,
            stderr=subprocess.PIPE,
            env=env,
        )
        os.close(slave)
        out = bytearray()
        # read until the terminal hangs up (EIO), or, once the child has exited, until nothing is
        # left: another process still holding this pty (a leaked child of an earlier test) keeps
        # EIO away for good, and a blocking read hung CI's worker for 20 minutes
        while True:
            ready, _, _ = select.select([master], [], [], 1.0)
            if not ready:
                if p.poll() is not None:
                    break
                continue
            try:
                chunk = os.read(master, 65536)
            except OSError:  # EIO: the child closed the terminal
                break
            if not chunk:
                break
            out.extend(chunk)
        assert p.wait(timeout=120) == 0, p.stderr.read().decode()
        return bytes(out)
    finally:
        os.close(master)


@pytest.mark.parametrize("no_color", [None, "1"])
def test_no_color_turns_off_ansi_colour_on_a_terminal(tmp_path, no_color):
    db = str(tmp_path / "s.db")
    with Store(db) as s:
        meta, cols = small_capture(device="IMU-1")
        for k, date in enumerate(["2024-01-01", "2024-07-01", "2025-01-01"]):
            s.save_calibration(
                accel_result(B=(0.1 + 0.01 * k, 0.2, 0.3)),
                meta=dict(meta, date=date),
                columns=cols,
            )
    env = {k: v for k, v in os.environ.items() if k != "NO_COLOR"}
    if no_color is not None:
        env["NO_COLOR"] = no_color
    out = _on_a_terminal(["drift", "IMU-1", "--param", "B[0]", "--db", db], env)
    assert b"year" in out  # the plot is there either way
    colour = b"\x1b[38;5;" in out or b"\x1b[48;5;" in out or b"\x1b[3" in out
    assert colour == (no_color is None)  # a terminal gets colour unless NO_COLOR is set


def test_the_tui_honours_no_color(monkeypatch):
    monkeypatch.setenv("NO_COLOR", "1")
    from station.app import make_app

    app = make_app(db_path=":memory:")
    assert app.no_color  # Textual then draws the whole app through its monochrome filter
