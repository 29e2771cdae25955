"""What a bench engineer new to the station met on the TUI at 80x24 (real app under its
pilot, the built-in simulated device on a clock the test advances)."""

from __future__ import annotations

import asyncio

from station.app import make_app
from tests.test_tui import SIZE, guided_bench, start_on_sim, text_of, wait_for, words_of


def test_p1_quarter_turn_prompt_is_shown_whole_at_80x24():
    """Asked for x_up with the unit on y_up, the prompt was cut at the panel's edge:
    "Wrong face up: 90° off, a quarter turn; put the face" (the rest, "shown up", lost)."""

    async def story():
        async with guided_bench(seed=1, average_s=60.0) as bench:
            app, pilot = bench.app, bench.pilot
            bench.src.place("y_up")  # asked for x_up: a quarter turn off
            await bench.run(lambda: "quarter turn" in app.screen.guide.status().message)
            await wait_for(pilot, lambda: "quarter turn" in text_of(app, "#message"))
            # the clock is stopped: the prompt settles; what is drawn must be all of it
            shown = lambda: words_of(app, "#message")  # noqa: E731
            try:
                await wait_for(pilot, lambda: shown() == app.screen.guide.status().message, timeout_s=10)
            except AssertionError:
                raise AssertionError((shown(), app.screen.guide.status().message)) from None

    asyncio.run(story())


def test_rejecting_a_passing_result_offers_no_override_key(tmp_path):
    """`x` on a result that passed opened the decision box with `^o Accept (override)` in the
    footer: the key did nothing there (only a FAIL can be accepted as an override), and the
    box asked for "a note saying why it is accepted anyway". Now the footer and the box show
    only what the keys do: a reason, ctrl+r, esc."""
    from station.screens.results import ResultsScreen
    from tests.test_tui import screen_lines, screen_name
    from tests.tui_data import p1_result

    cap, result = p1_result("IMU-9")

    async def story():
        app = make_app(str(tmp_path / "s.db"), device_id="IMU-9")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(pilot, lambda: app.screen.query_one("#params").row_count > 0)
            assert "FAIL" not in text_of(app, "#summary")
            await pilot.press("x")
            await wait_for(pilot, lambda: screen_name(app) == "DecideScreen")
            await pilot.pause(0.2)
            return screen_lines(app)

    lines = asyncio.run(story())
    screen = "\n".join(lines)
    assert "override" not in lines[-1].lower(), lines[-1]  # the footer
    assert "accepted anyway" not in screen and "override" not in screen.lower(), screen
    assert "ctrl+r" in screen and "^r" in lines[-1]


def test_importing_a_plain_csv_says_how_from_the_screen(tmp_path):
    """A bench CSV (columns time_ms, acc_x, ...) typed on the import screen (F7) was refused
    with the command line's hint "say which is which with --map, e.g. --map t=time,...": an
    option the screen has nowhere to type. Now the screen says the route that works: make a
    capture with `station import ... --map ... --out CAPTURE`, then import that capture."""
    from tests.test_tui_import import _open

    src = tmp_path / "bench.csv"
    src.write_text("time_ms,acc_x,acc_y,acc_z\n" + "".join(f"{10 * i},0.0,0.0,9.81\n" for i in range(50)))

    async def story():
        app = make_app(str(tmp_path / "s.db"))
        async with app.run_test(size=SIZE) as pilot:
            await _open(pilot, app, src)
            return text_of(app, "#status")

    status = " ".join(asyncio.run(story()).split())
    assert "bench.csv" in "".join(status.split()), status  # the path may wrap anywhere
    assert "station import" in status and "--out" in status, status
    assert "then import" in status, status


def test_a_capture_that_names_no_device_is_not_saved_under_the_last_device(tmp_path):
    """A station capture without a `# device:` line (a CSV imported without --device), opened
    with F7 after a run on another unit: `s` saved it under that unit (the session's last
    device, here a P5 LDV), judged against that unit's limits, with only a warning afterwards
    that the kinds differ. Now Results say the capture names no device and nothing is saved."""
    from db.store import Store
    from solvers.simulate import simulate
    from station.capture import write_capture
    from tests.station_run import capture_of, run_station
    from tests.test_tui import screen_name

    db = tmp_path / "s.db"
    assert run_station("--db", db, "devices", "add", "LDV-7", "--kind", "ldv").returncode == 0
    cap = capture_of(simulate("gyro-drift", seed=5))
    del cap.meta["device"]
    path = tmp_path / "still.csv"
    write_capture(str(path), cap)

    async def story():
        app = make_app(str(db), device_id="LDV-7")
        async with app.run_test(size=SIZE) as pilot:
            await pilot.press("f7")
            await wait_for(pilot, lambda: screen_name(app) == "ImportScreen")
            app.screen.query_one("#path").value = str(path)
            await pilot.press("enter")
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen", timeout_s=60)
            await wait_for(pilot, lambda: app.screen.device is not None)
            await pilot.press("s")
            await wait_for(pilot, lambda: "no device" in words_of(app, "#saved"), timeout_s=20)
            return words_of(app, "#saved"), app.screen.calibration_id

    saved, cal_id = asyncio.run(story())
    assert cal_id is None and "--device" in saved, saved
    with Store(str(db)) as s:
        assert s.history("LDV-7") == []


def test_resume_follows_the_procedure_picked_and_f6_is_shown_only_when_it_resumes(tmp_path):
    """Resume continues an interrupted P1. With P2 picked the button still said `Resume 3/12`
    (P1's run) and F6 started a new P2; with nothing to resume `f6 Resume` stayed in the
    footer and the key did nothing. Now the button and the key follow the procedure picked."""
    import json

    from station.procedures.state import default_state_path
    from tests.test_tui import screen_lines, screen_name

    steps = [{"status": "captured"}] * 3 + [{"status": "pending"}] * 9
    with open(default_state_path("IMU-5", base=str(tmp_path)), "w", encoding="utf-8") as fh:
        json.dump({"phase": "guide", "steps": steps}, fh)

    def footer(app) -> str:
        return screen_lines(app)[-1]

    async def story():
        app = make_app(str(tmp_path / "s.db"))
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")
            await wait_for(pilot, lambda: "f5" in footer(app))
            assert "f6" not in footer(app), footer(app)  # nothing to resume for the simulator's unit
            app.screen.query_one("#serial").value = "IMU-5"
            await wait_for(pilot, lambda: not app.screen.query_one("#resume").disabled)
            await wait_for(pilot, lambda: "f6" in footer(app))
            app.screen.query_one("#procedure").value = "accel-centrifuge"
            await wait_for(pilot, lambda: app.screen.query_one("#resume").disabled)
            await wait_for(pilot, lambda: "f6" not in footer(app))
            assert not any("3/12" in line for line in screen_lines(app))
            await pilot.press("f6")
            await pilot.pause(0.3)
            assert screen_name(app) == "ConnectScreen"
            app.screen.query_one("#procedure").value = "accel-tabletop"
            await wait_for(pilot, lambda: not app.screen.query_one("#resume").disabled)
            await wait_for(pilot, lambda: any("Resume 3/12 [F6]" in line for line in screen_lines(app)))

    asyncio.run(story())


def test_a_run_aborted_before_its_first_position_is_not_offered_for_resume(tmp_path):
    """P1 aborted with no position captured leaves its state file; Connect offered `Resume 0/12`,
    which would only start the same run again. Nothing captured: no Resume, no F6."""
    import json

    from station.procedures.state import default_state_path
    from tests.test_tui import screen_lines, screen_name

    path = default_state_path("IMU-5", base=str(tmp_path))

    def write(n_captured):
        steps = [{"status": "captured"}] * n_captured + [{"status": "pending"}] * (12 - n_captured)
        with open(path, "w", encoding="utf-8") as fh:
            json.dump({"phase": "guide", "steps": steps}, fh)

    async def story():
        write(1)  # one position captured: offered (the control for what follows)
        app = make_app(str(tmp_path / "s.db"))
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")
            app.screen.query_one("#serial").value = "IMU-5"
            await wait_for(pilot, lambda: any("Resume 1/12 [F6]" in line for line in screen_lines(app)))
            write(0)
            app.screen.query_one("#serial").value = "IMU-6"
            app.screen.query_one("#serial").value = "IMU-5"
            await wait_for(pilot, lambda: app.screen.query_one("#resume").disabled)
            await wait_for(pilot, lambda: "f6" not in screen_lines(app)[-1])
            assert not any("0/12" in line for line in screen_lines(app)), screen_lines(app)

    asyncio.run(story())


def test_a_device_lost_mid_run_is_said_on_the_procedure_screen():
    """The device on a port stops mid-run (unplugged; here its pty closed): P4 kept saying
    "Recording: keep the unit still" over a countdown stopped at 2:55, with only DISCONNECTED
    at the end of a readout line. The notice a silent port gets ("no data from PORT ...")
    was said only for a port silent from the start. Now also once the data stop."""
    import threading

    from solvers.simulate import LiveImu
    from station.device.simdevice import SimDevice
    from station.sources import SerialSource
    from tests.test_tui import screen_lines, screen_name

    dev = SimDevice(LiveImu(seed=7, rate_hz=100, hold_s=1e9))
    path = dev.open()
    stop = threading.Event()
    thread = threading.Thread(target=dev.run, args=(stop,), daemon=True)
    thread.start()
    try:

        async def story():
            app = make_app(None, device=SerialSource(path), average_s=180.0)
            app.session.procedure = "gyro-drift"  # P4 on a static base, as picked on Connect
            async with app.run_test(size=SIZE, notifications=True) as pilot:
                await pilot.press("f5")
                await wait_for(pilot, lambda: screen_name(app) == "HoldScreen" and app.screen.updates > 5)
                await wait_for(pilot, lambda: app.session.source.stats().samples > 50)
                assert "no data from" not in "\n".join(screen_lines(app))
                stop.set()  # the device goes away
                thread.join(10)
                dev.close()
                await wait_for(pilot, lambda: "no data from" in "\n".join(screen_lines(app)), timeout_s=30.0)
                lines = "\n".join(screen_lines(app))
            app.session.source.stop()
            return lines

        lines = asyncio.run(story())
    finally:
        stop.set()
        thread.join(10)
        dev.close()
    flat = " ".join(lines.replace("▌", " ").split())  # a toast's edge on each of its lines
    assert f"no data from {path}" in flat and "since its last sample" in flat and "check the cable" in flat, lines


def test_the_noise_run_has_the_p4_hold_layout_when_it_is_the_first_run(tmp_path):
    """The gyro noise run, picked first after start-up: its screen (a P4 hold screen with its
    own words) had none of the hold screen's layout (no margins, the readouts at the bottom
    rows), so the start-up reminder's toast lay over the live rates ("z +98▌ never
    calibrated"). The layout came only once a P4 hold screen had been shown in the session."""
    from tests.test_tui import screen_name

    async def story():
        app = make_app(str(tmp_path / "s.db"))
        app.session.procedure = "gyro-noise"
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")
            await pilot.press("f5")
            await wait_for(pilot, lambda: screen_name(app) == "NoiseHoldScreen" and app.screen.updates > 2)
            await pilot.pause(0.3)
            return app.screen.query_one("#readouts").region, app.screen.query_one("#body").region

    readouts, body = asyncio.run(story())
    assert readouts.x == 1, readouts  # the hold screen's margin
    assert readouts.bottom <= 14, readouts  # under the instruction and the bars, not at the foot


def test_quitting_p1_with_captured_positions_says_they_are_kept_for_resume(tmp_path):
    """ctrl+q on P1 with positions captured asked "Quit? The run in progress is lost.", while
    the captured positions were kept in the resume file and F6 continued them after a restart:
    an operator told hours of holds are lost answers no, or re-does them. Now it says what is
    lost (the position being averaged) and what is kept; with none captured it is unchanged."""
    import os

    from tests.test_tui import screen_name

    async def story():
        async with guided_bench(str(tmp_path / "s.db"), seed=3, average_s=1.0, settle_s=0.5) as bench:
            app, pilot = bench.app, bench.pilot
            guide = app.screen.guide
            await pilot.press("ctrl+q")
            await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
            before = app.screen.question
            await pilot.press("n")
            await wait_for(pilot, lambda: screen_name(app) != "ConfirmScreen")
            await bench.run(lambda: guide.n_captured == 1)  # x_up: the unit starts there
            await wait_for(pilot, lambda: os.path.exists(guide.state_path))
            await pilot.press("ctrl+q")
            await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
            after = app.screen.question
            await pilot.press("n")
            return before, after, guide.state_path, guide.n_captured

    before, after, state_path, kept = asyncio.run(story())
    assert "The run in progress is lost" in before and "kept" not in before, before
    assert os.path.exists(state_path)
    assert "The run in progress is lost" not in after, after
    assert f"The {kept} captured position" in after and "kept" in after and "F6" in after, after


def test_a_device_due_later_is_not_called_due_on_history_or_connect(tmp_path):
    """History lists what falls due within 30 days, the Connect screen within 7, and both said
    "due" of a device whose interval ends weeks ahead ("IMU-8: due — ... ends 2026-12-21")
    while `station due` said "nothing due" of the same database, exit 0. They now say when, as
    `station due --within` does ("due in 20 d (DATE)"; the 7-wide status column "in 20 d");
    "due" alone is left for a device due today."""
    import datetime as dt

    from db.store import Store
    from station.store import save_result
    from tests.station_run import run_station
    from tests.test_tui import screen_name
    from tests.tui_data import p1_result

    db = str(tmp_path / "s.db")
    # to the second: a calibration dated at midnight leaves 19.5 days at noon, which rounds to 19
    ten_days_ago = (dt.datetime.now(dt.UTC) - dt.timedelta(days=10)).strftime("%Y-%m-%dT%H:%M:%SZ")
    for device, interval in (("IMU-8", 30), ("IMU-9", 15)):
        cap, result = p1_result(device, date=ten_days_ago)
        save_result(db, cap, result, device_id=device, operator="test")
        Store(db).add_device(device, interval_days=interval)
    res = run_station("due", "--db", db)
    assert res.returncode == 0 and "nothing due" in res.stdout, res.stdout  # the command line's word
    left = {d["device_id"]: round(d["days_left"]) for d in Store(db).due(within_days=30)}
    assert left == {"IMU-8": 20, "IMU-9": 5}, left

    async def story():
        app = make_app(db)
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen" and "IMU-9" in text_of(app, "#due"))
            connect = text_of(app, "#due")
            await pilot.press("f2")
            await wait_for(pilot, lambda: screen_name(app) == "HistoryScreen" and "IMU-8" in text_of(app, "#due"))
            await wait_for(pilot, lambda: "IMU-9" in text_of(app, "#devices"))
            return connect, text_of(app, "#due"), text_of(app, "#devices")

    connect, header, devices = asyncio.run(story())
    assert "IMU-9 due in 5 d" in " ".join(connect.split()), connect
    header = " ".join(header.split())
    assert "IMU-8: due in 20 d" in header and "IMU-9: due in 5 d" in header and ": due —" not in header, header
    rows = {d: line for line in devices.splitlines() for d in ("IMU-8", "IMU-9") if d in line}
    assert len(rows) == 2, devices
    assert "in 20 d" in rows["IMU-8"] and "in 5 d" in rows["IMU-9"], rows
    assert not any(" due" in row for row in rows.values()), rows


def test_history_says_when_the_device_falls_due_and_i_sets_its_interval(tmp_path):
    """A new unit calibrated on the TUI is registered without an interval, so it is never due;
    History called it "ok" and showed no due date anywhere (`station due` says "nothing due"
    and names it on stderr only), and no screen could set the interval. History now says the
    highlighted device's due date or that it is never due, and ``i`` sets the interval, stored
    as ``devices add --interval-days`` does (the CLI sees the same date)."""
    import datetime as dt

    from db.store import Store
    from station.store import save_result
    from tests.station_run import run_station
    from tests.test_tui import screen_name
    from tests.tui_data import p1_result

    db = str(tmp_path / "s.db")
    ten_days_ago = (dt.datetime.now(dt.UTC) - dt.timedelta(days=10)).strftime("%Y-%m-%dT%H:%M:%SZ")
    cap, result = p1_result("IMU-5", date=ten_days_ago)
    save_result(db, cap, result, device_id="IMU-5", operator="test")
    assert Store(db).get_device("IMU-5")["interval_days"] is None

    async def story():
        app = make_app(db, start="history")
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: screen_name(app) == "HistoryScreen" and "IMU-5" in text_of(app, "#devices"))
            await wait_for(pilot, lambda: "never due: no recalibration interval (i sets one)" in words_of(app), 30)
            before = text_of(app, "#devices")
            await pilot.press("i")
            await wait_for(pilot, lambda: screen_name(app) == "IntervalScreen" and "never due" in words_of(app))
            for key in "abc":
                await pilot.press(key)
            await pilot.press("enter")
            await wait_for(pilot, lambda: "not a number of days" in words_of(app))
            assert Store(db).get_device("IMU-5")["interval_days"] is None
            await pilot.press("backspace", "backspace", "backspace", "3", "0", "enter")
            await wait_for(pilot, lambda: screen_name(app) == "HistoryScreen" and "interval 30 d" in words_of(app))
            return before, words_of(app), text_of(app, "#devices")

    before, after, devices = asyncio.run(story())
    assert "no int" in before and " ok" not in before, before
    assert Store(db).get_device("IMU-5")["interval_days"] == 30
    assert "due in 20 d" in after and "interval 30 d" in after, after
    assert "in 20 d" in devices, devices
    res = run_station("due", "--within", "30", "--db", db)  # the command line gives the same date
    assert res.returncode == 1 and "IMU-5" in res.stdout, (res.stdout, res.stderr)


def test_the_noise_runs_p4_verdict_is_shown_whole_at_80x24(tmp_path):
    """The Allan result's verdict had two rows: "No still P4 record reaches 1σ ≤ 1 °/h on every
    axis: the fitted noise floor of x (bias instability, rate random walk) is above it; y alone
    needs 70 min, z" was all a noise run on the simulator showed, the rest ("alone needs 70
    min.") cut off. It now takes the rows it needs, the plot giving them."""
    import numpy as np

    from station.capture import read_capture
    from station.procedures.noise import noise_report, p4_record_verdict
    from station.screens.noise import AllanScreen
    from tests.station_run import run_station
    from tests.test_tui import screen_name

    cap_path = tmp_path / "still.csv"
    assert run_station("simulate", "--procedure", "gyro-drift", "--seed", 400003, "--out", cap_path).returncode == 0
    cap = read_capture(cap_path)
    gyro = np.column_stack([cap.columns[c] for c in ("gx", "gy", "gz")])
    report = noise_report(gyro, float(cap.meta["sample_rate_hz"]), cap.meta.get("gyro_unit"))
    accuracy = "4.6"  # on this record: x reaches it, y never does, z in 73 min
    verdict = p4_record_verdict(report.time_needed_s(float(accuracy)), float(accuracy))
    assert len(verdict) > 2 * 78, verdict  # more than two rows of the screen's 78 columns

    async def story():
        app = make_app(None)
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(AllanScreen(cap, report))
            await wait_for(pilot, lambda: screen_name(app) == "AllanScreen")
            # the screen takes the focus off the field once drawn: the keys are the footer's
            await wait_for(pilot, lambda: "P4 needs" in text_of(app, "#table") and app.screen.focused is None)
            await pilot.press("t")
            await wait_for(pilot, lambda: app.screen.focused is not None and app.screen.focused.id == "accuracy")
            await pilot.press(*["backspace"] * 6, *accuracy, "enter")
            await wait_for(pilot, lambda: f"≤ {accuracy} °/h" in text_of(app, "#status"))
            return words_of(app, "#status")

    assert asyncio.run(story()) == verdict


def test_the_compass_prompt_is_shown_whole_at_80x24():
    """P3's prompt line was one row of the 48 columns beside the coverage map: "Turn the unit
    slowly through every orientation" was all it showed of "... (all faces up, all headings)"."""
    from tests.test_tui import screen_name

    async def story():
        app = make_app(None)
        async with app.run_test(size=SIZE) as pilot:
            src, clock = await start_on_sim(
                pilot, app, "compass", 3, lambda: screen_name(app) == "CompassScreen" and app.screen.updates > 2
            )
            asked = app.screen.last_status.message
            assert "all faces up" in asked, asked
            shown = lambda: words_of(app, "#message")  # noqa: E731
            try:  # the clock is stopped: the prompt settles; what is drawn must be all of it
                await wait_for(pilot, lambda: shown() == asked, timeout_s=10)
            except AssertionError:
                raise AssertionError((shown(), asked)) from None

    asyncio.run(story())


def test_a_disagreeing_centrifuge_row_is_said_whole_at_80x24():
    """P2's message had two rows of 56 columns: a row that disagrees (here typed at another speed
    than asked) read "Entered 1 @ 6.28: DISAGREES (speed 9 rad/s, asked 6.283); r redoes it.
    Next: Mount in orientation 1, spin at" and lost where to spin next. It takes the rows it needs.
    With no table rate measured, the readout's second row "table rate (gyro) — rad/s  (no rate
    measured: asked 12.57)" was two columns too long and lost "12.57)"."""
    from tests.test_tui import screen_lines, screen_name

    async def story():
        app = make_app(None)
        async with app.run_test(size=SIZE) as pilot:
            src, clock = await start_on_sim(
                pilot,
                app,
                "accel-centrifuge",
                3,
                lambda: screen_name(app) == "CentrifugeScreen" and app.screen.guide is not None,
            )
            await pilot.press("m")
            await wait_for(pilot, lambda: app.screen.focused is not None and app.screen.focused.id == "in-ax")
            for name, value in (("ax", "1.1"), ("ay", "0.3"), ("az", "0.9"), ("speed", "9")):
                app.screen.query_one(f"#in-{name}").value = value
            app.screen.query_one("#in-speed").focus()
            await pilot.press("enter")
            await wait_for(pilot, lambda: "DISAGREES" in app.screen.guide.status().message)
            asked = " ".join(app.screen.guide.status().message.split())
            assert "r redoes it" in asked and "Next: Mount" in asked, asked
            shown = lambda: words_of(app, "#message")  # noqa: E731
            try:  # the clock is stopped: the message settles; what is drawn must be all of it
                await wait_for(pilot, lambda: shown() == asked, timeout_s=10)
            except AssertionError:
                raise AssertionError((shown(), asked, "\n".join(screen_lines(app)))) from None
            # no table rate yet (a triad without a gyro never has one): its line is whole too
            return text_of(app, "#readouts")

    readouts = asyncio.run(story())
    assert "table rate (gyro) — rad/s (not measured, asked 12.57)" in readouts, readouts


def test_why_p1_left_its_gyro_uncalibrated_is_said_whole(tmp_path):
    """A P1 capture whose t column contradicts its sample_rate_hz keeps its accelerometer
    result and leaves the gyro uncalibrated, saying why. Results cut the why at 60 characters:
    "gyro not calibrated: line 10: metadata 'sample_rate_hz': 100 Hz, but the t column", what
    to correct lost. Now the whole reason, as `station calibrate` says it."""
    from station.calibrate import calibrate_capture
    from station.capture import read_capture
    from station.screens.results import ResultsScreen
    from tests.station_run import run_station
    from tests.test_tui import screen_name

    path = tmp_path / "p1.csv"
    assert run_station("simulate", "--procedure", "accel-tabletop", "--seed", 1, "--out", path).returncode == 0
    lines = path.read_text().splitlines(keepends=True)
    head = next(i for i, line in enumerate(lines) if line.startswith("t,"))
    for i in range(head + 1, len(lines)):  # t in ms, sample_rate_hz still 100
        t, rest = lines[i].split(",", 1)
        lines[i] = f"{float(t) * 1000:g},{rest}"
    path.write_text("".join(lines))
    cap = read_capture(path)
    result = calibrate_capture(cap)
    why = result["gyro"]["error"]
    assert "correct sample_rate_hz or t" in why, why

    async def story():
        app = make_app(None)
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(
                pilot, lambda: screen_name(app) == "ResultsScreen" and "gyro not" in text_of(app, "#summary")
            )
            return words_of(app, "#summary")

    shown = asyncio.run(story())
    assert f"gyro not calibrated: {' '.join(why.split())}" in shown, shown


def test_history_says_when_devices_fall_due_in_a_row_each_and_why_beside_the_device(tmp_path):
    """Four devices overdue: History's header gave three of them two rows each (when, and why:
    "IMU-1: overdue — accel-tabletop: 365-day interval since 2024-03-01 ends / 2025-03-01; drift
    of B[0] ..."), the fourth not at all, and left the drift plot three rows at 80x24. Now one
    row each, the rest counted, and why over the highlighted device's calibrations."""
    from tests.test_tui import screen_name
    from tests.tui_data import seed_history

    db = str(tmp_path / "s.db")
    for device in ("IMU-1", "IMU-2", "IMU-3", "IMU-4"):
        seed_history(db, device, n=4, interval_days=365, tolerances={"B": 0.5}, start_year=2021)

    async def story():
        app = make_app(db, start="history")
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: screen_name(app) == "HistoryScreen" and "IMU-1:" in text_of(app, "#due"))
            await wait_for(pilot, lambda: "365-day interval" in text_of(app, "#next"))
            plot = app.screen.query_one("#plot").region.height
            return text_of(app, "#due"), words_of(app, "#next"), plot

    header, beside, plot_rows = asyncio.run(story())
    rows = [r.strip() for r in header.splitlines() if r.strip()]
    assert rows[:3] == [f"IMU-{k}: overdue by {rows[0].split('by ')[1]}" for k in (1, 2, 3)], rows
    assert rows[3].startswith("… and 1 more"), rows
    assert len(rows) == 4, rows
    assert beside.startswith("overdue by ") and "accel-tabletop: 365-day interval since 2024-03-01" in beside, beside
    assert plot_rows >= 8, plot_rows  # its minimum: the header no longer squeezes it


def test_new_run_asks_before_it_drops_an_unsaved_result(tmp_path):
    """`n` on Results went back to Connect at once, the result of the run gone unsaved (a
    quarter hour of P1), where ctrl+q asks first. It asks now; n keeps the result, y drops it;
    a saved result goes without a question."""
    from station.screens.results import ResultsScreen
    from tests.test_tui import screen_name
    from tests.tui_data import p1_result

    db = str(tmp_path / "s.db")
    cap, result = p1_result("IMU-3")

    async def story():
        app = make_app(db, device_id="IMU-3")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(
                pilot, lambda: screen_name(app) == "ResultsScreen" and app.screen.query_one("#params").row_count
            )
            await pilot.press("n")
            await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
            question = words_of(app, "#box")
            await pilot.press("n")  # no: the result stays
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen")
            await pilot.press("s")
            await wait_for(pilot, lambda: app.screen.calibration_id is not None)
            await pilot.press("n")  # saved: no question
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(
                pilot, lambda: screen_name(app) == "ResultsScreen" and app.screen.query_one("#params").row_count
            )
            await pilot.press("n")
            await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
            await pilot.press("y")  # yes: dropped
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")
            return question

    question = asyncio.run(story())
    assert "not saved" in question and "lost" in question, question


def test_new_run_asks_before_it_drops_an_unexported_noise_record(tmp_path):
    """The Allan result's `n` dropped the record at once: nothing stores a noise run, so a
    record of hours was gone on one key. It asks unless the record was exported (`e`). Back from
    a question (or Help) the accuracy field had the focus, so `e` was typed into it."""
    import os

    import numpy as np

    from station.capture import read_capture
    from station.procedures.noise import noise_report
    from station.screens.noise import AllanScreen
    from tests.station_run import run_station
    from tests.test_tui import screen_name

    cap_path = tmp_path / "still.csv"
    assert run_station("simulate", "--procedure", "gyro-drift", "--seed", 400003, "--out", cap_path).returncode == 0
    cap = read_capture(cap_path)
    gyro = np.column_stack([cap.columns[c] for c in ("gx", "gy", "gz")])
    report = noise_report(gyro, float(cap.meta["sample_rate_hz"]), cap.meta.get("gyro_unit"))
    out = tmp_path / "exports"
    os.makedirs(out)

    async def story():
        app = make_app(None)
        app.session.extra["export_dir"] = str(out)
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(AllanScreen(cap, report))
            await wait_for(pilot, lambda: "P4 needs" in text_of(app, "#table") and app.screen.focused is None)
            await pilot.press("n")
            await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
            question = words_of(app, "#box")
            await pilot.press("n")  # no: the record stays
            await wait_for(pilot, lambda: screen_name(app) == "AllanScreen")
            await pilot.press("e")
            # the footer's keys work again (the field took the focus back and the e was typed in it)
            await wait_for(pilot, lambda: bool(app.screen.exported))
            await pilot.press("n")  # exported: no question
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")
            return question

    question = asyncio.run(story())
    assert "not exported" in question and "lost" in question, question
    assert os.listdir(out)


def test_p1_abort_notice_counts_its_positions_in_words(tmp_path):
    """`a`, `y` on P1 said "P1 aborted with 1 positions captured" (seen at 80x24); one position
    is "1 position", none is said as none."""
    from tests.test_tui import screen_name

    async def story(n_wanted):
        db = str(tmp_path / f"s{n_wanted}.db")
        async with guided_bench(db, seed=3, notifications=True, average_s=1.0, settle_s=0.5) as bench:
            app, pilot = bench.app, bench.pilot
            guide = app.screen.guide
            if n_wanted:
                await bench.run(lambda: guide.n_captured == n_wanted)  # x_up: it starts there
            await pilot.press("a")
            await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
            await pilot.press("y")
            await wait_for(pilot, lambda: "aborted" in text_of(app, "#notices"))
            return words_of(app, "#notices")

    one = asyncio.run(story(1))
    assert "P1 aborted with 1 position captured: Resume (F6) continues it" in one, one
    none = asyncio.run(story(0))
    assert "P1 aborted with no position captured" in none, none


def test_history_i_on_the_second_device_stays_on_it(tmp_path):
    """Seen at 80x24: `i` on History with the second of three devices highlighted set its
    interval (the notice named it), then the devices were read again, the cursor went back to
    the first device and the line over the calibrations showed *its* due date ("due in 365 d")
    under the 30 days just typed for the other. The cursor and the right side stay on the device
    whose interval was set; both say its new date."""
    from db.store import Store
    from tests.test_tui import screen_name
    from tests.tui_data import seed_history

    db = str(tmp_path / "s.db")
    seed_history(db, "IMU-1", n=1, interval_days=365, start_year=2026)
    seed_history(db, "IMU-2", n=1, start_year=2026)
    seed_history(db, "IMU-3", n=1, start_year=2026)

    def highlighted(app) -> str:
        t = app.screen.query_one("#devices")
        return t.coordinate_to_cell_key(t.cursor_coordinate).row_key.value

    async def story():
        app = make_app(db, start="history")
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: screen_name(app) == "HistoryScreen" and "IMU-3" in text_of(app, "#devices"))
            await wait_for(pilot, lambda: app.screen.device_id == "IMU-1" and "interval 365 d" in words_of(app))
            await pilot.press("down")
            await wait_for(pilot, lambda: app.screen.device_id == "IMU-2" and "never due" in words_of(app))
            await pilot.press("i")
            await wait_for(pilot, lambda: screen_name(app) == "IntervalScreen")
            await pilot.press("3", "0", "enter")
            # the devices read again (IMU-2 no longer "no int"), then the device's own read
            await wait_for(
                pilot, lambda: screen_name(app) == "HistoryScreen" and text_of(app, "#devices").count("no int") == 1
            )
            await app.workers.wait_for_complete()
            await pilot.pause()
            return highlighted(app), app.screen.device_id, text_of(app, "#next")

    cursor, right_side, next_line = asyncio.run(story())
    assert Store(db).get_device("IMU-2")["interval_days"] == 30
    assert (cursor, right_side) == ("IMU-2", "IMU-2")
    assert "interval 30 d" in next_line and "365" not in next_line, next_line
