"""End to end in a real terminal (tmux on a private socket, a real pseudo-terminal) at
80x24: `station demo`, and `station` driven by keys alone, to calibrations saved in a
temporary database, checked with `station history --json`."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TMUX = shutil.which("tmux") or "/usr/bin/tmux"

# CI (.ci/run) installs tmux and sets STATION_REQUIRE_TOOLS: there these tests run, not skip
REQUIRED = "tmux" in os.environ.get("STATION_REQUIRE_TOOLS", "").split()
pytestmark = pytest.mark.skipif(not os.path.exists(TMUX) and not REQUIRED, reason="tmux not installed")


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
        t_end = time.monotonic() + 300  # a safety net: 11 s alone, over 90 s once on a loaded CI
        screen = ""
        while time.monotonic() < t_end:
            screen = pane(sock)
            seen_procedure |= "Stillness" in screen and "Orientation" in screen
            if "Saved as calibration #1" in screen:
                break
            time.sleep(0.5)
        else:
            raise AssertionError("no saved calibration on screen within 300 s:\n" + screen)
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


# sock -> the file the app started by _start_tui writes its threads' stacks to on SIGUSR1
STACKS: dict[str, str] = {}


def _stacks(sock) -> str:
    """Every thread's stack of the app in ``sock`` (started by _start_tui), or ''."""
    import signal

    path = STACKS.get(sock)
    if not path or not os.path.exists(path + ".pid"):
        return ""
    try:
        with open(path + ".pid") as f:
            os.kill(int(f.read()), signal.SIGUSR1)
    except (OSError, ValueError):
        return ""
    t_end = time.monotonic() + 10
    while time.monotonic() < t_end and not os.path.getsize(path):
        time.sleep(0.1)  # waiting on the dump, not a pace
    time.sleep(0.5)  # the rest of the threads
    with open(path) as f:
        return f.read()


def _wait_pane(sock, cond, timeout_s, what):
    """Poll the pane until ``cond(screen)``; the timeout is a safety net for a hung app,
    generous so that a loaded machine only makes the test slower. On a timeout the
    message carries the screen and, for an app started by _start_tui, its threads' stacks."""
    t_end = time.monotonic() + timeout_s
    screen = ""
    while time.monotonic() < t_end:
        screen = pane(sock)
        if cond(screen):
            return screen
        time.sleep(0.3)  # polling interval, not a pace
    stacks = _stacks(sock)
    raise AssertionError(
        f"{what}: not seen within {timeout_s:g} s:\n{screen}" + (f"\nthreads:\n{stacks}" if stacks else "")
    )


def _keys(sock, *keys):
    """Keys in order (the terminal queues them; the app reads them in turn)."""
    for k in keys:
        tmux(sock, "send-keys", "-t", "demo", k)


def _procedure_line(screen: str) -> str:
    return next((line for line in screen.splitlines() if line.startswith(" Procedure ")), "")


def _pick(sock, title):
    """On Connect (focus on Start, as it is on arrival and on return): shift-tab twice to
    the procedure list, open it, wait until it is open, move to ``title``, choose it."""
    from station.procedures import registry

    titles = list(registry.guided().values())
    # (a pane caught mid-redraw can show a part of the line: wait for a whole title)
    screen = _wait_pane(
        sock, lambda s: "f5 Start" in s and any(t in _procedure_line(s) for t in titles), 60, "the Connect screen"
    )
    now = next(t for t in titles if t in _procedure_line(screen))
    _keys(sock, "BTab", "BTab", "Enter")
    _wait_pane(sock, lambda s: titles[-1] in s and titles[0] in s and "▲" in _procedure_line(s), 60, "the list open")
    step = titles.index(title) - titles.index(now)
    _keys(sock, *(["Down"] * step if step > 0 else ["Up"] * -step), "Enter")
    _wait_pane(sock, lambda s: title in _procedure_line(s) and "▼" in _procedure_line(s), 60, f"{title} picked")


def _save(sock, result_title, n):
    """On Results: wait for the summary (drawn once the device's record is read), save."""
    _wait_pane(sock, lambda s: result_title in s and " RMS " in s, 240, result_title)
    _keys(sock, "s")
    _wait_pane(sock, lambda s: f"Saved as calibration #{n}" in s, 60, f"save #{n}")
    _keys(sock, "n")


def _start_tui(sock, db, *extra):
    STACKS[sock] = str(db) + ".stacks"
    runner = os.path.join(ROOT, "tests", "_stacks_run.py")
    cmd = (
        f"cd {ROOT} && TERM=xterm-256color STATION_TEST_STACKS={STACKS[sock]} {sys.executable} {runner} tui "
        f"--db {db} --speed 20 "
        f"{' '.join(extra)}; echo EXIT=$?; sleep 30"
    )
    tmux(sock, "new-session", "-d", "-s", "demo", "-x", "80", "-y", "24", cmd)


def _quit(sock):
    _wait_pane(sock, lambda s: "f5 Start" in s, 60, "Connect again")
    _keys(sock, "C-q")
    _wait_pane(sock, lambda s: "EXIT=" in s, 30, "the exit")
    assert "EXIT=0" in pane(sock)


def _quit_discarding_the_result(sock):
    """On Results with an unsaved result: ctrl+q, answer yes to losing it, the app exits 0."""
    _keys(sock, "C-q")
    _wait_pane(sock, lambda s: "The unsaved result is lost" in s, 60, "the question before quitting")
    _keys(sock, "y")
    _wait_pane(sock, lambda s: "EXIT=" in s, 60, "the exit")
    assert "EXIT=0" in pane(sock)


def _history(db, device):
    out = subprocess.run(
        [sys.executable, "-m", "station", "history", device, "--json", "--db", str(db)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_p1_and_p5_by_keys_alone_in_tmux(tmp_path):
    """`station` (not the demo) at 80x24 on the built-in device, keys only: P1 with `p`
    placing each asked position, saved; then P5 picked on Connect, `d` drives, `t` turns,
    the conditioning says when it is enough, saved. The simulated device runs 20x."""
    sock = f"test-keys-{os.getpid()}"
    db = tmp_path / "station.db"
    _start_tui(sock, db, "--average-s 2")
    try:
        _wait_pane(sock, lambda s: "f5 Start" in s, 60, "the Connect screen")
        _keys(sock, "F5")
        _wait_pane(sock, lambda s: "P1 accelerometer, level table" in s and "p Place (sim)" in s, 60, "P1")
        placed = {"x_up"}  # the unit starts on x_up
        t_end = time.monotonic() + 300
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
            time.sleep(0.3)  # polling interval
        else:
            raise AssertionError("P1 not finished by keys within 300 s:\n" + screen)
        assert len(placed) == 12
        _save(sock, "P1 result", 1)
        _pick(sock, "P5 laser velocimeter")
        _keys(sock, "F5")
        _wait_pane(sock, lambda s: "d Drive/stop (sim)" in s and "Parked" in s, 60, "P5 parked")
        _keys(sock, "d")
        _wait_pane(sock, lambda s: "ILL-CONDITIONED" in s and "straight" in s, 60, "straight driving refused")
        _keys(sock, "t")
        screen = _wait_pane(sock, lambda s: "P5 LDV result" in s and "cond(HᵀH)" in s, 240, "the P5 result")
        assert "epochs" in screen  # what its count counts
        _save(sock, "P5 LDV result", 2)
        _quit(sock)
    finally:
        tmux(sock, "kill-server", check=False)
    for device, procedure in (("SIM-ACC-0000", "accel-tabletop"), ("SIM-LDV-0000", "ldv")):
        records = _history(db, device)
        assert len(records) == 1 and records[0]["procedure"] == procedure


def test_p2_p3_and_p4_in_both_modes_by_keys_alone_in_tmux(tmp_path):
    """The other procedures the same way, each picked on Connect: P2 (`p` mounts and spins
    the centrifuge for each asked row, `f` fits after 12 rows, four orientations), P3 (`p`
    sweeps the compass until the coverage is enough), P4 on a static base (hold still) and
    with the reference IMU (`p` runs the rate table); each saved."""
    sock = f"test-keys2-{os.getpid()}"
    db = tmp_path / "station.db"
    _start_tui(sock, db, "--average-s 40")  # per P2 row; the P4 record (≥ 30 s)
    try:
        _pick(sock, "P2 accelerometer, centrifuge")
        _keys(sock, "F5")
        _wait_pane(sock, lambda s: "p Spin (sim)" in s and "/60 captured" in s, 60, "P2")
        last = None
        t_end = time.monotonic() + 300
        screen = ""
        while time.monotonic() < t_end:
            screen = pane(sock)
            m = re.search(r"(\d+)/60 captured", screen)
            n = int(m.group(1)) if m else None
            if n is not None and n >= 12:
                break
            if "waiting for the change" in screen and n is not None and n != last:
                last = n  # one turn of the hand per asked row
                _keys(sock, "p")
            time.sleep(0.3)  # polling interval
        else:
            raise AssertionError("P2: 12 rows not captured by keys within 300 s:\n" + screen)
        _keys(sock, "f")
        screen = _wait_pane(sock, lambda s: "P2 centrifuge result" in s and " RMS " in s, 240, "the P2 result")
        assert "12 rows" in screen and "g/g^2" in screen  # D, the quadratic coefficient, with its unit
        _save(sock, "P2 centrifuge result", 1)

        _pick(sock, "P3 compass sweep")
        _keys(sock, "F5")
        _wait_pane(sock, lambda s: "p Sweep (sim)" in s and "Coverage" in s, 60, "P3")
        _keys(sock, "p")
        _save(sock, "P3 compass result", 2)

        _pick(sock, "P4 gyro drift, static base")
        _keys(sock, "F5")
        # the live mean in the axes of the result's drift (it was the device's own)
        _wait_pane(sock, lambda s: "Stillness" in s and "P4 body axes: x forward, y up, z right" in s, 60, "P4 static")
        _save(sock, "P4 gyro drift result", 3)

        _pick(sock, "P4 gyro drift, reference IMU")
        _keys(sock, "F5")
        _wait_pane(
            sock, lambda s: "p Rate table (sim)" in s and "unit − reference" in s and "P4 body axes" in s, 60, "P4 ref."
        )
        _keys(sock, "p")
        _wait_pane(sock, lambda s: "rate table ON" in s, 60, "the rate table running")
        _save(sock, "P4 gyro drift result", 4)
        _quit(sock)
    finally:
        tmux(sock, "kill-server", check=False)
    (p2,) = _history(db, "SIM-CFG-0000")
    assert p2["procedure"] == "accel-centrifuge" and p2["n_positions"] == 12
    (p3,) = _history(db, "SIM-COM-0000")
    assert p3["procedure"] == "compass"
    p4 = _history(db, "SIM-GYR-0000")
    assert [r["params"]["mode"] for r in p4] == ["static", "reference"]


def test_a_new_users_walkthrough_at_80x24_in_tmux(tmp_path):
    """The README's first command (`python3 dev.py station`) for a new user (a home with no
    database yet) at 80x24, every screen a first visit reaches: Help read to its end, History,
    a P4 file imported to Results, its limits set in °/h, its diagnosis; then quit. What was
    cut or misplaced at this size: Help lines wrapped to the box's edge, the diagnosis's long
    lines wrapped to the screen's edge, and Limits said "no database" until something was
    saved (the first limit now makes it)."""
    import math

    from station_run import run_station

    sock = f"test-walk-{os.getpid()}"
    home = tmp_path / "home"
    home.mkdir()
    capture = tmp_path / "p4.csv"
    r = run_station(
        "simulate", "--procedure", "gyro-drift", "--seed", 403000, "--option", "duration_s=60", "--out", capture
    )
    assert r.returncode == 0, r.stderr
    env = f"env -u STATION_DB -u XDG_DATA_HOME HOME={home} TERM=xterm-256color"
    cmd = f"cd {ROOT} && {env} {sys.executable} dev.py station; echo EXIT=$?; sleep 30"
    tmux(sock, "new-session", "-d", "-s", "demo", "-x", "80", "-y", "24", cmd)
    try:
        _wait_pane(sock, lambda s: "f5 Start" in s and "Built-in simulated device" in s, 120, "the Connect screen")
        _keys(sock, "F1")
        screen = _wait_pane(sock, lambda s: "Calibration station: keys" in s, 60, "Help")
        assert "simulated: p rate table (P4 reference IMU)" in screen
        assert not [line for line in screen.splitlines() if re.match(r"^ │ [a-z(]", line)], screen  # no stray wraps
        _keys(sock, "End")
        screen = _wait_pane(sock, lambda s: "│ under it says" in s, 60, "the end of Help")
        _keys(sock, "Escape", "F2")
        _wait_pane(sock, lambda s: "No devices yet" in s and "esc Back" in s, 60, "History")
        _keys(sock, "Escape")
        _wait_pane(sock, lambda s: "f5 Start" in s, 60, "Connect again")
        _keys(sock, "F7")
        _wait_pane(sock, lambda s: "path/to/file" in s, 60, "Import")
        _keys(sock, str(capture), "Enter")
        _wait_pane(sock, lambda s: "P4 gyro drift result" in s and " RMS " in s and "°/h" in s, 240, "P4 Results")
        _keys(sock, "l")
        _wait_pane(sock, lambda s: "the first one registers this new unit" in s, 60, "Limits of a new unit")
        _keys(sock, "drift=-2000:2000", "Enter")
        _wait_pane(sock, lambda s: "stored: drift = -2000 … 2000 °/h" in s, 60, "the limit stored")
        _keys(sock, "Escape")
        _wait_pane(sock, lambda s: "P4 gyro drift result" in s and "Limits of" not in s, 60, "Results again")
        _keys(sock, "g")
        screen = _wait_pane(sock, lambda s: "verdict" in s and "baseline" in s, 240, "the diagnosis")
        lines = screen.splitlines()[1:-1]
        labels = (
            "procedure",
            "baseline",
            "candidates",
            "extended",
            "verdict",
            "measured",
            "effect",
            "quality",
            "WARNING",
        )
        assert all(not line.strip() or line[1:].startswith((" ", *labels)) for line in lines), screen
        _keys(sock, "Escape")
        # judged again with the limit set: inside it
        _wait_pane(sock, lambda s: "P4 gyro drift result" in s and " PASS " in s, 60, "Results again")
        _quit_discarding_the_result(sock)
    finally:
        tmux(sock, "kill-server", check=False)
    from db import Store

    with Store(str(home / ".local" / "share" / "station" / "station.db")) as s:
        (device,) = s.list_devices()
        low, high = device["limits"]["drift"]
    assert math.isclose(high, 2000 * math.pi / 648000, rel_tol=1e-12) and math.isclose(low, -high, rel_tol=1e-12)


def test_keys_sent_in_one_burst_open_a_screen_and_fill_its_field_in_tmux(tmp_path):
    """`tmux send-keys F7 PATH Enter` in one burst: the path was lost (sent to Connect's Start
    button before F7 opened Import, dropped when it came back up), and so was the limit after
    `l` on Results. Each burst is one send-keys, waited on by what the screen then shows."""
    from station_run import run_station

    sock = f"test-burst-{os.getpid()}"
    db = tmp_path / "station.db"
    capture = tmp_path / "p4.csv"
    r = run_station(
        "simulate", "--procedure", "gyro-drift", "--seed", 403000, "--option", "duration_s=60", "--out", capture
    )
    assert r.returncode == 0, r.stderr
    _start_tui(sock, db)
    try:
        _wait_pane(sock, lambda s: "f5 Start" in s and "Import file" in s, 60, "the Connect screen")
        tmux(sock, "send-keys", "-t", "demo", "F7", str(capture), "Enter")  # one send-keys: one burst
        _wait_pane(sock, lambda s: "P4 gyro drift result" in s and " RMS " in s, 240, "P4 Results")
        tmux(sock, "send-keys", "-t", "demo", "l", "drift=-2000:2000", "Enter")
        _wait_pane(sock, lambda s: "stored: drift = -2000 … 2000 °/h" in s, 60, "the limit stored")
        _keys(sock, "Escape")  # alone: an escape with a key after it in one read is alt+that key
        _wait_pane(sock, lambda s: "P4 gyro drift result" in s and " PASS " in s, 60, "Results judged by the limit")
        _quit_discarding_the_result(sock)
    finally:
        tmux(sock, "kill-server", check=False)


def test_station_with_only_port_starts_the_tui_on_that_device_in_tmux(tmp_path):
    """README: `station` is the TUI "on the built-in simulated device unless --port is given".
    `station --port /dev/ttyUSB0` was refused by the argument parser (the port taken for a
    command name); it is `station tui --port ...`: Connect with the port filled in, and Start
    reads the device."""
    from station_run import sim_device

    sock = f"test-port-{os.getpid()}"
    with sim_device("--seed", "5") as sim:  # stopped by SIGINT after the tmux server
        port = sim.port
        try:
            cmd = (
                f"cd {ROOT} && TERM=xterm-256color {sys.executable} -m station --port {port} --db {tmp_path / 'st.db'}; "
                "echo EXIT=$?; sleep 30"
            )
            tmux(sock, "new-session", "-d", "-s", "demo", "-x", "80", "-y", "24", cmd)
            screen = _wait_pane(
                sock,
                lambda s: ("f5 Start" in s and f"Port or URL     {port}" in s and "Other port" in s) or "EXIT=" in s,
                120,
                "the Connect screen with the port",
            )
            assert "EXIT=" not in screen, screen
            _keys(sock, "F5")
            _wait_pane(sock, lambda s: "Stillness" in s and "0/12 captured" in s, 120, "P1 on the serial device")
            _keys(sock, "a")
            _wait_pane(sock, lambda s: "y yes" in s, 60, "the abort question")
            _keys(sock, "y")
            _quit(sock)
        finally:
            tmux(sock, "kill-server", check=False)


def test_history_boxes_leave_the_reminder_whole_at_80x24_in_tmux(tmp_path):
    """The start-up reminder of an overdue device, with History's interval box (`i`) or the
    firmware box (`e`) open, was drawn twice: on History's notice lines under the box and as a
    toast over them, which cut the line ('Recalibration: overdue: OLD-UNIT-7; du▌'). Textual's
    pilot does not draw that toast; the real terminal does."""
    from db import Store
    from station.store import save_result
    from tests.tui_data import p1_result

    db = tmp_path / "station.db"
    cap, result = p1_result("OLD-UNIT-7")
    save_result(str(db), cap, result, device_id="OLD-UNIT-7")  # 2026-03-01
    with Store(str(db)) as store:
        store.add_device("OLD-UNIT-7", interval_days=30)
    sock = f"test-boxes-{os.getpid()}"
    _start_tui(sock, db)
    try:
        _wait_pane(sock, lambda s: "f5 Start" in s and "OLD-UNIT-7" in s, 60, "Connect with the reminder")
        seen = {}
        for key, what in (("i", "Recalibration interval of"), ("e", "for a flight controller")):
            _keys(sock, "F2")
            # the device's calibrations drawn (its interval and its row), not only the screen: a key
            # before that finds no device highlighted (CI: `e` said "No calibration to export")
            _wait_pane(
                sock,
                lambda s: (
                    "devices and calibrations" in s and "e Firmware" in s and "30-day interval" in s and "in use" in s
                ),
                60,
                "History with the device's calibration",
            )
            _keys(sock, "Tab", key)
            seen[key] = _wait_pane(sock, lambda s, w=what: w in s and "(F2 history)" in s, 60, what)
            _keys(sock, "Escape", "Escape")
        _quit(sock)
    finally:
        tmux(sock, "kill-server", check=False)
    for key, screen in seen.items():
        assert "▌" not in screen, (key, screen)  # a toast's left edge
        flat = " ".join(screen.split())
        assert "Recalibration: overdue: OLD-UNIT-7 (F2 history)" in flat, (key, screen)
