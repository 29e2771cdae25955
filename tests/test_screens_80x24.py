"""The screens at 80x24 as an operator reads them (real app under its pilot, real SQLite):
units, whole warnings, every P1 position, dates with times on the History axis, counters
of the procedure only, confirmation before quitting a run, lab metadata entered once on
Connect and remembered; and `station tui` without a terminal."""

from __future__ import annotations

import asyncio
import re
import subprocess
import sys

import numpy as np
import pytest

from db import Store
from station.app import make_app
from station.sources import SimSource
from tests.test_tui import (
    SIZE,
    BenchClock,
    history_shown,
    run_bench,
    screen_lines,
    screen_name,
    text_of,
    wait_for,
    words_of,
)
from tests.tui_data import p1_result


def test_tui_without_a_terminal_exits_with_one_line(tmp_path):
    """It spun at 70 % of a core until killed (issue 15)."""
    for argv in (["tui"], [], ["demo"]):
        r = subprocess.run(
            [sys.executable, "-m", "station", *argv, "--db", str(tmp_path / "s.db")],
            stdin=subprocess.DEVNULL,
            check=False,
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert r.returncode == 2, (argv, r.stderr)
        assert r.stderr.count("\n") == 1 and "terminal" in r.stderr and r.stdout == ""


def test_results_show_units_whole_warnings_and_every_position(tmp_path):
    from station.screens.results import ResultsScreen

    cap, result = p1_result("IMU-8")
    long = (
        "the placement of x_down disagrees with its label by 12.5° (more than the 10° the gauge assumes): "
        "the table's vector condition is weakened; the norm condition still holds"
    )
    result["warnings"] = [long, "second warning that must be readable too, not cut with an ellipsis"]

    async def story():
        app = make_app(str(tmp_path / "s.db"), device_id="IMU-8")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(pilot, lambda: app.screen.query_one("#residuals").row_count == 12)
            summary = app.screen.query_one("#summary")
            text = str(summary.render())
            params = app.screen.query_one("#params")
            units = {params.get_row_at(i)[0]: params.get_row_at(i)[3] for i in range(params.row_count)}
            # every position reachable: focus the residual table and walk to its end
            app.screen.query_one("#residuals").focus()
            for _ in range(12):
                await pilot.press("down")
            await wait_for(pilot, lambda: any("xz_135" in line for line in screen_lines(app)))
            return text, units, screen_lines(app)

    text, units, lines = asyncio.run(story())
    flat = " ".join(text.split())
    assert " ".join(long.split()) in flat and "not cut with an ellipsis" in flat
    assert "…" not in flat
    assert units["B[0]"] == "m/s^2" and units["M[0][0]"].startswith("m/s^2 per")
    # one spelling of the unit on screen: the parameters' m/s^2 (the summary and the residual
    # table said m/s², mm/s²)
    assert "m/s^2 RMS" in " ".join(lines[:4]) and "|B+MV| m/s^2" in "\n".join(lines)
    assert not [line for line in lines if "/s²" in line]
    assert all(len(line) <= 80 for line in lines)


def _history_times(db, device, times):
    for k, t in enumerate(times):
        cap, result = p1_result(device, drift=0.02 * k, date=t)
        from station.store import save_result

        save_result(db, cap, result, device_id=device, operator="test", time=t)


def test_history_shows_times_of_day_and_a_date_axis(tmp_path):
    db = str(tmp_path / "s.db")
    _history_times(db, "IMU-5", ["2026-11-23T08:15:00Z", "2026-11-23T13:40:00Z", "2026-11-23T17:05:00Z"])

    async def story():
        app = make_app(db, start="history")
        async with app.run_test(size=SIZE) as pilot:
            await history_shown(pilot, app, 3)
            # the rows and the plot are painted on later refreshes than row_count says: wait for what is asserted
            want = ("date and time (UTC)", "2026-11-23 17:05", "2026-11-23 08:15")
            await wait_for(pilot, lambda: all(w in "\n".join(screen_lines(app)) for w in want))
            return screen_lines(app)

    lines = asyncio.run(story())
    text = "\n".join(lines)
    assert "2026-11-23 17:05" in text and "2026-11-23 08:15" in text  # not midnight
    ticks = re.findall(r"\b(\d\d-\d\d) (\d\d:\d\d)\b", text)
    assert ticks and all(day == "11-23" for day, _ in ticks), ticks  # one day: times of day, no year 1013
    assert "B[0] [m/s^2]" in text
    assert all(len(line) <= 80 for line in lines)


def test_history_plot_gives_a_trend_only_with_enough_calibrations_and_says_how_sure(tmp_path):
    """Two P4 calibrations minutes apart were plotted under '-9.49e+05 °/h/yr': a rate from two
    points, which the due date ignores. Under three calibrations the title says a trend needs
    three; from three on it gives the rate ± σ, the σ count and * when significant (the rule
    that moves the due date). The calibrations table is set apart from the devices table (its
    rows read as the highlighted device's own calibrations, not the one on the same line)."""
    from tests.tui_data import seed_history

    async def title(db, rows):
        app = make_app(db, start="history")
        async with app.run_test(size=SIZE) as pilot:
            await history_shown(pilot, app, rows)
            await wait_for(pilot, lambda: "B[0] [m/s^2]" in "\n".join(screen_lines(app)))
            lines = screen_lines(app)
            return next(line for line in lines if "B[0] [m/s^2]" in line), lines

    two, three = str(tmp_path / "two.db"), str(tmp_path / "three.db")
    seed_history(two, "IMU-2", n=2)
    seed_history(three, "IMU-3", n=3)  # B drifts 0.02 m/s² a year, σ 0.001 per calibration
    line2, _ = asyncio.run(title(two, 2))
    line3, lines = asyncio.run(title(three, 3))
    assert line2.rstrip().endswith("B[0] [m/s^2] 1/12  trend: 3+ calibrations")
    assert "/yr" not in line2
    [t] = [t for t in Store(three).drift("IMU-3", param="B[0]")]
    want = f"+{t['rate_per_year']:.2g}±{t['rate_sigma_per_year']:.1g} m/s^2/yr {t['significance_sigmas']:.1f}σ*"
    assert t["significant"] and line3.rstrip().endswith(want), (line3, want)
    # a column of its own between the devices and the calibrations, on every table row
    table_rows = [line for line in lines[2:6] if line.strip()]
    sep = {line[26] for line in table_rows}
    assert len(sep) == 1 and sep.pop().strip() != "", table_rows
    assert all(len(line) <= 80 for line in lines)


def test_quit_during_a_run_asks_first_and_counters_start_with_the_run(tmp_path):
    clock = BenchClock()
    src = SimSource(seed=3, clock=clock)
    src.max_batch_s = 0.5
    src.start()
    clock.t_s = 30.0  # the device ran on while nobody read it: 29.5 s of samples lost
    src.drain()
    assert src.stats().dropped > 1000
    # and again while the operator fills in Connect: nobody reads it, so the samples it could
    # not keep are counted when the procedure first reads it (they were shown as dropped)
    clock.t_s = 60.0

    async def story():
        app = make_app(None, device=src, start="procedure", average_s=60.0)
        async with app.run_test(size=SIZE) as pilot:
            await run_bench(pilot, src, clock, lambda: getattr(app.screen, "updates", 0) > 3, step_s=0.1)
            await wait_for(pilot, lambda: "dropped" in text_of(app, "#readouts"))
            readouts = text_of(app, "#readouts")
            await pilot.press("ctrl+q")
            await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
            # the footer is the question's (it showed the procedure's s Skip r Redo..., dead under the box)
            await wait_for(pilot, lambda: screen_lines(app)[-1].split() == ["y", "Yes", "n", "No"])
            await pilot.press("n")
            # mounted: its on_mount has run (leaving the app before then tears it down mid-mount)
            await wait_for(pilot, lambda: screen_name(app) == "ProcedureScreen" and app.screen.is_mounted)
            running = app.is_running
            await pilot.press("ctrl+q")
            await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
            await pilot.press("y")
            await wait_for(pilot, lambda: not app.is_running)
            return readouts, running

    readouts, running = asyncio.run(story())
    assert running
    assert re.search(r"dropped 0\b", readouts), readouts


def test_connect_remembers_the_lab_and_writes_it_into_the_capture(tmp_path):
    db = str(tmp_path / "s.db")

    async def first():
        app = make_app(db)
        async with app.run_test(size=SIZE) as pilot:
            scr = app.screen
            scr.query_one("#operator").value = "Ann Lee"
            scr.query_one("#place").value = "Lab 2, bench 3"
            scr.query_one("#reference").value = "granite table GT-4"
            scr.query_one("#serial").value = "IMU-3"
            app.session.source = SimSource(seed=1, speed=1.0)
            await pilot.press("f5")
            # mounted: its on_mount has run (leaving the app before then tears it down mid-mount)
            await wait_for(pilot, lambda: screen_name(app) == "ProcedureScreen" and app.screen.is_mounted)
            return app.session.extra

    extra = asyncio.run(first())
    assert extra["operator"] == "Ann Lee"
    with Store(db) as s:
        assert s.settings() == {
            "operator": "Ann Lee",
            "place": "Lab 2, bench 3",
            "reference_equipment": "granite table GT-4",
        }

    async def second():
        app = make_app(db)
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: app.screen.query_one("#place").value == "Lab 2, bench 3")
            return {k: app.screen.query_one(f"#{k}").value for k in ("operator", "place", "reference")}

    assert asyncio.run(second()) == {
        "operator": "Ann Lee",
        "place": "Lab 2, bench 3",
        "reference": "granite table GT-4",
    }

    # a result saved in that session carries them into its capture (and so the report)
    from station.screens.results import ResultsScreen

    cap, result = p1_result("IMU-3")

    async def save():
        app = make_app(db, device_id="IMU-3")
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: app.screen.query_one("#place").value == "Lab 2, bench 3")
            app.session.extra.update(
                operator="Ann Lee", place="Lab 2, bench 3", reference_equipment="granite table GT-4"
            )
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(pilot, lambda: app.screen.assessment is not None)
            await pilot.press("s")
            await wait_for(pilot, lambda: app.screen.calibration_id is not None)
            return app.screen.calibration_id

    cal_id = asyncio.run(save())
    with Store(db) as s:
        cal = s.calibration(cal_id)
        meta = s.capture_info(cal["capture_id"])["meta"]
    assert cal["operator"] == "Ann Lee"
    assert meta["place"] == "Lab 2, bench 3" and meta["reference_equipment"] == "granite table GT-4"


def test_the_step_list_follows_the_current_step_past_the_bottom_of_the_screen():
    """P2's 60 rows are taller than the step list at 80x24: as the run moves on (here the
    operator skips 30 rows), the current row stays in view (it stayed on rows 1-20)."""
    clock = BenchClock()
    src = SimSource(seed=1, procedure="accel-centrifuge", clock=clock)

    async def story():
        app = make_app(None, device=src, start="procedure", average_s=30.0)
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: getattr(app.screen, "guide", None) is not None)
            g = app.screen.guide
            assert len(g.steps) == 60
            await run_bench(
                pilot,
                src,
                clock,
                lambda: app.screen.last_status is not None and app.screen.last_status.phase == "change",
            )
            for k in range(30):
                await pilot.press("s")
                await wait_for(pilot, lambda k=k: g.index == k + 1)
            await wait_for(pilot, lambda: "▶ 31" in text_of(app, "#steps"))
            return text_of(app, "#steps")

    steps = asyncio.run(story())
    assert "– 30" in steps and " 1  1 @" not in steps  # scrolled: the first rows are above


def test_connect_says_what_the_averaging_time_means_for_the_procedure_picked():
    """It read "per position" (cut from "per position (source: 180–300 s)") for every
    procedure, while P4 takes it as the record's length and P3/P5 do not use it."""

    async def story():
        app = make_app(None)
        seen = {}
        async with app.run_test(size=SIZE) as pilot:
            for procedure in ("accel-tabletop", "gyro-drift", "ldv"):
                app.screen.query_one("#procedure").value = procedure
                want = registry.average_means(procedure)
                await wait_for(pilot, lambda w=want: w in text_of(app, "#average-means"))
                seen[procedure] = next(line for line in screen_lines(app) if "Average (s)" in line)
        return seen

    from station.procedures import registry

    seen = asyncio.run(story())
    assert "per position (source: 180–300 s)" in seen["accel-tabletop"]
    assert "record length (P4 asks ≥ 180 s)" in seen["gyro-drift"]
    assert "not used" in seen["ldv"]
    assert all(len(line) <= 80 for line in seen.values())


def test_a_refused_fit_says_why_in_words_not_none():
    """A P4 hold shorter than the fit allows: Results said "No calibration: None: mode B:
    ..." (the live capture has no file name) and "410 positions captured"."""
    clock = BenchClock()
    src = SimSource(seed=7, procedure="gyro-drift", clock=clock)

    async def story():
        app = make_app(None, device=src, start="procedure", average_s=10.0, settle_s=0.5)
        async with app.run_test(size=SIZE) as pilot:
            await run_bench(pilot, src, clock, lambda: screen_name(app) == "ResultsScreen", step_s=0.5)
            await wait_for(pilot, lambda: "too short" in text_of(app, "#summary"))
            return words_of(app, "#summary")

    summary = asyncio.run(story())
    assert "None" not in summary and "is too short for a drift" in summary
    assert "rows recorded" in summary and "positions" not in summary


def test_results_open_with_the_parameters_focused(tmp_path):
    """The focus was on the summary's invisible scroll container: PgDn did nothing and no
    widget showed the focus until Tab; the parameter table has it, with its bar."""
    from station.screens.results import ResultsScreen

    cap, result = p1_result("IMU-8")

    async def story():
        app = make_app(str(tmp_path / "s.db"), device_id="IMU-8")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(pilot, lambda: app.screen.query_one("#params").row_count > 0)
            await wait_for(pilot, lambda: app.focused is not None)
            focused = app.focused.id
            params = app.screen.query_one("#params")
            await pilot.press("pagedown")
            await wait_for(pilot, lambda: params.cursor_row > 0)
            return focused, screen_lines(app)

    focused, lines = asyncio.run(story())
    assert focused == "params"
    assert any(line.startswith("▊") or line.startswith("█") or line.startswith("▌") for line in lines[3:8])


def test_tab_into_a_field_and_typing_edits_its_text():
    """Textual's Input selects its whole text when focused, so Tab to the averaging time (or
    P2's radius) and a keystroke replaced the value; the station's fields keep it."""
    clock = BenchClock()
    src = SimSource(seed=0, clock=clock, procedure="accel-centrifuge")

    async def story():
        app = make_app(None, device=src)
        seen = {}
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: app.focused is not None and app.focused.id == "start")
            await pilot.press("shift+tab")  # Start → the averaging time above it
            field = app.focused
            seen["average"] = (field.id, field.value)
            await pilot.press("5")
            seen["average"] += (field.value,)
            field.value = seen["average"][1]
            await pilot.press("f5")  # P2 on the simulated centrifuge: the step list has the focus
            await wait_for(pilot, lambda: screen_name(app) == "CentrifugeScreen" and app.focused is not None)
            await pilot.press("tab")  # the step list → the radius
            field = app.focused
            seen["radius"] = (field.id, field.value)
            await pilot.press("2")
            seen["radius"] += (field.value,)
        return seen

    seen = asyncio.run(story())
    assert seen["average"][0] == "average" and seen["average"][2] == seen["average"][1] + "5", seen
    assert seen["radius"][0] == "radius" and seen["radius"][2] == seen["radius"][1] + "2", seen


def test_every_text_field_of_the_tui_is_the_stations_field():
    """The fix above holds where each screen makes its fields through ``Field``; a bare
    ``Input(`` in a screen would bring the old selection back."""
    import pathlib

    import station

    root = pathlib.Path(station.__file__).parent
    bare = [
        f"{p.relative_to(root)}:{n}"
        for p in root.rglob("*.py")
        if p.name != "field.py"
        for n, line in enumerate(p.read_text().splitlines(), 1)
        if re.search(r"(?<![A-Za-z_])Input\(", line)
    ]
    assert not bare, bare


def test_notices_never_cover_the_connect_buttons(tmp_path):
    """Back on Connect after an abort, its notice (a toast, bottom right, for 4 s) lay over
    the buttons; with a recalibration reminder and its line on top there was less room still.
    On Connect the notices are lines under the buttons, gone when they expire."""
    from tests.tui_data import seed_history

    db = str(tmp_path / "s.db")
    seed_history(db, "IMU-7", n=1, interval_days=30, start_year=2021)  # overdue: its line and notice
    clock = BenchClock()
    src = SimSource(seed=5, procedure="gyro-drift", clock=clock)

    def buttons_clear(app) -> bool:
        """Every cell of every button is the button's own (no toast or other widget on it)."""
        for button in app.screen.query("Button"):
            r = button.region
            for x in range(r.x, r.right):
                if app.screen.get_widget_at(x, r.y)[0] is not button:
                    return False
        return True

    async def story():
        app = make_app(db, device=src, average_s=180.0)
        frames = []
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await wait_for(pilot, lambda: "IMU-7" in text_of(app, "#notices"))
            frames.append((buttons_clear(app), screen_lines(app)))
            await pilot.press("f5")
            await run_bench(pilot, src, clock, lambda: screen_name(app) == "HoldScreen" and app.screen.updates > 2)
            await pilot.press("a")
            await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
            await pilot.press("y")
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")
            await wait_for(pilot, lambda: "aborted" in text_of(app, "#notices"))
            frames.append((buttons_clear(app), screen_lines(app)))
            await wait_for(pilot, lambda: "aborted" not in text_of(app, "#notices"), timeout_s=30.0)
            frames.append((buttons_clear(app), screen_lines(app)))
        return frames

    frames = asyncio.run(story())
    for clear, lines in frames:
        assert clear, "\n".join(lines)
        row = next(i for i, line in enumerate(lines) if "Start [F5]" in line)
        assert all(b in lines[row] for b in ("Resume [F6]", "History [F2]", "Import file [F7]")), lines[row]
    # the abort's notice was shown, below the buttons, in words
    lines = frames[1][1]
    row = next(i for i, line in enumerate(lines) if "Start [F5]" in line)
    assert any("P4 aborted: nothing saved" in line for line in lines[row + 1 :]), "\n".join(lines)


def test_results_l_sets_the_devices_limits_and_judges_the_result_again(tmp_path):
    """Limits were reachable from History only; after a calibration the operator is on
    Results: `l` opens the same editor there, and the verdict is drawn again with them."""
    from station.screens.results import ResultsScreen
    from tests.tui_data import seed_history

    db = str(tmp_path / "s.db")
    seed_history(db, "IMU-7", n=1)
    cap, result = p1_result("IMU-7", drift=0.02)

    async def story():
        app = make_app(db, device_id="IMU-7")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(pilot, lambda: app.screen.query_one("#params").row_count > 0)
            before = text_of(app, "#summary")
            await pilot.press("l")
            await wait_for(
                pilot, lambda: screen_name(app) == "LimitsScreen" and "no limits" in text_of(app, "#current")
            )
            await pilot.press(*"B=5:6", "enter")  # B is a few cm/s², far below 5 m/s^2
            await wait_for(pilot, lambda: "B " in text_of(app, "#current"))
            await pilot.press("escape")
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen" and "FAIL" in text_of(app, "#summary"))
            return before, words_of(app, "#summary")

    before, after = asyncio.run(story())
    assert "NO TOLERANCE" in before and "FAIL" not in before
    assert "B[0] =" in after and "outside its limits 5 … 6" in after
    assert Store(db).get_device("IMU-7")["limits"] == {"B": [5.0, 6.0]}


def _simulated_result(procedure: str, seed: int, **options):
    from solvers.simulate import simulate
    from station.calibrate import calibrate_capture
    from station.capture import Capture

    sim = simulate(procedure, seed=seed, **options)
    cap = Capture(dict(sim.meta), {k: np.asarray(v) for k, v in sim.columns.items()})
    return cap, calibrate_capture(cap)


def test_limits_and_tolerances_are_shown_and_typed_in_the_units_results_shows(tmp_path):
    """P4's drift is on Results in °/h: its limits editor showed and took rad/s (a limit typed
    as 2000, meant as °/h, was stored as 2000 rad/s) and the FAIL reasons said rad/s beside
    a table in °/h. Now one unit on the screen, typed in it, stored in rad/s (1 °/h =
    π/648000 rad/s); the compass's soft iron alike as a ratio (uT/uT, stored nT per uT)."""
    import math

    from station.screens.results import ResultsScreen

    db = str(tmp_path / "s.db")
    deg_h = math.pi / 648000.0
    cap, result = _simulated_result("gyro-drift", 401000, duration_s=60)
    Store(db).add_device("G1", tolerances={"drift": 1.0 * deg_h}, limits={"drift": (-0.001, 0.001)})
    previous = {"id": 1, "time": "2026-01-01T00:00:00Z", "params": dict(result["params"])}
    previous["params"]["drift"] = [x - 5.0 * deg_h for x in result["params"]["drift"]]  # 5 °/h ago
    mcap, mresult = _simulated_result("compass", 401001)
    assert mresult["mag_unit"] == "uT"
    Store(db).add_device("M1")

    async def story():
        app = make_app(db, device_id="G1")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, previous))
            await wait_for(pilot, lambda: "FAIL" in text_of(app, "#summary"))
            reasons = words_of(app, "#summary")
            await pilot.press("l")
            await wait_for(pilot, lambda: screen_name(app) == "LimitsScreen" and "drift" in text_of(app, "#current"))
            shown = text_of(app, "#current")
            await pilot.press(*"drift=-2000:2000", "enter")
            await wait_for(pilot, lambda: "stored" in text_of(app, "#said"))
            said = text_of(app, "#said")
            await wait_for(pilot, lambda: "-2000 … 2000" in text_of(app, "#current"))
            await pilot.press("escape")
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen")
            app.session.device_id = "M1"
            await app.push_screen(ResultsScreen(mcap, mresult, None, None))
            await wait_for(pilot, lambda: app.screen.query_one("#params").row_count > 0)
            await pilot.press("l")
            await wait_for(
                pilot, lambda: screen_name(app) == "LimitsScreen" and "no limits" in text_of(app, "#current")
            )
            await pilot.press(*"soft_iron=0.9:1.1", "enter")
            await wait_for(pilot, lambda: "soft_iron" in text_of(app, "#current"))
            soft = text_of(app, "#current")
        return reasons, shown, said, soft

    reasons, shown, said, soft = asyncio.run(story())
    assert "rad/s" not in reasons and "rad/s" not in shown
    # 5 °/h changed against 1 °/h allowed; 0.001 rad/s is 206.265 °/h
    assert re.search(r"drift\[0\] changed \+5(\.0+\d*)? °/h \(tolerance 1 °/h\)", reasons), reasons
    outside = [i for i, x in enumerate(result["params"]["drift"]) if abs(x) > 0.001]
    for i in outside:
        assert f"drift[{i}] = " in reasons and "outside its limits -206.265 … 206.265 °/h" in reasons
    assert "-206.265 … 206.265" in shown and "°/h" in shown
    assert "drift = -2000 … 2000 °/h" in said
    low, high = Store(db).get_device("G1")["limits"]["drift"]
    assert math.isclose(high, 2000 * deg_h, rel_tol=1e-12) and math.isclose(low, -2000 * deg_h, rel_tol=1e-12)
    assert "0.9 … 1.1" in soft and "uT/uT" in soft
    assert Store(db).get_device("M1")["limits"]["soft_iron"] == [900.0, 1100.0, "nT per uT"]


def test_limits_editor_takes_a_soft_iron_limit_before_any_compass_calibration_as_the_cli_does(tmp_path):
    """The compass's soft iron is typed as a ratio and stored in nT per the capture's unit:
    with no compass calibration of the device that unit is unknown. It was refused (the
    editor before that stored 0.9:1.1 as 'nT per raw', read later in nT per uT); now the CLI
    and the editor keep it as typed with its unit, a ratio, said whole in the box at 80x24,
    and each later result reads it in its own unit."""
    from station.cli import main
    from station.screens.results import ResultsScreen
    from tests.station_run import run_station
    from tests.tui_data import seed_history

    db = tmp_path / "s.db"
    seed_history(str(db), "IMU-7", n=1)  # a P1 calibration only
    Store(str(db)).add_device("IMU-7", limits={"B": (-0.5, 0.5)})
    entry = "soft_iron[0][0]=0.9:1.1"
    cli = run_station("devices", "add", "IMU-7", "--limit", entry, "--db", db)
    assert cli.returncode == 0, cli.stderr
    assert Store(str(db)).get_device("IMU-7")["limits"]["soft_iron[0][0]"] == [0.9, 1.1, "ratio"]
    assert run_station("devices", "add", "IMU-7", "--limit", "soft_iron[0][0]=", "--db", db).returncode == 0
    new_db = tmp_path / "new.db"  # a new user's first run, on Results: no database yet
    cap, result = p1_result("NEW-1")

    def shown(app):
        return " ".join((text_of(app, "#error") + " " + text_of(app, "#said")).split())

    async def story(path, open_editor, **options):
        app = make_app(str(path), **options)
        async with app.run_test(size=SIZE) as pilot:
            await open_editor(app, pilot)
            await pilot.press("l")
            await wait_for(
                pilot, lambda: screen_name(app) == "LimitsScreen" and "reading" not in text_of(app, "#current")
            )
            await pilot.press(*entry, "enter")
            await wait_for(pilot, lambda: shown(app) and "soft_iron" in text_of(app, "#current"))
            return shown(app), screen_lines(app)

    async def history(app, pilot):
        await history_shown(pilot, app, 1)

    async def results(app, pilot):
        await app.push_screen(ResultsScreen(cap, result, None, None))
        await wait_for(pilot, lambda: app.screen.query_one("#params").row_count > 0)

    for path, device, open_editor, options in (
        (db, "IMU-7", history, {"start": "history"}),
        (new_db, "NEW-1", results, {"device_id": "NEW-1"}),
    ):
        message, lines = asyncio.run(story(path, open_editor, **options))
        assert message == "stored: soft_iron[0][0] = 0.9 … 1.1 mag_unit/mag_unit", message
        assert "Traceback" not in "\n".join(lines)
        assert all(len(line) <= 80 for line in lines) and len(lines) == 24
        assert Store(str(path)).get_device(device)["limits"]["soft_iron[0][0]"] == [0.9, 1.1, "ratio"]
    assert main(["verify", "--db", str(db)]) == 0


def test_help_lines_fit_the_box_at_80x24():
    """F1 at 80x24: every line of the keys fits the box beside its scroll bar. A longer one
    wrapped to the box's left edge ('ref.)' and 'on.' alone under the key column), where it
    read as a new entry; all of it is reached by scrolling."""
    from textual.widgets import Static

    from station.screens.help import HELP

    async def story():
        app = make_app(None)
        async with app.run_test(size=SIZE) as pilot:
            await pilot.press("f1")
            await wait_for(pilot, lambda: screen_name(app) == "HelpScreen")
            text = app.screen.query_one("#help Static", Static)  # (not the notices line under the box)
            await wait_for(pilot, lambda: text.size.height > 0)
            height = text.size.height
            box = app.screen.query_one("#help")
            await pilot.press("end")
            await wait_for(pilot, lambda: box.scroll_y == box.max_scroll_y)
            return height, screen_lines(app)

    height, lines = asyncio.run(story())
    assert height == len(HELP.split("\n"))  # one screen row per line (the last one empty): nothing wrapped
    # (s28: the box's last page since the Diagnose entry, above the P1 text)
    assert any("esc stops it and goes back (nothing is saved or changed)" in line for line in lines)
    assert any(line.strip(" │").startswith("under it says") for line in lines)  # the last line, reached


def test_diagnose_screen_lines_continue_under_their_text_at_80x24():
    """A P4 diagnosis at 80x24: its long lines (an unresolvable effect's reason, the
    candidates' rule, the per-time-block rows) wrapped to the screen's left edge, where a
    continuation read as a new entry. Now each line fits, continued under its own text."""
    from station.screens.diagnose import DiagnoseScreen

    cap, _ = _simulated_result("gyro-drift", 401002, duration_s=60)

    async def story():
        app = make_app(None)
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(DiagnoseScreen(capture=cap))
            await wait_for(pilot, lambda: app.screen.report is not None)
            report = app.screen.report
            shown = screen_lines(app)
        return report, shown

    report, shown = asyncio.run(story())
    text = [line for line in report.splitlines() if "\x1b" not in line]  # the plots have their own width
    assert "unresolvable: " in report and "per time block" in report
    assert all(len(line) <= 74 for line in text), [line for line in text if len(line) > 74]
    reason = next(i for i, line in enumerate(text) if "unresolvable: " in line)
    column = text[reason].index("unresolvable: ")
    assert text[reason + 1].startswith(" " * column) and text[reason + 1][column] != " "
    # on screen: no line of the report begins at the screen's edge but the labels' own
    labels = ("procedure", "baseline", "candidates", "extended", "verdict", "measured", "effect", "quality", "WARNING")
    body = [line[1:] for line in shown[1:-1] if line.strip()]
    assert all(line.startswith(" ") or line.startswith(labels) for line in body), body


def test_limits_example_uses_the_devices_own_parameter_names(tmp_path):
    """The limits box's example said ``B=… M[0][0]=… S=…`` (P1/P2 names) on a P4 gyro whose
    only limited parameter is ``drift``: from Results (the result on screen) and from
    History (the device's newest calibration) it now names the procedure's parameters."""
    from station.screens.limits import LimitsScreen
    from station.screens.results import ResultsScreen

    db = str(tmp_path / "s.db")
    cap, result = _simulated_result("gyro-drift", 401002, duration_s=60)
    Store(db).save_calibration(result, meta=dict(cap.meta), columns=dict(cap.columns), device_id="G2")

    async def story():
        app = make_app(db, device_id="G2")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(pilot, lambda: app.screen.query_one("#params").row_count > 0)
            await pilot.press("l")
            await wait_for(pilot, lambda: screen_name(app) == "LimitsScreen")
            from_results = app.screen.query_one("#edit").placeholder
            await pilot.press("escape")
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen")
            await app.push_screen(LimitsScreen("G2"))
            await wait_for(pilot, lambda: "reading" not in text_of(app, "#current"))
            await wait_for(pilot, lambda: "drift" in app.screen.query_one("#edit").placeholder)
            return from_results, app.screen.query_one("#edit").placeholder

    from_results, from_history = asyncio.run(story())
    for shown in (from_results, from_history):
        assert "drift=" in shown and "°/h" in shown, shown
        assert "M[0][0]" not in shown and "B" not in shown, shown


def test_a_soft_iron_limit_stored_before_any_compass_calibration_says_no_invented_unit(tmp_path):
    """The limits editor once stored a soft iron limit for a device with no compass
    calibration as typed (it refuses that now); such a row in a real database file was
    listed as 'nT per raw', and a hard iron one as 'raw': a unit no capture had said. It is
    now listed in the stored unit with the capture's magnetometer unit named as not known
    ('nT per mag_unit'); once a compass calibration tells it, its unit is said."""
    from station.screens.limits import LimitsScreen

    db = str(tmp_path / "s.db")
    Store(db).add_device("M9", limits={"soft_iron": [0.9, 1.1], "hard_iron": [-5.0, 5.0]})  # as the old editor did

    async def story():
        app = make_app(db, device_id="M9")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(LimitsScreen("M9"))
            await wait_for(
                pilot, lambda: screen_name(app) == "LimitsScreen" and "soft_iron" in text_of(app, "#current")
            )
            return text_of(app, "#current")

    shown = asyncio.run(story())
    assert "raw" not in shown, shown
    soft = next(line for line in shown.splitlines() if "soft_iron" in line)
    hard = next(line for line in shown.splitlines() if "hard_iron" in line)
    assert soft.split()[-1] == "mag_unit" and "nT per mag_unit" in soft, soft
    assert hard.split()[-1] == "mag_unit", hard


def test_history_status_words_fit_their_column(tmp_path):
    """History's device list showed "never c" for a device never calibrated (a 7-wide column
    cut "never calibrated"): every status Store.due gives is now said whole in the column."""
    from station.screens.history import STATUS_WIDTH

    db = str(tmp_path / "s.db")
    Store(db).add_device("NEW-1")

    async def story():
        app = make_app(db)
        async with app.run_test(size=SIZE) as pilot:
            await pilot.press("f2")
            await wait_for(pilot, lambda: screen_name(app) == "HistoryScreen" and "NEW-1" in text_of(app, "#devices"))
            return text_of(app, "#devices")

    shown = asyncio.run(story())
    row = next(line for line in shown.splitlines() if "NEW-1" in line)
    assert "no cal" in row and "never c" not in row, row
    for word in ("overdue", "due", "ok", "no cal"):
        assert len(word) <= STATUS_WIDTH


def test_notices_never_cover_the_results_tables(tmp_path):
    """A toast (bottom right, 3 to 5 lines each, two stacked) lay over the per-position
    residuals and the last parameter rows at 80x24 for up to 8 s (an export's "Exported ... in
    FOLDER", "Save first (s)"). On Results the notices are lines under the tables: every cell of
    both tables stays the table's own, and the notice is read in words, gone when it expires."""
    from station.screens.results import ResultsScreen

    cap, result = p1_result("IMU-8")

    def tables_clear(app) -> bool:
        """Every cell of each table's region shows that table or its scrollbar (no toast or
        other widget on it)."""
        for table in app.screen.query("DataTable"):
            r = table.region
            if not table.display or r.area == 0:
                return False
            for y in range(r.y, r.bottom):
                for x in range(r.x, r.right):
                    if table not in app.screen.get_widget_at(x, y)[0].ancestors_with_self:
                        return False
        return True

    async def story():
        app = make_app(str(tmp_path / "s.db"), device_id="IMU-8")
        app.session.extra["export_dir"] = str(tmp_path)
        frames = []
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(pilot, lambda: app.screen.query_one("#residuals").row_count == 12)
            await pilot.press("r")  # a report before saving: a warning notice
            await pilot.press("e")  # an export: where the files went

            def notices() -> str:  # the line under the tables ("" where there is none)
                return text_of(app, "#notices") if app.screen.query("#notices") else ""

            def both_shown() -> bool:  # as toasts (drawn) or as lines
                toasts = [t for t in app.screen.query("Toast") if t.region.area]
                return len(toasts) == 2 or "Exported" in notices()

            await wait_for(pilot, both_shown)
            frames.append((tables_clear(app), screen_lines(app), notices()))
            await wait_for(pilot, lambda: "Save first" not in notices(), timeout_s=30.0)
            frames.append((tables_clear(app), screen_lines(app), notices()))
        return frames

    frames = asyncio.run(story())
    for clear, lines, _ in frames:
        assert clear, "\n".join(lines)
    lines, notices = frames[0][1], " ".join(frames[0][2].split())
    assert "Save first (s): the report is of a stored calibration" in notices
    assert "Exported" in notices and "Exported" in "\n".join(lines)
    row = next(i for i, line in enumerate(lines) if "Save first" in line)
    assert row > max(i for i, line in enumerate(lines) if "xz_135" in line or "x_up" in line)  # below the tables


# ---------------------------------------------------------------- notices on the other screens


def _covered(app, selectors) -> list[str]:
    """The widgets of ``selectors`` (on the screen on top) that another widget, such as a toast,
    lies over somewhere in their region: each cell of each region must show that widget (or a
    child of it)."""
    out = []
    for sel in selectors:
        w = app.screen.query_one(sel)
        r = w.region
        assert w.display and r.area, sel
        if any(
            w not in app.screen.get_widget_at(x, y)[0].ancestors_with_self
            for y in range(r.y, r.bottom)
            for x in range(r.x, r.right)
        ):
            out.append(sel)
    return out


def _notices(app) -> str:
    """The notices line of the screen on top ("" where there is none), in words."""
    return words_of(app, "#notices") if app.screen.query("#notices") else ""


def _shown(app, *words) -> bool:
    """Each of ``words`` is on screen, as a toast (drawn) or in the notices line."""
    toasts = " ".join(str(t.render()) for t in app.screen.query("Toast") if t.region.area)
    return all(w in toasts or w in _notices(app) for w in words)


def _hold_notices(app, hold_s: float = 120.0) -> None:
    """Let every notice of ``app`` last ``hold_s``: the screens say them for 2 s, and a loaded
    machine may let the first go before the next is drawn; what is checked is where two lie at once."""
    notify = app.notify

    def held(message, *, timeout=None, **kw):
        return notify(message, timeout=hold_s, **kw)

    app.notify = held


async def _press_until_shown(pilot, app, keys, words):
    """Press ``keys`` once and wait until every one of ``words`` is on screen at once."""
    _hold_notices(app)
    await pilot.press(*keys)
    await wait_for(pilot, lambda: _shown(app, *words), timeout_s=60.0)


def test_notices_never_cover_the_p1_and_p2_prompts(tmp_path):
    """P1: a position captured and the next `p` (or a device error, a warning) stacked two
    toasts over the right half of the readouts and the prompt under them ("turn the unit over");
    P2: a spin and a `f` too early lay over the prompt, the progress and the row-entry fields.
    (Measured here with `f` too early and `p`, 39x4 + 39x3 cells.)
    Both now say them on the free rows under the progress."""
    from station.screens.centrifuge import CentrifugeScreen

    async def p1():
        clock = BenchClock()
        src = SimSource(seed=2, clock=clock, procedure="accel-tabletop")
        app = make_app(str(tmp_path / "s.db"), device=src, average_s=2.0, settle_s=0.5, start="procedure")
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await wait_for(pilot, lambda: screen_name(app) == "ProcedureScreen" and app.screen.updates > 2)
            await run_bench(pilot, src, clock, lambda: _shown(app, "x_up captured"))
            # fit asked too early (a warning), then the next position asked of the simulated bench
            await _press_until_shown(pilot, app, ("f", "p"), ("P1 needs at least 9", "Simulated unit turned to"))
            return _covered(app, ["#readouts", "#message", "#progress"]), _notices(app), screen_lines(app)

    async def p2():
        app = make_app(None, device=SimSource(seed=2, procedure="accel-centrifuge"), average_s=2.0, start="procedure")
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await wait_for(pilot, lambda: isinstance(app.screen, CentrifugeScreen) and app.screen.guide is not None)
            # spin (simulated), then fit with no row yet
            await _press_until_shown(pilot, app, ("p", "f"), ("Simulated centrifuge", "P2 needs at least"))
            sel = ["#message", "#progress", "#manual", "#readouts"]
            return _covered(app, sel), _notices(app), screen_lines(app)

    for story in (p1, p2):
        covered, notices, lines = asyncio.run(story())
        assert covered == [], (story.__name__, covered, "\n".join(lines))
        assert notices.count("\n") == 0 and len(notices) > 20, notices  # said in words, on screen
        assert all(len(line) <= 80 for line in lines)


def test_notices_never_cover_the_history_plot_nor_the_allan_table(tmp_path):
    """History: the start-up reminder says "(F2 history)"; pressed, its toast (10 s, 39x5) lay
    over the drift plot's last points and date axis. Allan result: an export's toast (8 s, up to
    39x9) lay over the table's means and "P4 needs" and the answer under it."""
    import os

    from station.capture import read_capture
    from station.procedures.noise import noise_report
    from station.screens.noise import AllanScreen
    from tests.tui_data import seed_history

    db = str(tmp_path / "s.db")
    seed_history(db, "IMU-7", n=3, interval_days=365)
    seed_history(db, "IMU-8", n=1, interval_days=365)  # 2024-03-01: overdue

    async def history():
        app = make_app(db)
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await wait_for(pilot, lambda: any(n.title == "Recalibration" for n in app.notices))
            await pilot.press("f2")
            await history_shown(pilot, app, 3)
            await wait_for(
                pilot, lambda: _shown(app, "overdue: IMU-8") and "date (UTC)" in "\n".join(screen_lines(app))
            )
            return _covered(app, ["#devices", "#calibrations", "#plot"]), _notices(app), screen_lines(app)

    cap_path = tmp_path / "still.csv"
    from tests.station_run import run_station

    assert run_station("simulate", "--procedure", "gyro-drift", "--seed", 400003, "--out", cap_path).returncode == 0
    cap = read_capture(cap_path)
    gyro = np.column_stack([cap.columns[c] for c in ("gx", "gy", "gz")])
    report = noise_report(gyro, float(cap.meta["sample_rate_hz"]), cap.meta.get("gyro_unit"))

    async def allan():
        app = make_app(None)
        app.session.extra["export_dir"] = str(tmp_path / "a folder the bench keeps its exports in")
        os.makedirs(app.session.extra["export_dir"])
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await app.push_screen(AllanScreen(cap, report))
            await wait_for(pilot, lambda: "P4 needs" in "\n".join(screen_lines(app)) and app.screen.focused is None)
            await pilot.press("e")
            await wait_for(pilot, lambda: _shown(app, "Exported"))
            return _covered(app, ["#table", "#ask", "#status"]), _notices(app), screen_lines(app)

    for story in (history, allan):
        covered, notices, lines = asyncio.run(story())
        assert covered == [], (story.__name__, covered, "\n".join(lines))
        assert ("Recalibration" in notices) if story is history else ("Exported" in notices), notices
        assert all(len(line) <= 80 for line in lines)


def test_notices_of_results_never_cover_its_boxes_nor_the_diagnose_report(tmp_path):
    """Results says its notices on lines under its tables; a box opened over it (Decide on a
    FAIL, Limits, Help) or Diagnose got them back as toasts: an export's (8 s, 39x9) lay over
    Decide's and Limits' last lines, Help's text, the report's figures. Each says them in its
    own place."""
    from station.screens.results import ResultsScreen
    from tests.tui_data import seed_history

    db = str(tmp_path / "s.db")
    seed_history(db, "IMU-7", n=1, tolerances={"B": 0.1})
    with Store(db) as s:
        previous = s.history("IMU-7")[-1]
    cap, result = p1_result("IMU-7", drift=0.5)  # B moved 0.5 m/s²: FAIL

    async def story():
        app = make_app(db, device_id="IMU-7")
        app.session.extra["export_dir"] = str(tmp_path)
        seen = {}
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, previous))
            await wait_for(pilot, lambda: app.screen.query_one("#params").row_count > 0)
            for key, screen, parts in (
                ("s", "DecideScreen", ["#box"]),
                ("l", "LimitsScreen", ["#box"]),
                ("f1", "HelpScreen", ["#help"]),
                ("g", "DiagnoseScreen", ["VerticalScroll"]),
            ):
                for _ in range(5):  # again if a loaded machine let the notice go before the box came
                    await pilot.press("e")  # an export: where the files went (8 s)
                    await wait_for(pilot, lambda: "Exported" in _notices(app))
                    await pilot.press(key)
                    await wait_for(pilot, lambda screen=screen: screen_name(app) == screen)
                    try:
                        await wait_for(pilot, lambda: _shown(app, "Exported"), timeout_s=6.0)
                        seen[screen] = (_covered(app, parts), _notices(app), screen_lines(app))
                    except AssertionError:
                        pass
                    await pilot.press("escape")
                    await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen")
                    if screen in seen:
                        break
        return seen

    seen = asyncio.run(story())
    assert list(seen) == ["DecideScreen", "LimitsScreen", "HelpScreen", "DiagnoseScreen"]
    for screen, (covered, notices, lines) in seen.items():
        assert covered == [], (screen, covered, "\n".join(lines))
        assert "Exported IMU-7-accel-tabletop-" in notices and ".json in" in notices, (screen, notices)
        assert all(len(line) <= 80 for line in lines)


@pytest.mark.parametrize("device", ["lab/unit7", "../unit7"])
def test_export_of_a_device_whose_id_holds_a_slash_stays_in_the_export_folder(tmp_path, device):
    """`e` on Results named its files `<device>-<what>-<stamp>.*` with the id as it is: a device
    'lab/unit7' said "Export failed: ... cannot write: no folder .../lab", and '../unit7' wrote
    beside the export folder, not in it. The id goes into the name as the resume file's does
    (letters, digits, - _ . kept; anything else _)."""
    from station.screens.results import ResultsScreen

    cap, result = p1_result(device)
    folder = tmp_path / "exports"
    folder.mkdir()

    async def story():
        app = make_app(str(tmp_path / "s.db"), device_id=device)
        app.session.extra["export_dir"] = str(folder)
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(pilot, lambda: app.screen.query_one("#residuals").row_count == 12)
            await pilot.press("e")
            await wait_for(pilot, lambda: _shown(app, "Export"))
            return _notices(app) + " ".join(str(t.render()) for t in app.screen.query("Toast"))

    shown = asyncio.run(story())
    assert "failed" not in shown, shown
    names = sorted(p.name for p in folder.iterdir())
    assert [n.rsplit(".", 1)[1] for n in names] == ["csv", "json"], names
    assert all(n.startswith(device.replace("/", "_") + "-accel-tabletop-") for n in names), names
    assert not [p.name for p in tmp_path.iterdir() if p.suffix in (".csv", ".json")]  # none beside the folder


def test_history_shows_the_status_of_a_device_with_a_long_id(tmp_path):
    """History's devices table is 26 columns wide: an id of 44 characters took them all, and
    `n` and `status` (overdue, due) were off to the right, out of sight at 80x24. A long id is
    shown by its start and end, so the status stays on screen beside it."""
    from tests.tui_data import seed_history

    db = str(tmp_path / "s.db")
    long_id = "BENCH-IMU-LONG-SERIAL-0123456789-ABCDEFGHIJ"
    seed_history(db, long_id, n=1, interval_days=30, start_year=2024)  # years ago: overdue

    async def story():
        app = make_app(db)
        async with app.run_test(size=SIZE) as pilot:
            await pilot.press("f2")
            await history_shown(pilot, app, 1)
            return screen_lines(app)

    lines = asyncio.run(story())
    row = next(line for line in lines if "BENCH" in line and "▏" in line)  # not the overdue notice above
    left = row.split("▏")[0]  # the devices table, left of the divider
    assert "overdue" in left and "EFGHIJ" in left, "\n".join(lines)


def test_compass_results_show_the_tol_column_and_use_the_screen_height(tmp_path):
    """The compass's parameter table was 86 columns wide at 80x24 (its reference names,
    `reference.declination_deg`, are 25 characters): `tol` was cut off behind a horizontal
    scrollbar while 7 blank lines lay under the table (the compass has no per-position table,
    yet the parameters kept to two thirds of the height). A device with tolerances and a
    calibration in use (another simulated unit's, so every Δ/σ is a real number)."""
    from station.screens.results import ResultsScreen

    db = str(tmp_path / "s.db")
    cap, result = _simulated_result("compass", 401001)
    _, other = _simulated_result("compass", 401002)
    assert result["mag_unit"] == "uT"
    Store(db).add_device("M1", tolerances={"hard_iron": 0.5, "soft_iron": 20.0})  # 0.5 uT, 0.02 as a ratio
    previous = {"id": 1, "time": "2026-01-01T00:00:00Z", "params": other["params"]}

    async def story():
        app = make_app(db, device_id="M1")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, previous))
            await wait_for(pilot, lambda: "hard_iron[0]" in "\n".join(screen_lines(app)))
            params, tables = app.screen.query_one("#params"), app.screen.query_one("#tables")
            fits = params.virtual_size.width <= params.scrollable_content_region.width
            first = screen_lines(app)
            gap = tables.region.bottom - params.region.bottom
            for _ in range(params.row_count):  # to the last row: every parameter is reachable
                await pilot.press("down")
            await wait_for(pilot, lambda: "declination_deg" in "\n".join(screen_lines(app)))
            return fits, gap, first, screen_lines(app)

    fits, gap, first, last = asyncio.run(story())
    shown = "\n".join(first)
    assert fits and all(len(line) <= 80 for line in first + last), shown
    at = next(i for i, line in enumerate(first) if " param " in line)
    table = first[at:]  # the FAIL reasons above name the same parameters
    assert table[0].split()[-1] == "tol", shown
    for name, tol in (("hard_iron[0]", "0.5"), ("soft_iron[0][0]", "0.02"), ("soft_iron[2][2]", "0.02")):
        row = next(line for line in table if f" {name} " in line)
        assert row.split()[-1] == tol, shown  # the row's tolerance, on screen
    assert gap == 0, shown  # no blank lines under the parameters
    assert sum(" soft_iron[" in line for line in table) == 9, shown  # all of the soft iron at once
    end = "\n".join(last)
    assert "reference." in end and "inclination_deg" in end and "declination_deg" in end, end


def test_saving_a_compass_to_a_unit_registered_as_an_accelerometer_is_said(tmp_path):
    """As `calibrate --save` says it: a compass result saved on Results to a device registered
    for accel only is saved (a unit may carry several sensors) and a notice says mag is now
    among its kinds (the device id may name another unit). A device registered for mag saves
    without it."""
    from station.screens.results import ResultsScreen

    db = str(tmp_path / "s.db")
    cap, result = _simulated_result("compass", 401001)
    cap2, result2 = _simulated_result("compass", 401004)
    Store(db).add_device("ACC-1", sensor_kinds=["accel"])
    Store(db).add_device("MAG-1", sensor_kinds=["mag", "accel"])

    async def story():
        said = []
        app = make_app(db, device_id="ACC-1")
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            for device, c, r in (("ACC-1", cap, result), ("MAG-1", cap2, result2)):
                app.session.device_id = device
                await app.push_screen(ResultsScreen(c, r, None, None))
                # the device's record is read (a worker) before the table is drawn: then s saves
                await wait_for(pilot, lambda: app.screen.query_one("#params").row_count > 0)
                await pilot.press("s")
                await wait_for(pilot, lambda: "Saved as calibration" in text_of(app, "#saved"))
                await pilot.pause(0.2)
                said.append(words_of(app, "#notices") if app.screen.query("#notices") else "")
        return said

    acc, mag = asyncio.run(story())
    assert "ACC-1 was registered for accel, not mag: mag is now among its sensor kinds" in acc, acc
    assert "MAG-1 was registered" not in mag, mag  # (the first one's notice may still be up)
    assert Store(db).get_device("ACC-1")["sensor_kinds"] == ["accel", "mag"]
