"""End to end in a real terminal (tmux on a private socket, a real pseudo-terminal) at
80x24: `station demo`, and `station` driven by keys alone, to calibrations saved in a
temporary database, checked with `station history --json`."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TMUX = shutil.which("tmux") or "/usr/bin/tmux"

pytestmark = pytest.mark.skipif(not os.path.exists(TMUX), reason="tmux not installed")


def tmux(sock, *args, check=True):
    return subprocess.run([TMUX, "-L", sock, *args], capture_output=True, text=True, check=check, timeout=20)


def pane(sock) -> str:
    return tmux(sock, "capture-pane", "-p", "-t", "demo", check=False).stdout


def test_station_demo_in_tmux_saves_a_calibration(tmp_path):
    sock = f"test-{os.getpid()}"
    db = tmp_path / "station.db"
    cmd = (
        f"cd {ROOT} && TERM=xterm-256color {sys.executable} -m station demo --db {db} "
        f"--speed 12 --average-s 1; echo EXIT=$?; sleep 30"
    )
    tmux(sock, "new-session", "-d", "-s", "demo", "-x", "80", "-y", "24", cmd)
    try:
        seen_procedure = False
        t_end = time.monotonic() + 90
        screen = ""
        while time.monotonic() < t_end:
            screen = pane(sock)
            seen_procedure |= "Stillness" in screen and "Orientation" in screen
            if "Saved as calibration #1" in screen:
                break
            time.sleep(0.5)
        else:
            raise AssertionError("no saved calibration on screen within 90 s:\n" + screen)
        assert seen_procedure, "the procedure screen was never seen"
        assert "P1 result" in screen and "NO TOLERANCE" in screen  # a new device: nothing to compare
        tmux(sock, "send-keys", "-t", "demo", "C-q")
        t_end = time.monotonic() + 15
        while time.monotonic() < t_end and "EXIT=" not in (screen := pane(sock)):
            time.sleep(0.2)
        assert "EXIT=0" in screen, screen
    finally:
        tmux(sock, "kill-server", check=False)
    out = subprocess.run(
        [sys.executable, "-m", "station", "history", "SIM-ACC-0000", "--json", "--db", str(db)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    records = json.loads(out.stdout)
    assert len(records) == 1 and records[0]["procedure"] == "accel-tabletop"
    assert records[0]["n_positions"] == 12


def _wait_pane(sock, cond, timeout_s, what):
    t_end = time.monotonic() + timeout_s
    screen = ""
    while time.monotonic() < t_end:
        screen = pane(sock)
        if cond(screen):
            return screen
        time.sleep(0.3)
    raise AssertionError(f"{what}: not seen within {timeout_s:g} s:\n{screen}")


def _keys(sock, *keys):
    for k in keys:
        tmux(sock, "send-keys", "-t", "demo", k)
        time.sleep(0.4)  # one key at a time, as a person types (select lists open on Enter)


def test_p1_and_p5_by_keys_alone_in_tmux(tmp_path):
    """`station` (not the demo) at 80x24 on the built-in device, keys only: P1 with `p`
    placing each asked position, saved; then P5 picked on Connect, `d` drives, `t` turns,
    the conditioning says when it is enough, saved. The simulated device runs 20x."""
    sock = f"test-keys-{os.getpid()}"
    db = tmp_path / "station.db"
    cmd = (
        f"cd {ROOT} && TERM=xterm-256color {sys.executable} -m station tui --db {db} --speed 20 "
        f"--average-s 2; echo EXIT=$?; sleep 30"
    )
    tmux(sock, "new-session", "-d", "-s", "demo", "-x", "80", "-y", "24", cmd)
    try:
        _wait_pane(sock, lambda s: "f5 Start" in s, 60, "the Connect screen")
        _keys(sock, "F5")
        _wait_pane(sock, lambda s: "P1 accelerometer, level table" in s and "p Place (sim)" in s, 60, "P1")
        placed = {"x_up"}  # the unit starts on x_up
        t_end = time.monotonic() + 240
        screen = ""
        while time.monotonic() < t_end:
            screen = pane(sock)
            if "P1 result" in screen:
                break
            lines = screen.splitlines()
            head = lines[1].split("╮", 1)[-1].split() if len(lines) > 1 and "Steps" in lines[1] else []
            step = head[0] if head else ""  # the asked position, above its drawing
            if step and step not in placed:
                placed.add(step)
                _keys(sock, "p")
            time.sleep(0.3)
        else:
            raise AssertionError("P1 not finished by keys within 240 s:\n" + screen)
        assert len(placed) == 12
        _keys(sock, "s")
        _wait_pane(sock, lambda s: "Saved as calibration #1" in s, 30, "the P1 save")
        _keys(sock, "n")
        _wait_pane(sock, lambda s: "f5 Start" in s, 30, "Connect again")
        _keys(sock, "BTab", "BTab", "Enter", "Down", "Down", "Down", "Down", "Enter")
        _wait_pane(sock, lambda s: "P5 laser velocimeter" in s, 10, "P5 picked")
        _keys(sock, "F5")
        _wait_pane(sock, lambda s: "d Drive/stop (sim)" in s and "Parked" in s, 60, "P5 parked")
        _keys(sock, "d")
        _wait_pane(sock, lambda s: "ILL-CONDITIONED" in s and "straight" in s, 60, "straight driving refused")
        _keys(sock, "t")
        # the summary is drawn once the device's tolerances are read (a worker): wait for it
        screen = _wait_pane(sock, lambda s: "P5 LDV result" in s and "cond(HᵀH)" in s, 180, "the P5 result")
        _keys(sock, "s")
        _wait_pane(sock, lambda s: "Saved as calibration #2" in s, 30, "the P5 save")
        _keys(sock, "C-q")
        _wait_pane(sock, lambda s: "EXIT=" in s, 15, "the exit")
        assert "EXIT=0" in pane(sock)
    finally:
        tmux(sock, "kill-server", check=False)
    for device, procedure in (("SIM-ACC-0000", "accel-tabletop"), ("SIM-LDV-0000", "ldv")):
        out = subprocess.run(
            [sys.executable, "-m", "station", "history", device, "--json", "--db", str(db)],
            capture_output=True,
            text=True,
            cwd=ROOT,
            timeout=60,
        )
        assert out.returncode == 0, out.stderr
        records = json.loads(out.stdout)
        assert len(records) == 1 and records[0]["procedure"] == procedure
