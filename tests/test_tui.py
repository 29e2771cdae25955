"""Pilot tests: each screen's story, on the real Textual app at 80x24, a real SQLite file,
the simulated device (in-process, or on a real pty through the serial reader)."""

from __future__ import annotations

import asyncio
import contextlib
import datetime
import json
import math
import os
import threading
import time

import numpy as np
import pytest
from textual.css.query import NoMatches

from station.app import make_app
from station.sources import SimSource
from tests.tui_data import p1_result, seed_history

SIZE = (80, 24)


async def wait_for(pilot, cond, timeout_s=120.0, step_s=0.05):
    """Wait until ``cond()`` holds. The timeout is a safety net for a hung app, not a pace:
    it is generous so a loaded machine (8 jobs on 2 cores) only makes the test slower. A
    widget not mounted yet (the screen is still composing) counts as not yet."""
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        try:
            if cond():
                return True
        except NoMatches:
            pass
        await pilot.pause(step_s)
    try:  # what the screen showed, to tell a hung app from a condition that never held
        shown = "\n".join(screen_lines(pilot.app))
    except Exception as exc:  # noqa: BLE001 - a screen that cannot be drawn says so instead
        shown = f"(no screen: {exc!r})"
    raise AssertionError(f"timed out after {timeout_s} s waiting for {cond}; the screen:\n{shown}")


async def history_shown(pilot, app, rows: int):
    """Wait until History is the screen and its table holds ``rows`` calibrations."""
    await wait_for(
        pilot,
        lambda: screen_name(app) == "HistoryScreen" and app.screen.query_one("#calibrations").row_count == rows,
    )


class BenchClock:
    """The simulated bench's clock, advanced by the test (``SimSource(clock=...)``): the
    device only moves on when the test says so, so no phase can pass unseen and a loaded
    machine cannot make the consumer fall behind and lose samples."""

    def __init__(self) -> None:
        self.t_s = 0.0

    def __call__(self) -> float:
        return self.t_s


def _consumed(src) -> bool:
    """Has the app drained everything the clock made due? (the source's own counters)"""
    if src._t0 is None:
        return True
    return int((src.clock() - src._t0) * src.speed * src.rate_hz) <= src._produced


async def run_bench(pilot, src, clock: BenchClock, until, step_s=0.2, max_device_s=3600.0, timeout_s=600.0):
    """Advance ``clock`` by ``step_s`` each time the app has drained the source, until
    ``until()`` holds (NoMatches counts as not yet)."""
    t_end = time.monotonic() + timeout_s
    t_max = clock.t_s + max_device_s
    while True:
        try:
            if until():
                return
        except NoMatches:
            pass
        if clock.t_s > t_max or time.monotonic() > t_end:
            raise AssertionError(f"{until} never held ({clock.t_s:.1f} s device time)")
        if _consumed(src):
            clock.t_s += step_s
        await pilot.pause(0.01)


class Bench:
    """A guided screen on a simulated unit whose clock the test advances (:func:`guided_bench`):
    the ``app``, its ``pilot``, the source ``src`` and its ``clock``."""

    def __init__(self, app, pilot, src, clock: BenchClock) -> None:
        self.app, self.pilot, self.src, self.clock = app, pilot, src, clock

    async def run(self, until, **options) -> None:
        """Run the bench until ``until()`` holds (:func:`run_bench`'s options)."""
        await run_bench(self.pilot, self.src, self.clock, until, **options)


@contextlib.asynccontextmanager
async def guided_bench(db=None, *, seed: int, notifications: bool = False, **app_options):
    """The app started on P1's guided screen (``make_app(..., start="procedure")`` with
    ``app_options``: ``average_s``, ``settle_s``) over a simulated unit of ``seed`` on a
    :class:`BenchClock`, at 80x24; yields a :class:`Bench` once the screen's guide is up."""
    clock = BenchClock()
    src = SimSource(seed=seed, clock=clock)
    app = make_app(db, device=src, start="procedure", **app_options)
    async with app.run_test(size=SIZE, notifications=notifications) as pilot:
        await wait_for(pilot, lambda: getattr(app.screen, "guide", None) is not None)
        yield Bench(app, pilot, src, clock)


async def abort_to_resume(pilot, app):
    """``a`` on a guided screen and ``y`` to its question: back on Connect, whose Resume button
    (for the positions kept) is returned once it is enabled."""
    await pilot.press("a")
    await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
    await pilot.press("y")
    await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")
    resume = app.screen.query_one("#resume")
    await wait_for(pilot, lambda: not resume.disabled)
    return resume


@contextlib.contextmanager
def simulated_device_on_a_pty(seed: int, rate_hz: float, buffer_s: float = 0.5):
    """The built-in device serving a real pseudo-terminal from a thread; yields the device and
    its port's path, and stops the thread and closes the pty on the way out. ``buffer_s``: the
    output its UART holds while the host does not read (`sim-device --buffer-s`; 0.5 s, the
    default, drops what waits when the app is not scheduled for half a second)."""
    from solvers.simulate import LiveImu
    from station.device.simdevice import SimDevice

    dev = SimDevice(LiveImu(seed=seed, rate_hz=rate_hz, hold_s=1e9), max_pending_s=buffer_s)
    path = dev.open()
    stop = threading.Event()
    t = threading.Thread(target=dev.run, args=(stop,), daemon=True)
    t.start()
    try:
        yield dev, path
    finally:
        stop.set()
        t.join(10)
        dev.close()


def screen_name(app) -> str:
    return type(app.screen).__name__


def screen_lines(app) -> list[str]:
    """The terminal as text (what the operator sees)."""
    return [strip.text for strip in app.screen._compositor.render_strips()]


def screen_text(app) -> str:
    """The terminal as one text, a line per row."""
    return "\n".join(screen_lines(app))


async def start_on_sim(pilot, app, procedure: str, seed: int, until):
    """On Connect: pick ``procedure``, give the session a simulated device of it on a bench clock,
    F5, and run the bench until ``until()`` holds; returns (source, clock) to run it on."""
    app.screen.query_one("#procedure").value = procedure
    clock = BenchClock()
    src = app.session.source = SimSource(seed=seed, procedure=procedure, clock=clock)
    await pilot.press("f5")
    await run_bench(pilot, src, clock, until)
    return src, clock


def text_of(app, selector) -> str:
    """The text shown in the widget's region of the screen."""
    r = app.screen.query_one(selector).region
    return "\n".join(line[r.x : r.right] for line in screen_lines(app)[r.y : r.bottom])


def words_of(app, selector=None) -> str:
    """The words shown in the widget's region (without ``selector``, on the whole screen) as one
    line: the text as it reads, wherever the screen wrapped it."""
    return " ".join((text_of(app, selector) if selector else screen_text(app)).split())


# ---------------------------------------------------------------- Connect


def test_connect_screen_starts_p1_on_the_simulator_and_registers_the_device(tmp_path):
    db = str(tmp_path / "station.db")

    async def story():
        # 180 s given: the first position is still being averaged when it is looked at (the
        # simulator's own 10 s pass in 1 s at speed 10)
        app = make_app(db, device=SimSource(seed=2, speed=10), average_s=180.0)
        async with app.run_test(size=SIZE) as pilot:
            assert screen_name(app) == "ConnectScreen"
            assert "Built-in simulated device" in text_of(app, "#source")
            assert "f5 Start" in screen_lines(app)[-1]  # the footer shows the keys
            await pilot.click("#model")
            await pilot.press(*"ADXL335")
            await pilot.press("f5")
            await wait_for(pilot, lambda: screen_name(app) == "ProcedureScreen")
            await wait_for(pilot, lambda: app.screen.last_status is not None and app.screen.updates > 3)
            assert "x_up" in text_of(app, "#placement")
            assert "Stillness" in text_of(app, "#stability")
        return app

    app = asyncio.run(story())  # noqa: F841
    from db.store import Store

    dev = Store(db).get_device("SIM-ACC-0002")
    assert dev is not None and dev["model"] == "ADXL335"


def test_connect_refuses_a_bad_averaging_time_and_a_missing_port():
    async def story():
        app = make_app(None)
        async with app.run_test(size=SIZE) as pilot:
            app.screen.query_one("#average").value = "abc"
            await pilot.press("f5")
            await wait_for(pilot, lambda: "positive number" in text_of(app, "#status"))
            app.screen.query_one("#average").value = "5"
            app.screen.query_one("#source").value = "other"
            await pilot.press("f5")
            await wait_for(pilot, lambda: "Type a port" in text_of(app, "#status"))
            assert screen_name(app) == "ConnectScreen"

    asyncio.run(story())


@pytest.mark.parametrize("procedure", ["gyro-drift", "gyro-reference"])
def test_connect_refuses_a_p4_record_too_short_for_its_fit_before_recording(procedure):
    """A record length left at a short P1 average (1 s) ran P4 for that long, then said the
    record was too short: refused on Connect instead, nothing recorded."""
    from solvers.gyrodrift import MIN_DURATION_S

    async def story():
        app = make_app(None)
        async with app.run_test(size=SIZE) as pilot:
            app.screen.query_one("#procedure").value = procedure
            app.screen.query_one("#average").value = "1"
            await pilot.press("f5")
            await wait_for(pilot, lambda: "too short" in text_of(app, "#status"))
            status = words_of(app, "#status")
            assert f"at least {MIN_DURATION_S:g} s" in status and "P4 asks ≥ 180 s" in status
            assert screen_name(app) == "ConnectScreen" and app.session.source is None
            app.screen.query_one("#average").value = f"{MIN_DURATION_S:g}"
            await pilot.press("f5")
            await wait_for(pilot, lambda: screen_name(app) != "ConnectScreen")

    asyncio.run(story())


def test_help_opens_and_closes_with_the_keyboard():
    async def story():
        app = make_app(None)
        async with app.run_test(size=SIZE) as pilot:
            await pilot.press("f1")
            await wait_for(pilot, lambda: screen_name(app) == "HelpScreen")
            await wait_for(pilot, lambda: "s skip" in text_of(app, "HelpScreen Static"))
            # how to close it is on screen (the footer showed Connect's keys, dead under the box)
            await wait_for(pilot, lambda: screen_lines(app)[-1].split() == ["esc", "Close"])
            assert "esc, F1 or ? closes this" in text_of(app, "HelpScreen Static")
            # the simulated device's keys of every procedure (P1 and P2 were missing)
            assert "simulated: p place the unit" in text_of(app, "HelpScreen Static")
            assert "simulated: p mount and spin" in text_of(app, "HelpScreen Static")
            await pilot.press("end")  # the rest by scrolling
            await wait_for(pilot, lambda: "g diagnose" in text_of(app, "HelpScreen Static"))
            await pilot.press("escape")
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")
            await pilot.press("f1")
            await wait_for(pilot, lambda: screen_name(app) == "HelpScreen")
            await pilot.press("f1")
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")

    asyncio.run(story())


# ---------------------------------------------------------------- Procedure → Results


def test_demo_runs_a_whole_p1_and_saves_it(tmp_path):
    """The scripted operator follows the prompts; the result reaches the database."""
    db = str(tmp_path / "station.db")

    async def story():
        clock = BenchClock()
        src = SimSource(seed=4, clock=clock)
        app = make_app(db, device=src, demo=True, average_s=1.0, settle_s=0.5)
        async with app.run_test(size=SIZE) as pilot:
            await run_bench(pilot, src, clock, lambda: screen_name(app) == "ResultsScreen", step_s=0.25)
            await wait_for(pilot, lambda: app.screen.calibration_id is not None)
            summary = text_of(app, "#summary")
            params = app.screen.query_one("#params")
            residuals = app.screen.query_one("#residuals")
            # both triads: B, M (12) and the gyro's K, eps, G (21) from the turns between positions
            assert params.row_count == 12 + 21 and residuals.row_count == 12
            assert "Saved as calibration" in text_of(app, "#saved")
            cal_id = app.screen.calibration_id
            steps = app.session.guide.steps
        return steps, summary, cal_id

    steps, summary, cal_id = asyncio.run(story())
    assert all(s.status == "captured" and s.n >= 100 for s in steps)  # 1 s averages at 100 Hz
    assert "no previous" in summary and "gyro: 11 turns between 12 holds" in summary
    from db.store import Store

    hist = Store(db).history("SIM-ACC-0004")
    assert [h["id"] for h in hist] == [cal_id] and hist[0]["procedure"] == "accel-tabletop"
    assert hist[0]["n_positions"] == 12
    gyro = Store(db).calibration(cal_id)["extra"]["gyro"]
    assert gyro["n_rotations"] == 11 and len(gyro["params"]["K"]) == 3 and len(gyro["uncertainty"]["eps"]) == 3
    assert not any(p.startswith("resume-") for p in os.listdir(tmp_path))  # saved: nothing to resume


def test_compass_sweep_from_connect_to_a_saved_result(tmp_path):
    """Connect with the P3 procedure picked; the demo operator turns the unit; coverage map
    fills; the fit is saved."""
    db = str(tmp_path / "station.db")

    async def story():
        app = make_app(db, demo=True)
        # 120 s of device time (3 s here): the shared coverage measure (30° per direction)
        # passes 80 % within seconds, so a shorter minimum ended the run before the screen
        # was looked at
        app.session.extra["compass_min_s"] = 120.0
        async with app.run_test(size=SIZE) as pilot:
            src, clock = await start_on_sim(
                pilot, app, "compass", 3, lambda: screen_name(app) == "CompassScreen" and app.screen.updates > 2
            )
            await wait_for(pilot, lambda: "+z" in text_of(app, "#map") and "Coverage" in text_of(app, "#progress"))
            # both lines in sight at 80x24: a longer coverage line wrapped and hid 'Recorded'
            progress = text_of(app, "#progress")
            assert "Recorded" in progress and "samples" in progress, progress
            await run_bench(pilot, src, clock, lambda: screen_name(app) == "ResultsScreen", step_s=0.5)
            await wait_for(pilot, lambda: app.screen.calibration_id is not None)
            title = screen_lines(app)[0]
            assert not app.screen.query_one("#residuals").display  # P1-only table
            params = app.screen.query_one("#params")
            shown = {params.get_row_at(i)[0]: params.get_row_at(i) for i in range(params.row_count)}
        return title, shown

    day_before = datetime.datetime.now(datetime.UTC).date().isoformat()
    title, shown = asyncio.run(story())
    day_after = datetime.datetime.now(datetime.UTC).date().isoformat()
    assert "P3 compass result" in title
    from db.store import Store

    hist = Store(db).history("SIM-COM-0003")
    assert len(hist) == 1 and hist[0]["procedure"] == "compass"
    # filed today, at the run's start (the built-in bench had the simulator's fixed date: a sweep
    # made today went into the history, and the due date, days in the past at midnight)
    assert hist[0]["time"][:10] in (day_before, day_after), hist[0]["time"]
    # soft iron on screen as a ratio (calibrated per raw field, both in the capture's unit):
    # ~1 on the diagonal; stored as nT per mag_unit (calibrate.md), e.g. ~1000 nT per uT
    unit = hist[0]["extra"]["mag_unit"]
    per_unit_nT = {"nT": 1.0, "uT": 1e3, "gauss": 1e5}[unit]
    for i in range(3):
        for j in range(3):
            name, value, _, shown_unit = shown[f"soft_iron[{i}][{j}]"][:4]
            assert shown_unit == f"{unit}/{unit}"
            assert float(value) == pytest.approx(hist[0]["params"]["soft_iron"][i][j] / per_unit_nT, rel=1e-6)
        # a simulated magnetometer's scale errors are a few percent, not a factor
        assert 0.8 < float(shown[f"soft_iron[{i}][{i}]"][1]) < 1.2


def test_gyro_drift_hold_to_a_saved_result(tmp_path):
    """P4 static base: the unit lies still, the countdown runs, the drift is fitted and saved."""
    db = str(tmp_path / "station.db")

    async def story():
        clock = BenchClock()
        src = SimSource(seed=5, procedure="gyro-drift", clock=clock)
        app = make_app(db, device=src, demo=True, average_s=180.0)
        async with app.run_test(size=SIZE) as pilot:
            await run_bench(pilot, src, clock, lambda: screen_name(app) == "HoldScreen" and app.screen.updates > 2)
            await run_bench(
                pilot,
                src,
                clock,
                lambda: app.screen.last_status is not None and app.screen.last_status.phase == "average",
            )
            await wait_for(
                pilot, lambda: "left" in text_of(app, "#countdown") and "still" in text_of(app, "#stability")
            )
            recording = text_of(app, "#readouts")
            assert text_of(app, "#countdown").startswith("Record ")  # a P4 record, not an average
            await run_bench(pilot, src, clock, lambda: screen_name(app) == "ResultsScreen", step_s=1.0)
            await wait_for(pilot, lambda: app.screen.calibration_id is not None)
            params = app.screen.query_one("#params")
            shown = {params.get_row_at(i)[0]: params.get_row_at(i) for i in range(params.row_count)}
            summary = str(app.screen.query_one("#summary").render())
            title = screen_lines(app)[0]
        return title, recording, shown, summary

    title, recording, shown, summary = asyncio.run(story())
    assert "P4 gyro drift result" in title
    from db.store import Store

    hist = Store(db).history("SIM-GYR-0005")
    assert len(hist) == 1 and hist[0]["procedure"] == "gyro-drift"
    # one unit for the drift on screen, while recording and on Results: °/h (1 °/h = π/648000
    # rad/s); the stored result keeps rad/s (calibrate.md)
    deg_h = math.radians(1.0) / 3600.0
    assert "°/h" in recording and "rad/s" not in recording
    assert "P4 body axes: x forward, y up, z right" in recording  # the result's axes, not the device's
    assert "rad/s" not in summary and "°/h RMS" in summary
    for i in range(3):
        name, value, sigma, unit = shown[f"drift[{i}]"][:4]
        stored, stored_sigma = hist[0]["params"]["drift"][i], hist[0]["uncertainty"]["drift"][i]
        assert unit == "°/h" and shown[f"earth_rate_body[{i}]"][3] == "°/h"
        # the table's 7 and 2 significant digits
        assert float(value) == pytest.approx(stored / deg_h, rel=1e-6)
        assert float(sigma) == pytest.approx(stored_sigma / deg_h, rel=0.05)


def test_wrong_face_up_is_shown_and_blocks_capture():
    async def story():
        async with guided_bench(seed=1, average_s=60.0) as bench:
            app, pilot = bench.app, bench.pilot
            bench.src.place("x_down")  # asked for x_up
            await bench.run(
                lambda: app.screen.last_status and app.screen.last_status.wrong_face and app.screen.last_status.is_still
            )
            await wait_for(pilot, lambda: "WRONG FACE UP" in text_of(app, "#orientation"))
            assert "Upside down: turn the unit over" in text_of(app, "#message")
            assert app.screen.guide.n_captured == 0

    asyncio.run(story())


def test_p1_live_rate_reads_in_degrees_per_second():
    """P1's live readout gives the gyro in °/s, as an operator reads a rate, from a device
    that streams rad/s; the guide's status (and so the capture) keeps the device's unit."""
    import re

    async def story():
        async with guided_bench(seed=3, average_s=60.0) as bench:
            app, src = bench.app, bench.src
            src.place("y_up")  # a quarter turn from x_up: tens of °/s for a few seconds
            seen = {}

            def turning() -> bool:
                st = app.screen.last_status  # drawn in the same handler as the readout
                if st is None or not all(map(math.isfinite, st.gyro)):
                    return False
                seen["gyro"], seen["text"] = st.gyro, str(app.screen.query_one("#readouts").render())
                return max(map(abs, st.gyro)) > math.radians(10.0)

            await bench.run(turning, step_s=0.05)
            return src.units["gyro_unit"], seen

    unit, seen = asyncio.run(story())
    assert unit == "rad/s"  # what the device streams
    line = next(x for x in seen["text"].splitlines() if x.startswith("rate"))
    assert line.endswith(" °/s") and "rad/s" not in seen["text"], seen["text"]
    shown = [float(v) for v in re.findall(r"[-+]?\d+\.\d+", line)]
    # printed to 0.001 °/s; 1 rad/s = 180/π °/s
    assert shown == pytest.approx([math.degrees(w) for w in seen["gyro"]], abs=6e-4)
    assert max(map(abs, shown)) > 10.0


def test_skip_redo_abort_and_resume(tmp_path):
    db = str(tmp_path / "station.db")

    async def story():
        async with guided_bench(db, seed=5, average_s=1.0, settle_s=0.5) as bench:
            app, pilot, src = bench.app, bench.pilot, bench.src
            g = app.screen.guide
            await bench.run(lambda: g.n_captured == 1)  # x_up: the unit starts there
            await pilot.press("s")  # skip x_down
            await wait_for(pilot, lambda: g.steps[1].status == "skipped")
            assert g.step.name == "y_up"
            src.place("y_up")
            await bench.run(lambda: g.steps[2].status == "captured")
            steps = app.screen.query_one("#steps")
            await wait_for(pilot, lambda: "✓" in str(steps.get_option_at_index(2).prompt))
            await pilot.press("a")  # abort asks first; n keeps the run
            await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
            await pilot.press("n")
            await wait_for(pilot, lambda: screen_name(app) == "ProcedureScreen")
            assert g.phase != "aborted"
            resume = await abort_to_resume(pilot, app)
            assert "2/12" in str(resume.label)
            await pilot.press("f6")
            await wait_for(pilot, lambda: screen_name(app) == "ProcedureScreen" and app.screen.guide is not None)
            g2 = app.screen.guide
            assert g2 is not g and g2.n_captured == 2
            assert [s.status for s in g2.steps[:3]] == ["captured", "skipped", "captured"]
            assert g2.step.name == "y_down"

    asyncio.run(story())


def test_a_damaged_resume_file_is_said_on_screen_not_a_crash(tmp_path):
    """A resume file whose index points beyond its steps (edited, damaged) took F6 into the
    procedure screen and crashed the TUI at the first live update (IndexError, a traceback
    in the terminal). The screen says what is wrong with the file; Start begins anew."""
    from station.procedures.state import default_state_path
    from station.procedures.tabletop_guide import GuideConfig, P1Guide

    db = str(tmp_path / "station.db")
    src = SimSource(seed=5, clock=BenchClock())
    path = default_state_path(src.device_id, base=str(tmp_path))
    guide = P1Guide(sample_rate_hz=100.0, accel_unit="V", device_id=src.device_id, config=GuideConfig())
    state = guide.to_state()
    state["index"] = 999
    # a run with something to resume (nothing captured: not offered)
    state["steps"][0].update(status="captured", mean=[1.0, 0.0, 0.0], std=[0.001] * 3, n=100, t_s=1.0, t0_s=0.0)
    with open(path, "w", encoding="utf-8") as fh:
        json.dump(state, fh)

    async def story():
        app = make_app(db, device=src, start="connect", average_s=1.0, settle_s=0.5)
        async with app.run_test(size=SIZE) as pilot:
            resume = app.screen.query_one("#resume")
            await wait_for(pilot, lambda: not resume.disabled)
            await pilot.press("f6")
            await wait_for(pilot, lambda: screen_name(app) == "ProcedureScreen")
            message = app.screen.query_one("#message")
            await wait_for(pilot, lambda: "resume state: index 999" in str(message.render()))
            await pilot.pause(0.5)
            assert app.is_running and screen_name(app) == "ProcedureScreen"

    asyncio.run(story())


def test_results_compare_with_the_previous_calibration_and_export(tmp_path):
    """A device with history and a tolerance on B: the new result shows Δ/σ and pass/fail."""
    from station.capture import read_capture
    from station.screens.results import ResultsScreen

    db = str(tmp_path / "station.db")
    seed_history(db, "IMU-7", n=1, tolerances={"B": 0.1})  # B may move 0.1 m/s² between calibrations
    from db.store import Store

    previous = Store(db).history("IMU-7")[-1]
    cap, result = p1_result("IMU-7", drift=0.5)  # B moved 0.5 m/s²

    async def story():
        app = make_app(db, device_id="IMU-7")
        app.session.extra["export_dir"] = str(tmp_path)
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, previous))
            await wait_for(pilot, lambda: app.screen.query_one("#params").row_count > 0)
            summary = text_of(app, "#summary")
            table = app.screen.query_one("#params")
            row = table.get_row_at(0)  # B[0]
            await pilot.press("e")
            await wait_for(pilot, lambda: getattr(app.screen, "exported", None))
            paths = app.screen.exported
            # the operator is told where the files are, not only their names
            await wait_for(pilot, lambda: any(f"in {tmp_path}" in n.message for n in app._notifications))
            await pilot.press("d")
            await wait_for(pilot, lambda: "Discarded" in text_of(app, "#saved"))
            saved = text_of(app, "#saved")
        return summary, row, paths, saved

    summary, row, paths, saved = asyncio.run(story())
    assert "FAIL" in summary and f"previous #{previous['id']}" in summary
    assert row[0] == "B[0]" and row[3] == "m/s^2" and row[4] == "✗"  # ok beside the unit
    b_new, b_old = result["params"]["B"][0], previous["params"]["B"][0]
    s2 = result["uncertainty"]["B"][0] ** 2 + previous["uncertainty"]["B"][0] ** 2
    assert float(row[6]) == pytest.approx((b_new - b_old) / np.sqrt(s2), abs=0.051)
    assert row[6] == "+88.4"  # 0.5 / sqrt(2 * 0.004²)
    assert "Discarded" in saved
    back = read_capture(paths[0])
    np.testing.assert_array_equal(back.columns["ax"], cap.columns["ax"])
    assert json.load(open(paths[1]))["procedure"] == "accel-tabletop"
    assert len(Store(db).history("IMU-7")) == 1  # discarded: not stored


def test_review_verdicts():
    from station.procedures.review import p1_residuals, param_rows, verdict

    cap, old = p1_result(drift=0.0)
    _, new = p1_result(drift=0.05)
    rows = param_rows(new, old, {"B": 0.1, "residual_rms": 0.001})
    assert verdict(rows, new, {"B": 0.1, "residual_rms": 0.001}) == ("pass", [])
    word, why = verdict(param_rows(new, old, {"B[2]": 0.01}), new, {"B[2]": 0.01})
    assert word == "fail" and why[0].startswith("B[2] changed +0.05")
    assert verdict(param_rows(new, None, {"B": 0.1}), new, {"B": 0.1})[0] == "no tolerance"
    res = dict((n, r) for n, _, r in p1_residuals(cap, old))
    assert abs(res["z_up"]) < 1e-9 and abs(res["x_up"]) > 1e-4  # the planted misfit on x_up


# ---------------------------------------------------------------- History, due reminders


def test_history_lists_devices_calibrations_and_drift(tmp_path):
    db = str(tmp_path / "station.db")
    seed_history(db, "IMU-7", n=3, interval_days=365, start_year=2022)

    async def story():
        app = make_app(db, start="history")
        async with app.run_test(size=(120, 40)) as pilot:
            await history_shown(pilot, app, 3)
            await wait_for(pilot, lambda: len(app.screen.drift) > 1)  # 'p' needs the drift loaded
            devices = app.screen.query_one("#devices")
            first = devices.get_row_at(0)
            p0 = app.screen.param_index
            await pilot.press("p")
            p1 = app.screen.param_index
            # the due line and the start-up reminder come from two workers: wait for both
            await wait_for(pilot, lambda: "IMU-7: overdue" in text_of(app, "#due"))
            await wait_for(pilot, lambda: any("overdue: IMU-7" in n.message for n in app._notifications))
            due = text_of(app, "#due")
            notes = [n.message for n in app._notifications]
        return first, p0, p1, due, notes

    first, p0, p1, due, notes = asyncio.run(story())
    assert first[0] == "IMU-7" and first[1] == "3"
    assert first[2] == "overdue"  # last calibration 2024-03-01 + 365 d is long past
    assert (p0, p1) == (0, 1)
    assert "IMU-7: overdue" in due
    assert any("overdue: IMU-7" in n for n in notes)  # the start-up reminder


def test_diagnose_a_stored_calibration_from_history(tmp_path):
    db = str(tmp_path / "station.db")
    seed_history(db, "IMU-7", n=2)

    async def story():
        app = make_app(db, start="history")
        async with app.run_test(size=SIZE) as pilot:
            await history_shown(pilot, app, 2)
            await pilot.press("g")  # the newest calibration is under the cursor
            await wait_for(pilot, lambda: screen_name(app) == "DiagnoseScreen" and app.screen.report is not None)
            title, report = screen_lines(app)[0], app.screen.report
            await pilot.press("escape")
            await wait_for(pilot, lambda: screen_name(app) == "HistoryScreen")
            back = screen_name(app)
        return title, report, back

    title, report, back = asyncio.run(story())
    assert "diagnose calibration #2" in title
    # the fixture's table is the model's own output (with one planted 2e-5 V misfit): no effect
    assert "procedure   accel-tabletop" in report and "verdict     none" in report
    assert back == "HistoryScreen"


def test_import_an_ldv_file_with_its_conditioning_check(tmp_path):
    """P5 comes as a file: a well-turned run calibrates; a straight run is refused in one line."""
    from solvers.simulate import simulate
    from station.capture import Capture, write_capture

    good, bad = str(tmp_path / "ldv.csv"), str(tmp_path / "straight.csv")
    for path, opts in ((good, {}), (bad, {"maneuver": "straight"})):
        sim = simulate("ldv", seed=1, **opts)
        write_capture(path, Capture(meta=sim.meta, columns=sim.columns))

    async def story():
        app = make_app(None)
        out = {}
        async with app.run_test(size=SIZE) as pilot:
            await pilot.press("f7")
            await wait_for(pilot, lambda: screen_name(app) == "ImportScreen")
            for path, key in ((str(tmp_path / "missing.csv"), "missing"), (bad, "bad")):
                app.screen.query_one("#path").value = path
                await pilot.press("enter")
                await wait_for(
                    pilot,
                    lambda: (
                        "[" not in text_of(app, "#status")
                        and "…" not in text_of(app, "#status")
                        and text_of(app, "#status").strip() != ""
                    ),
                )
                out[key] = words_of(app, "#status")
            app.screen.query_one("#path").value = good
            await pilot.press("enter")
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen")
            # the summary is drawn once the device's record is read (a worker): wait for it
            await wait_for(pilot, lambda: "cond(HᵀH) =" in text_of(app, "#summary"))
            out["title"] = screen_lines(app)[0]
            out["summary"] = words_of(app, "#summary")
            table = app.screen.query_one("#params")
            out["cond"] = next(
                table.get_row_at(i) for i in range(table.row_count) if table.get_row_at(i)[0] == "condition_number"
            )
        return out

    out = asyncio.run(story())
    # the condition number is a figure of the run, not an estimate: no "± 0" beside it
    assert str(out.pop("cond")[2]) == "—"
    squeeze = {k: v.replace(" ", "") for k, v in out.items()}  # long tmp paths wrap on screen
    assert "missing.csv:nosuchfile" in squeeze["missing"]
    assert "ill-conditioned" in squeeze["bad"] and "straight.csv" in squeeze["bad"]
    assert "P5 LDV result" in out["title"] and "cond(HᵀH) =" in out["summary"]


# ---------------------------------------------------------------- a serial device on a real pty


def test_procedure_reads_the_simulated_device_over_a_real_pty():
    from station.sources import SerialSource

    # a 30 s buffer (as the clean read-back tests of `station record` give theirs): on a loaded
    # machine the app may not read for half a second, and the device must not drop then
    with simulated_device_on_a_pty(seed=6, rate_hz=200, buffer_s=30.0) as (dev, path):

        async def story():
            app = make_app(None, device=SerialSource(path))
            async with app.run_test(size=SIZE) as pilot:
                assert app.screen.query_one("#source").value == "other"
                await pilot.press("f5")
                await wait_for(
                    pilot,
                    lambda: (
                        screen_name(app) == "ProcedureScreen"
                        and app.screen.last_status is not None
                        and app.screen.last_status.n_captured >= 0
                        and app.screen.updates > 10
                    ),
                )
                await wait_for(pilot, lambda: not app.screen.last_status.calibrating)
                readouts = text_of(app, "#readouts")
                st = app.screen.last_status
                src = app.session.source
            src.stop()
            return readouts, st, src

        readouts, st, src = asyncio.run(story())
    assert src.device_id == "SIM-ACC-0006"
    import re

    rate = float(re.search(r"(\d+) Hz", readouts).group(1))
    assert rate > 50  # estimated from host arrival times: loose on a loaded machine
    assert src.rate_hz == 200.0  # from the device's header
    # nothing dropped, nothing cut: the device discarded no output (its buffer outlasts any
    # stall of the app), the reader saw every sequence number and no broken sentence
    errors = int(re.search(r"errors (\d+)", readouts).group(1))
    dropped = int(re.search(r"dropped (\d+)", readouts).group(1))
    assert dev.stats.dropped == 0 and dev.stats.samples > 0, dev.stats
    assert (errors, dropped) == (0, 0), readouts
    assert src.reader.stats().gaps == 0 and src.reader.stats().dropped == 0, src.reader.stats()
    assert st.angle_deg < 5  # sim-device nominal: x_up from the start


def test_a_serial_device_gets_the_benchs_site_and_the_station_remembers_it(tmp_path):
    """A device on a port does not know where it is: `--site` gives the bench's place (for
    P1's gravity, P4's Earth rate, P3's IGRF), it is remembered in the database, and the
    next session on a serial device gets it without the option."""
    from db.store import Store
    from station.sources import SerialSource, parse_site

    db = str(tmp_path / "station.db")
    sites = []
    with simulated_device_on_a_pty(seed=7, rate_hz=100) as (_, path):
        for given in (parse_site("39.98, 116.35, 52"), None):

            async def story(given=given):
                app = make_app(db, device=SerialSource(path))
                if given is not None:
                    app.session.extra["site"] = given
                async with app.run_test(size=SIZE) as pilot:
                    await pilot.press("f5")
                    await wait_for(pilot, lambda: screen_name(app) == "ProcedureScreen")
                    src = app.session.source
                    sites.append(dict(src.site))
                src.stop()

            asyncio.run(story())
    want = {"latitude_deg": 39.98, "longitude_deg": 116.35, "altitude_m": 52.0}
    assert sites == [want, want]
    assert Store(db).settings()["site"] == "39.98, 116.35, 52"


@pytest.mark.parametrize("site", ["91,0", "40", "north,east", "40,10,nan"])
def test_a_bad_site_is_one_line_and_exit_2(site, capsys):
    from station.cli import main

    assert main(["tui", "--site", site]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--site" in err


# ---------------------------------------------------------------- the commands


def test_headless_demo_saves_a_p1(tmp_path, capsys):
    from station.cli import main

    db = str(tmp_path / "station.db")
    assert main(["demo", "--headless", "--db", db]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert sum("captured" in line for line in lines) == 12
    assert any("wrong face up at y_down" in line for line in lines)  # the scripted mistake, caught
    assert lines[-1] == f"saved as calibration #1 in {db}"


@pytest.mark.parametrize(
    "argv", [["demo", "--average-s", "0"], ["demo", "--speed", "-1"], ["tui", "--average-s", "-3"]]
)
def test_bad_options_are_one_line_and_exit_2(argv, capsys):
    from station.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "positive" in err


def test_history_l_views_and_edits_a_devices_limits(tmp_path):
    """`l` on History: the device's limits with their units and the value in use; a bad
    entry is one line and stores nothing; a good one is stored through the store (the
    CLI's `devices show` reads it, `verify` passes); `NAME=` removes one."""
    from db.store import Store
    from station.cli import main

    db = str(tmp_path / "station.db")
    seed_history(db, "IMU-7", n=2)
    Store(db).add_device("IMU-7", limits={"B": (-0.5, 0.5)})
    in_use = Store(db).history("IMU-7")[-1]["params"]["M"][0][0]

    async def story():
        app = make_app(db, start="history")
        async with app.run_test(size=SIZE) as pilot:
            await history_shown(pilot, app, 2)
            assert "l Limits" in screen_lines(app)[-1]
            await pilot.press("l")
            await wait_for(pilot, lambda: screen_name(app) == "LimitsScreen" and "-0.5" in text_of(app, "#current"))
            shown = text_of(app, "#current")
            params = text_of(app, "#params")
            await pilot.press(*"M[0][0]=2:1", "enter")
            await wait_for(pilot, lambda: "expected NAME=LOW:HIGH" in text_of(app, "#error"))
            bad = text_of(app, "#error")
            low = round(in_use, 3) + 0.01  # a limit the calibration in use is outside of
            await pilot.press(*["backspace"] * 11, *f"M[0][0]={low}:", "enter")
            await wait_for(pilot, lambda: "M[0][0]" in text_of(app, "#current"))
            after = text_of(app, "#current")
            await pilot.press(*"B=", "enter")
            await wait_for(pilot, lambda: "B " not in text_of(app, "#current").replace("B[", ""))
            final = text_of(app, "#current")
            await pilot.press("escape")
            await wait_for(pilot, lambda: screen_name(app) == "HistoryScreen")
        return shown, params, bad, after, final, low

    shown, params, bad, after, final, low = asyncio.run(story())
    assert "B" in shown and "-0.5 … 0.5" in shown and "m/s" in shown
    assert "P1: B, M" in params
    assert "'M[0][0]=2:1'" in bad
    assert f"{low:g} …" in after and "OUTSIDE" in after and "in use" in after
    assert "M[0][0]" in final and "-0.5" not in final
    assert Store(db).get_device("IMU-7")["limits"] == {"M[0][0]": [low, None]}
    assert main(["verify", "--db", db]) == 0


def test_history_l_shows_a_block_limit_against_every_value_in_use(tmp_path):
    """A block limit (`B`, P4's `drift`) applies to each of its elements: the box showed no
    value in use and no OUTSIDE for it, so a limit every calibration in use broke looked met."""
    from db.store import Store

    db = str(tmp_path / "station.db")
    seed_history(db, "IMU-7", n=2)
    b = Store(db).history("IMU-7")[-1]["params"]["B"]
    low, high = min(b), max(b)
    Store(db).add_device("IMU-7", limits={"B": (low, high), "M": (-100.0, 100.0)})

    async def story():
        app = make_app(db, start="history")
        async with app.run_test(size=SIZE) as pilot:
            await history_shown(pilot, app, 2)
            await pilot.press("l")
            await wait_for(pilot, lambda: screen_name(app) == "LimitsScreen" and "in use" in text_of(app, "#current"))
            inside = text_of(app, "#current").splitlines()
            await pilot.press(*f"B={(low + high) / 2}:", "enter")  # the lower elements now outside
            await wait_for(pilot, lambda: "OUTSIDE" in text_of(app, "#current"))
            outside = text_of(app, "#current").splitlines()
        return inside, outside

    def entry(lines, name):  # a limit's line and its continuation (the value in use when it does not fit beside)
        k = next(i for i, line in enumerate(lines) if line.startswith(name + " "))
        more = lines[k + 1] if k + 1 < len(lines) and lines[k + 1].startswith("             ") else ""
        return " ".join((lines[k] + " " + more).split())

    inside, outside = asyncio.run(story())
    assert f"in use {low:.6g} … {high:.6g}" in entry(inside, "B") and "OUTSIDE" not in " ".join(inside)
    # whole at 80x24: the values in use and OUTSIDE are not cut off at the box's edge
    assert entry(outside, "B").endswith(f"in use {low:.6g} … {high:.6g} OUTSIDE")
    assert "in use" in entry(outside, "M") and "OUTSIDE" not in entry(outside, "M")


def test_a_port_typed_while_source_is_simulated_is_the_port_used(tmp_path):
    """Typing a port with Source left at "Built-in simulated device" and pressing Enter
    silently ran the simulator. The typed port is what the bench engineer means: Source
    switches to Other as it is typed, and the run reads that port (a real pty); choosing
    the simulator again with the port still typed is refused with the reason."""

    with simulated_device_on_a_pty(seed=7, rate_hz=200) as (_, path):

        async def story():
            app = make_app(None)
            async with app.run_test(size=SIZE) as pilot:
                await pilot.click("#port")
                # typed: all but the last key put in at once (each key pressed waits up to 2 s for
                # an app kept busy by the device's stream), the last one pressed
                app.screen.query_one("#port").insert_text_at_cursor(path[:-1])
                await pilot.press(path[-1])
                assert app.screen.query_one("#port").value == path
                assert app.screen.query_one("#source").value == "other"
                app.screen.query_one("#source").value = "sim"  # the simulator chosen again
                await pilot.press("f5")
                await wait_for(pilot, lambda: "clear the port" in text_of(app, "#status"))
                refused = words_of(app, "#status")
                assert screen_name(app) == "ConnectScreen" and app.session.source is None
                # the port as typed above (Source follows it); typed again key by key, each key
                # waited up to 2 s for an app kept busy by the device's stream (pilot's idle wait)
                port = app.screen.query_one("#port")
                port.value = ""
                port.value = path
                port.focus()
                await pilot.press("enter")
                await wait_for(pilot, lambda: screen_name(app) == "ProcedureScreen")
                src = app.session.source
                kind, port = src.kind, getattr(src, "port", None)
                await wait_for(pilot, lambda: app.screen.updates > 3)
                src.stop()
                return refused, kind, port

        refused, kind, port = asyncio.run(story())
    assert kind == "serial" and port == path
    assert path in refused and "simulated" in refused


def test_a_device_that_sends_nothing_is_said_on_the_procedure_screen():
    """A port where nothing answers (wrong port, baud rate or protocol; the unit unpowered):
    P1 showed dashes, "Hold the unit still: measuring the sensor noise" and "t=nan s" for ever,
    nothing saying the device was silent. Now a notice names the port within 5 s and says
    what to check, and the time reads "t=— s" until a sample comes."""
    import os

    from station.sources import SerialSource

    master, slave = os.openpty()  # a real pty whose other end never writes
    try:
        path = os.ttyname(slave)

        async def story():
            app = make_app(None, device=SerialSource(path, header_timeout_s=0.5))
            async with app.run_test(size=SIZE, notifications=True) as pilot:
                await pilot.press("f5")
                await wait_for(pilot, lambda: screen_name(app) == "ProcedureScreen" and app.screen.updates > 2)
                progress = text_of(app, "#progress")
                await wait_for(pilot, lambda: "no data from" in "\n".join(screen_lines(app)), timeout_s=20.0)
                lines = "\n".join(screen_lines(app))
            app.session.source.stop()
            return progress, lines

        progress, lines = asyncio.run(story())
    finally:
        os.close(master)
        os.close(slave)
    assert "t=— s" in progress and "nan" not in progress, progress
    flat = " ".join(lines.split())
    assert f"no data from {path}" in flat and "baud rate" in flat, lines


def test_headless_demo_run_twice_says_it_is_saved_already(tmp_path, capsys):
    """`station demo --headless` runs on a simulated clock: the same seed gives the same capture,
    sample for sample. A second run (a script that runs it again) ended in "cannot process this
    input (DuplicateCapture ...)" and exit 2; it says which calibration holds that run, exit 0,
    and stores nothing twice."""
    from db.store import Store
    from station.cli import main

    db = str(tmp_path / "station.db")
    assert main(["demo", "--headless", "--db", db]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == f"saved as calibration #1 in {db}"
    assert main(["demo", "--headless", "--db", db]) == 0
    out, err = capsys.readouterr()
    assert out.splitlines()[-1] == (
        f"already saved as calibration #1 in {db}: the same --seed runs the same demo (--seed N for another)"
    )
    assert err == ""
    assert len(Store(db).history("SIM-ACC-0000")) == 1
