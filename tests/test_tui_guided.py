"""Pilot tests for the P2 centrifuge and the gyro noise (Allan) screens at 80x24: each
screen's story on the real Textual app, the simulated device, a real SQLite file."""

from __future__ import annotations

import asyncio
import json

import numpy as np
import pytest

from station.app import make_app
from station.sources import SimSource
from tests.test_tui import (
    SIZE,
    BenchClock,
    run_bench,
    screen_lines,
    screen_name,
    start_on_sim,
    text_of,
    wait_for,
    words_of,
)


def test_centrifuge_manual_entry_refuses_bad_values_then_skip_and_abort():
    """P2 picked on Connect; the operator types a row: a word is refused in one line and
    nothing is captured; the corrected row is captured (✓); skip; abort back to Connect."""

    async def story():
        app = make_app(None, average_s=60.0)
        # the bench clock runs (each step consumed) until the noise rest is over, then it
        # stands still, so the pilot's key presses (which wait for an idle process) are not
        # slowed by the stream
        clock = BenchClock()
        async with app.run_test(size=SIZE) as pilot:
            assert "P2 accelerometer, centrifuge" in [str(o[0]) for o in app.screen.query_one("#procedure")._options]
            app.screen.query_one("#procedure").value = "accel-centrifuge"
            src = app.session.source = SimSource(seed=1, procedure="accel-centrifuge", clock=clock)
            await pilot.press("f5")
            await wait_for(pilot, lambda: screen_name(app) == "CentrifugeScreen" and app.screen.guide is not None)
            g = app.screen.guide
            await run_bench(
                pilot,
                src,
                clock,
                lambda: app.screen.last_status is not None and app.screen.last_status.phase == "change",
                step_s=0.1,
            )
            assert "Mount in orientation 1, spin at 6.28 rad/s" in text_of(app, "#prompt")
            footer = screen_lines(app)[-1]
            assert "m Type row" in footer and "s Skip" in footer and "f Fit now" in footer
            await pilot.press("m")
            await pilot.press(*"1.5", "enter", *"abc", "enter", *"0.2", "enter", *"6.28", "enter")
            await wait_for(pilot, lambda: "ay: 'abc' is not a number" in text_of(app, "#entry-error"))
            assert g.n_captured == 0 and g.index == 0
            app.screen.query_one("#in-ay").value = "-0.25"
            app.screen.query_one("#in-speed").focus()
            await pilot.press("enter")
            await wait_for(pilot, lambda: g.n_captured == 1)
            assert g.steps[0].how == "manual" and g.steps[0].values == [1.5, -0.25, 0.2]
            assert text_of(app, "#entry-error").strip() == ""
            steps = app.screen.query_one("#steps")
            await wait_for(pilot, lambda: "✓" in str(steps.get_option_at_index(0).prompt))
            await pilot.press("escape", "s")
            await wait_for(pilot, lambda: g.steps[1].status == "skipped")
            # the prompt asks for the speed exactly as the step list writes it
            assert "Mount in orientation 1, spin at 18.85 rad/s" in text_of(app, "#prompt")
            assert "18.85" in str(steps.get_option_at_index(2).prompt)
            await pilot.press("f")  # 1 row: too few to fit
            await wait_for(pilot, lambda: any("at least" in n.message for n in app._notifications))
            assert screen_name(app) == "CentrifugeScreen"
            await pilot.press("a")
            await wait_for(pilot, lambda: screen_name(app) == "ConfirmScreen")
            await pilot.press("y")
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")

    asyncio.run(story())


def test_centrifuge_live_run_to_a_saved_result(tmp_path):
    """The demo operator mounts and spins the simulated centrifuge; each row is averaged at
    speed; the table is fitted (P2 exact) and saved."""
    db = str(tmp_path / "station.db")

    async def story():
        clock = BenchClock()
        src = SimSource(seed=2, procedure="accel-centrifuge", clock=clock)
        app = make_app(db, device=src, demo=True, average_s=1.0, settle_s=0.5)
        app.session.extra["n_orientations"] = 4  # 12 rows: the exact fit needs more than 9
        async with app.run_test(size=SIZE) as pilot:
            await run_bench(
                pilot, src, clock, lambda: screen_name(app) == "CentrifugeScreen" and app.screen.updates > 2
            )
            scr = app.screen
            await run_bench(
                pilot,
                src,
                clock,
                lambda: (
                    scr.last_status is not None
                    and scr.last_status.phase == "average"
                    or screen_name(app) == "ResultsScreen"
                ),
                step_s=0.1,
            )
            await run_bench(pilot, src, clock, lambda: screen_name(app) == "ResultsScreen", step_s=0.25)
            await wait_for(pilot, lambda: app.screen.calibration_id is not None)
            summary = words_of(app, "#summary")
            return screen_lines(app)[0], summary, app.screen.result, scr.guide, app.screen.capture

    title, summary, result, guide, capture = asyncio.run(story())
    assert "P2 centrifuge result" in title and result["n_positions"] == 12
    assert "· 12 rows ·" in summary  # rows of the table, not "positions"
    # every row at the asked speed as the gyro measured it
    for s in guide.steps:
        assert s.how == "live" and abs(s.rate_gyro_rad_s / s.speed_rad_s - 1) < 0.02
    assert capture.meta["speed_source"].startswith("set point, confirmed by the gyro")
    from db.store import Store

    hist = Store(db).history("SIM-CFG-0002")
    assert len(hist) == 1 and hist[0]["procedure"] == "accel-centrifuge"


def test_gyro_noise_run_shows_the_allan_deviation_and_the_p4_time(tmp_path):
    """Connect → "Gyro noise (Allan) run" → the still hold → the result: a log-log plot per
    axis, ARW and bias instability per axis; typing an accuracy gives the P4 time; export
    writes the recording and the report."""

    async def story():
        app = make_app(None, average_s=200.0)
        app.session.extra["export_dir"] = str(tmp_path)
        async with app.run_test(size=SIZE) as pilot:
            src, clock = await start_on_sim(
                pilot, app, "gyro-noise", 4, lambda: screen_name(app) == "NoiseHoldScreen" and app.screen.updates > 2
            )
            assert "gyro noise (Allan) run" in screen_lines(app)[0]
            await run_bench(pilot, src, clock, lambda: screen_name(app) == "AllanScreen", step_s=1.0)
            scr = app.screen
            await wait_for(pilot, lambda: "ARW" in text_of(app, "#table"))
            table = text_of(app, "#table")
            assert all(f"   {ax}  " in table for ax in "xyz") and "P4 needs" in table
            # the axes said: the device's, while the hold before showed P4's body axes
            assert "axes as the device reports them" in table
            # the plot is painted on its own refresh: wait for its title
            await wait_for(pilot, lambda: "Allan deviation" in "\n".join(screen_lines(app)[1:3]))
            await wait_for(pilot, lambda: "t Accuracy" in screen_lines(app)[-1])
            assert "e Export" in screen_lines(app)[-1]
            r = scr.report
            assert r.duration_s >= 200.0 and np.all(np.isfinite(r.arw_deg_rt_h))
            await pilot.press("t")
            scr.query_one("#accuracy").value = ""
            await pilot.press(*"abc", "enter")
            await wait_for(pilot, lambda: "positive number" in text_of(app, "#status"))
            await pilot.press("t")
            scr.query_one("#accuracy").value = ""
            await pilot.press(*"5", "enter")
            await wait_for(pilot, lambda: scr.accuracy_deg_h == 5.0 and "1σ ≤ 5 °/h" in text_of(app, "#status"))
            # the line under the table agrees with its "P4 needs" column: the axes that never
            # get there are named, the others' times repeated
            rows = text_of(app, "#table").splitlines()[1:4]
            never = [row.split()[0] for row in rows if row.rstrip().endswith("never")]
            status = words_of(app, "#status")
            assert status.startswith("No still P4 record" if never else "For 1σ ≤ 5 °/h")
            assert all(f" {ax} " in status for ax in never)
            await pilot.press("e")
            await wait_for(pilot, lambda: len(scr.exported) == 2)
            return scr.exported, r

    paths, report = asyncio.run(story())
    from station.capture import read_capture

    cap = read_capture(paths[0])
    assert cap.meta["run"] == "gyro-noise" and cap.n_rows == pytest.approx(report.duration_s * 100, abs=2)
    js = json.loads(open(paths[1], encoding="utf-8").read())
    assert js["kind"] == "gyro-noise" and js["accuracy_deg_h"] == 5.0


def test_the_allan_result_survives_a_resized_terminal(tmp_path):
    """Resizing the terminal on the Allan result (or giving its plot rows) built the log-log
    figure again: plotext had taken the log of its data in place, took the log of the logs
    and the TUI stopped with a math domain error (τ < 1 s)."""
    from station.capture import read_capture
    from station.procedures.noise import noise_report
    from station.screens.noise import AllanScreen
    from tests.station_run import run_station

    path = tmp_path / "still.csv"
    assert run_station("simulate", "--procedure", "gyro-drift", "--seed", 400003, "--out", path).returncode == 0
    cap = read_capture(path)
    gyro = np.column_stack([cap.columns[c] for c in ("gx", "gy", "gz")])
    report = noise_report(gyro, float(cap.meta["sample_rate_hz"]), cap.meta.get("gyro_unit"))
    assert report.taus_s.min() < 1.0  # the logs of the shortest τ are negative

    async def story():
        app = make_app(None)
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(AllanScreen(cap, report))
            await wait_for(pilot, lambda: "Allan deviation" in "\n".join(screen_lines(app)[1:3]))
            await pilot.resize_terminal(100, 30)
            await wait_for(pilot, lambda: len(screen_lines(app)) == 30 and len(screen_lines(app)[2].rstrip()) > 80)
            await pilot.resize_terminal(*SIZE)
            await wait_for(pilot, lambda: len(screen_lines(app)) == SIZE[1])
            return screen_lines(app)

    lines = asyncio.run(story())
    plot = "\n".join(lines[1:13])
    assert "Allan deviation" in plot and "60.00" in plot and "•" in plot  # the τ axis to 60 s, the points
