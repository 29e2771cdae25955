"""A new user at 80x24 over SSH, and what earlier testers left open (qa-s27t): the quit
question under a toast, a diagnosis that said nothing for a minute and could not be stopped,
the Connect screen's status lines without end. The real app under its pilot, a real SQLite
file, the simulated device."""

from __future__ import annotations

import asyncio
import os
import re
import sys
import time

from station.app import make_app
from station.sources import SimSource
from tests.test_screens_80x24 import _covered
from tests.test_tui import SIZE, BenchClock, screen_lines, screen_name, wait_for

# ---------------------------------------------------------------- 1. a toast over the quit question


def test_a_toast_never_covers_the_quit_question(tmp_path):
    """ctrl+q with a toast up (an export's, a reminder's: up to 10 s, two stacked at the bottom
    right) drew the toasts over the confirmation's box: its question was cut ("Quit? The run
    in progress is l▌"). The box says the notices itself, under its question."""

    async def story():
        clock = BenchClock()
        src = SimSource(seed=3, clock=clock)
        app = make_app(str(tmp_path / "s.db"), device=src, start="procedure", average_s=1.0, settle_s=0.5)
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await wait_for(pilot, lambda: getattr(app.screen, "guide", None) is not None)
            for n in range(2):
                app.notify(f"Exported IMU-7-accel-tabletop-20261130T015{n}Z.json in /tmp/station/exports", timeout=60)
            await pilot.press("ctrl+q")
            await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
            await wait_for(pilot, lambda: "20261130T0151Z" in " ".join(screen_lines(app)))  # a notice is drawn
            covered, lines = _covered(app, ["#box"]), screen_lines(app)
            await pilot.press("n")
            await wait_for(pilot, lambda: screen_name(app) != "ConfirmScreen")
            return covered, lines

    covered, lines = asyncio.run(story())
    assert covered == [], "\n".join(lines)
    flat = " ".join(" ".join(line.strip(" │╭╮╰╯─") for line in lines).split())
    assert "Quit? The run in progress is lost." in flat, "\n".join(lines)
    assert "y yes · n no" in flat, "\n".join(lines)


def test_the_quit_question_follows_the_run_going_on_behind_it(tmp_path):
    """The P1 run goes on while the quit question is up (the operator may have the unit on the
    table already): a position captured then was kept for Resume, but the box still said "The 1
    captured position is kept" (found at 80x24 in tmux: two ticked in the step list behind it).
    The question now says what quitting keeps at the moment it is answered."""
    from tests.test_tui import run_bench

    async def story():
        clock = BenchClock()
        src = SimSource(seed=3, clock=clock)
        app = make_app(str(tmp_path / "s.db"), device=src, start="procedure", average_s=1.0, settle_s=0.5)
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: getattr(app.screen, "guide", None) is not None)
            guide, procedure = app.screen.guide, app.screen
            await run_bench(pilot, src, clock, lambda: guide.n_captured == 1)  # x_up: the unit starts there
            await wait_for(pilot, lambda: os.path.exists(guide.state_path))
            await pilot.press("p")  # turned to x_down
            await wait_for(pilot, lambda: "turned to x_down" in " ".join(n.message for n in app._notifications))
            await pilot.press("ctrl+q")
            await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
            before = app.screen.question
            # the bench goes on behind the box: x_down settles, is averaged, captured and kept
            await run_bench(pilot, src, clock, lambda: guide.n_captured == 2)
            try:
                await wait_for(pilot, lambda: "The 2 captured positions are kept" in app.screen.question, timeout_s=30)
            except AssertionError:
                pass
            after = app.screen.question
            await pilot.press("n")
            await wait_for(pilot, lambda: app.screen is procedure)
            return before, after

    before, after = asyncio.run(story())
    assert "The 1 captured position is kept" in before, before
    assert "The 2 captured positions are kept: F6 on the Connect screen resumes." in after, after


# ---------------------------------------------------------------- 2. a diagnosis that says how far it is


def _children(pid: int) -> list[str]:
    """The command lines of the processes ``pid`` started that still run."""
    out = []
    for task in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{task}/children") as fh:
                kids = fh.read().split()
        except OSError:
            continue
        for kid in kids:
            try:
                with open(f"/proc/{kid}/cmdline", "rb") as fh:
                    out.append(fh.read().replace(b"\0", b" ").decode())
            except OSError:
                pass
    return out


def _diagnosis_running() -> list[str]:
    """What of a diagnosis still runs in this process (a thread in its code) or under it (a child
    process): the world's view, not the screen's."""
    busy = []
    for tid, frame in sys._current_frames().items():
        f = frame
        while f is not None:
            name = f.f_code.co_filename.replace(os.sep, "/")
            if "/solvers/diagnose/" in name or name.endswith("procedures/diagnose.py"):
                busy.append(f"thread {tid}: {name}:{f.f_lineno}")
                break
            f = f.f_back
    busy += [f"process: {cmd}" for cmd in _children(os.getpid()) if "diagnos" in cmd]
    return busy


SEARCHING = {"calibrating (the baseline model)", "fitting the baseline and searching the candidate effects"}


def test_a_long_diagnosis_says_its_step_and_time_and_escape_stops_it():
    """Diagnose showed "Diagnosing: fitting the baseline and the candidate effects…" and nothing
    else for 60-90 s on a loaded machine (a compass capture); Escape went back but the diagnosis
    ran on in its thread, and a second Diagnose ran beside it. Now the screen says the step it is
    at and the seconds taken, and Escape stops it: nothing of it runs afterwards."""
    from solvers.simulate import simulate_compass
    from station.screens.diagnose import DiagnoseScreen
    from tests.station_run import capture_of

    # a long hand-held tumble (60 attitudes held 10 s at 200 Hz): minutes of diagnosis
    cap = capture_of(simulate_compass(seed=5, rate_hz=200.0, n_orientations=60, hold_s=10.0))
    progress = re.compile(r"Diagnosing \((\d+) s\): (.+?)…")

    def said():
        m = progress.search(" ".join(screen_lines(app)))
        return (int(m.group(1)), m.group(2)) if m else None

    async def story():
        nonlocal app
        app = make_app(None)
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await app.push_screen(DiagnoseScreen(capture=cap))
            seen = []
            # it says the step it has begun, and the seconds count on while it works in it
            await wait_for(pilot, lambda: (s := said()) and (seen.append(s) or s[1] in SEARCHING))
            t_s = seen[-1][0]
            await wait_for(pilot, lambda: (s := said()) and (seen.append(s) or s[0] > t_s))
            steps = {s[1] for s in seen}
            report = app.screen.report
            lines = screen_lines(app)
            await pilot.press("escape")
            await wait_for(pilot, lambda: screen_name(app) != "DiagnoseScreen")
            await wait_for(pilot, lambda: not _diagnosis_running(), timeout_s=30.0)
            back = screen_name(app)
            notices = " ".join(n.message for n in app._notifications)
        return steps, report, lines, back, notices

    app = None
    steps, report, lines, back, notices = asyncio.run(story())
    assert report is None, report  # still working when it was stopped
    assert steps & SEARCHING, (steps, "\n".join(lines))
    assert any("Esc" in line and "stops" in line for line in lines), "\n".join(lines)
    assert back == "ConnectScreen"
    assert "Diagnosis stopped" in notices, notices


# ---------------------------------------------------------------- 3. Connect's lines under the buttons


def test_connect_keeps_its_error_and_its_notices_within_the_screen(tmp_path):
    """Under Connect's buttons there are 3 rows at 80x24. A refused port (2 rows), the start-up
    reminder and the notices a run left (a device error, an abort) took 5 and more: the screen
    scrolled (a scroll bar narrowed it, the Reference hint lost its ')'), and the newest notices,
    the device's error among them, were below the footer, where no key brings them. Now the
    status stays whole, the newest error is shown first and the rest are counted."""
    from tests.tui_data import seed_history

    db = str(tmp_path / "s.db")
    seed_history(db, "IMU-7", n=1, interval_days=30, start_year=2021)  # overdue: the start-up reminder
    device_error = "device: /dev/ttyUSB0: read failed: the device is not answering (unplugged?)"

    async def story():
        app = make_app(db)
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await wait_for(pilot, lambda: "IMU-7" in " ".join(screen_lines(app)[19:23]))
            app.notify(device_error, severity="error", timeout=120)
            app.notify("P1 aborted: nothing saved", timeout=120)
            app.screen.query_one("#port").focus()
            await pilot.press(*"/dev/ttyNOPE", "f5")
            await wait_for(pilot, lambda: "Cannot connect" in " ".join(screen_lines(app)))
            await pilot.pause()
            return app.screen.max_scroll_y, screen_lines(app)

    scroll_rows, lines = asyncio.run(story())
    shown = "\n".join(lines)
    flat = " ".join(shown.split())
    assert scroll_rows == 0, shown  # nothing out of sight
    assert "Cannot connect: cannot open the port: No such file or directory: check the path and the cable" in flat
    assert "device: /dev/ttyUSB0: read failed" in flat, shown  # the newest error, if cut, begun
    assert re.search(r"\b[23] (more )?notices\b", flat), shown  # the rest counted
    assert "model and serial)" in flat, shown  # no scroll bar took a column
    assert lines[-1].startswith("f5 Start")


# ---------------------------------------------------------------- end to end, in a real terminal


def test_diagnose_in_tmux_says_its_step_and_escape_stops_it(tmp_path, shared_data):
    """`station` at 80x24 in tmux, keys only: F7 imports a real compass capture (sunsided's full
    sphere, ../shared/data), `g` diagnoses it: the screen says the step and the seconds; Esc is
    back on Results at once with "Diagnosis stopped", and the app has nothing of it running."""
    import pytest

    from tests.test_e2e_tmux import REQUIRED, STACKS, TMUX, _keys, _quit_discarding_the_result, _start_tui, _wait_pane
    from tests.test_e2e_tmux import tmux as run_tmux

    if not os.path.exists(TMUX) and not REQUIRED:
        pytest.skip("tmux not installed")
    capture = str(shared_data / "sunsided_marg" / "sunsided_full_sphere.capture.csv")
    sock = f"test-s27t-{os.getpid()}"
    _start_tui(sock, tmp_path / "s.db")
    try:
        _wait_pane(sock, lambda s: "f5 Start" in s, 60, "Connect")
        _keys(sock, "F7")
        _wait_pane(sock, lambda s: "path/to/file" in s, 60, "Import")
        _keys(sock, capture, "Enter")
        _wait_pane(sock, lambda s: "P3 compass result" in s and "g Diagnose" in s, 120, "the P3 result")
        _keys(sock, "g")
        working = re.compile(r"Diagnosing \((\d+) s\): (calibrating|fitting the baseline)")
        screen = _wait_pane(sock, lambda s: working.search(s), 120, "the diagnosis's step and time")
        assert "Esc stops it" in screen, screen
        _keys(sock, "Escape")
        _wait_pane(sock, lambda s: "P3 compass result" in s and "Diagnosis stopped" in s, 60, "Results again")
        with open(STACKS[sock] + ".pid") as fh:
            app_pid = int(fh.read())
        t_end = time.monotonic() + 30
        while [c for c in _children(app_pid) if "diagnos" in c] and time.monotonic() < t_end:
            time.sleep(0.2)  # polling, not a pace
        assert not [c for c in _children(app_pid) if "diagnos" in c], _children(app_pid)
        _quit_discarding_the_result(sock)
    finally:
        run_tmux(sock, "kill-server", check=False)
