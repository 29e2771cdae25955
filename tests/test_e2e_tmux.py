"""End to end: `station demo` in a real terminal (tmux on a private socket, a real
pseudo-terminal), to a calibration saved in a temporary database, checked with
`station history --json`."""
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
    cmd = (f"cd {ROOT} && TERM=xterm-256color {sys.executable} -m station demo --db {db} "
           f"--speed 12 --average-s 1; echo EXIT=$?; sleep 30")
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
    out = subprocess.run([sys.executable, "-m", "station", "history", "SIM-ACC-0000", "--json", "--db", str(db)],
                         capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert out.returncode == 0, out.stderr
    records = json.loads(out.stdout)
    assert len(records) == 1 and records[0]["procedure"] == "accel-tabletop"
    assert records[0]["n_positions"] == 12
