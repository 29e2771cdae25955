"""A bench engineer's first session at 80x24 (QA s26e), each story on the real app under its
pilot with a real SQLite file: a wrong port path says what to do next, a save that fails
says how to keep the result, and the keys a newcomer guesses for help open it."""

from __future__ import annotations

import asyncio

from station.app import make_app
from tests.test_tui import SIZE, screen_lines, screen_name, text_of, wait_for, words_of


def test_a_port_path_that_does_not_exist_says_what_to_do_next(tmp_path):
    """Typing a wrong port and F5 said only 'Cannot connect: /dev/ttyNOPE0: cannot open: No such
    file or directory'. The line now says what to check and where the ports found are listed,
    whole on the 80x24 screen (a path as long as a /dev/serial/by-id/ one), and Start is usable
    again."""
    port = str(tmp_path / "ttyNOPE0")

    async def story():
        app = make_app(str(tmp_path / "station.db"))
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")
            app.screen.query_one("#port").focus()
            await pilot.press(*port)
            await pilot.press("f5")
            await wait_for(pilot, lambda: "Cannot connect" in text_of(app, "#status"))
            return words_of(app, "#status"), app.screen.query_one("#start").disabled, screen_lines(app)

    status, start_disabled, lines = asyncio.run(story())
    assert status == (  # the port is in its field above: a long /dev/serial/by-id/ path pushed the rest off
        "Cannot connect: cannot open the port: No such file or directory: check the path and the cable "
        "(Source lists the ports found)"
    )
    assert not start_disabled
    assert all(len(line) <= SIZE[0] for line in lines)


def test_a_save_that_fails_says_how_to_keep_the_result(tmp_path):
    """`s` on Results with a database that cannot take the save (here another program wrote
    over the file: not SQLite) said 'Not saved: file is not a database ...' and nothing more:
    the operator did not learn that `e` keeps the capture and result as files, nor that `s`
    tries again once the database is mended. Both are said now, whole at 80x24; the result is
    still unsaved (ctrl+q asks)."""
    from station.screens.results import ResultsScreen
    from tests.tui_data import p1_result

    db = tmp_path / "station.db"
    db.write_text("a spreadsheet saved over the station database\n")
    cap, result = p1_result("IMU-8")

    async def story():
        app = make_app(str(db), device_id="IMU-8")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(pilot, lambda: app.screen.query_one("#residuals").row_count == 12)
            await pilot.press("s")
            await wait_for(pilot, lambda: "Not saved" in text_of(app, "#saved"))
            saved = words_of(app, "#saved")
            await pilot.press("ctrl+q")
            await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
            return saved, screen_lines(app)

    saved, lines = asyncio.run(story())
    assert saved.startswith("Not saved: file is not a database")
    assert saved.endswith("e exports the capture and result to files; s tries again")
    assert all(len(line) <= SIZE[0] for line in lines)


def test_question_mark_opens_the_help_and_a_field_keeps_it_as_text(tmp_path):
    """`?`, the key a newcomer guesses for help (less, man, htop), did nothing: only F1 opened
    it. It opens and closes the help now, on Connect and on Results; typed in a field (an
    operator's note, a place) it stays text."""
    from station.screens.results import ResultsScreen
    from tests.tui_data import p1_result

    cap, result = p1_result("IMU-8")

    async def story():
        app = make_app(str(tmp_path / "station.db"), device_id="IMU-8")
        seen = []
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")
            app.screen.query_one("#start").focus()
            await pilot.press("question_mark")
            await wait_for(pilot, lambda: screen_name(app) == "HelpScreen")
            seen.append(
                any("F1 ? help · ctrl+q quit · tab/shift+tab move · enter choose" in line for line in screen_lines(app))
            )
            await pilot.press("question_mark")
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")
            app.screen.query_one("#place").focus()
            await pilot.press("b", "a", "y", "question_mark")
            await wait_for(pilot, lambda: app.screen.query_one("#place").value == "bay?")
            seen.append(screen_name(app))
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(pilot, lambda: app.screen.query_one("#residuals").row_count == 12)
            await pilot.press("question_mark")
            await wait_for(pilot, lambda: screen_name(app) == "HelpScreen")
            await pilot.press("escape")
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen")
            return seen

    assert asyncio.run(story()) == [True, "ConnectScreen"]


def test_history_exports_a_calibration_for_a_flight_controller(tmp_path):
    """From the console there was no way to a flight controller's parameters (`station export`
    was only in the README). `e` on History's highlighted calibration writes it in the format
    typed, named by device and calibration, in the export folder; the footer shows the key at
    80 columns, and a format the calibration cannot go to is refused in one line, nothing written."""
    from db import Store
    from station.firmware_export import export
    from station.screens.history import HistoryScreen
    from station.store import save_result
    from tests.tui_data import p1_result

    db = str(tmp_path / "station.db")
    cap, result = p1_result("IMU-8")
    cal_id = save_result(db, cap, result, device_id="IMU-8")
    out = tmp_path / "out"
    out.mkdir()

    async def story():
        app = make_app(db)
        app.session.extra["export_dir"] = str(out)
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(HistoryScreen())
            await wait_for(pilot, lambda: app.screen.query_one("#calibrations").row_count == 1)
            app.screen.query_one("#calibrations").focus()
            await wait_for(pilot, lambda: "f1 Help" in screen_lines(app)[-1])
            footer = screen_lines(app)[-1]
            await pilot.press("e")
            await wait_for(pilot, lambda: screen_name(app) == "FirmwareScreen")
            await pilot.press(*"ardupilot", "enter")  # a capture in volts: ArduPilot's drivers deliver m/s^2
            await wait_for(pilot, lambda: "Not exported" in text_of(app, "#said"))
            refused = [words_of(app, "#said")]
            await pilot.press("ctrl+a", "ctrl+k", *"betaflight", "enter")
            await wait_for(pilot, lambda: "no format" in text_of(app, "#said"))
            refused.append(words_of(app, "#said"))
            await pilot.press("ctrl+a", "ctrl+k", *"c-header", "enter")
            await wait_for(pilot, lambda: "Wrote" in text_of(app, "#said"))
            wrote = words_of(app, "#said")
            lines = screen_lines(app)
            await pilot.press("escape")
            await wait_for(pilot, lambda: screen_name(app) == "HistoryScreen")
            return footer, wrote, refused, lines

    footer, wrote, refused, lines = asyncio.run(story())
    assert "e Firmware" in footer and footer.rstrip().endswith("f1 Help")
    assert refused[0].startswith("Not exported: ardupilot: accel-tabletop calibration of raw 'V' (accel_unit)")
    assert refused[1] == "no format betaflight: one of ardupilot, px4, qgc, c-header, json"
    # the line wraps where the screen ends, inside a long folder name too: compared without spaces
    assert wrote.replace(" ", "") == f"Wrote IMU-8-cal{cal_id}.h in {out}".replace(" ", ""), wrote
    with Store(db) as store:
        cal = store.calibration(cal_id)
        meta = store.capture_info(cal["capture_id"])["meta"]
    assert (out / f"IMU-8-cal{cal_id}.h").read_text() == export(cal, meta, "c-header")
    assert sorted(p.name for p in out.iterdir()) == [f"IMU-8-cal{cal_id}.h"]  # nothing from the refusals
    assert all(len(line) <= SIZE[0] for line in lines)


def test_start_asks_before_a_new_run_replaces_the_positions_kept_for_resume(tmp_path):
    """After an aborted P1 (positions kept, `Resume 1/12 [F6]` on Connect), F5 started a new
    run at once, and its first captured position wrote over the resume file: the positions
    captured before (3-5 minutes each at the source's averaging time) were gone without a word.
    F5 asks now; n (or Esc) keeps them and F6 still resumes them; y starts anew."""
    from tests.test_tui import abort_to_resume, guided_bench

    db = str(tmp_path / "station.db")

    async def story():
        async with guided_bench(db, seed=5, average_s=1.0, settle_s=0.5) as bench:
            app, pilot = bench.app, bench.pilot
            g = app.screen.guide
            await bench.run(lambda: g.n_captured == 1)  # x_up: the unit starts there
            await abort_to_resume(pilot, app)
            app.screen.query_one("#start").focus()
            await pilot.press("f5")
            await wait_for(pilot, lambda: any("Start a new run?" in line for line in screen_lines(app)))
            box = [line.split("│")[1] for line in screen_lines(app) if line.count("│") == 2]  # the box's lines
            asked = " ".join(" ".join(box).split())
            await pilot.press("n")
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")
            await pilot.press("f6")  # what was kept still resumes
            await wait_for(pilot, lambda: screen_name(app) == "ProcedureScreen" and app.screen.guide is not None)
            return asked, app.screen.guide.n_captured

    asked, n_resumed = asyncio.run(story())
    assert "Start a new run? The interrupted run's 1/12 positions are discarded" in asked
    assert "F6 (Resume) continues them instead" in asked
    assert n_resumed == 1
