"""The TUI's Import screen (F7 on Connect) with logs: a real PX4 log from ../shared/data/px4_ulog
read by the same loader as `station import`, what it found shown at 80x24, the procedure
picked, and on to a calibration (Results) or the procedure's own refusal in one line.

The ArduPilot .bin that goes all the way to Results is WRITTEN BY PYMAVLINK'S OWN DataFlash
encoder (tests/test_import_ardupilot.py's DataFlashWriter): no real ArduPilot log is in ../shared.
"""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from station.app import make_app
from station.capture import read_capture
from station.importers import load
from station.importers.options import ImportOptions
from tests.conftest import SHARED
from tests.station_run import run_station
from tests.test_import_ardupilot import PARAMS, DataFlashWriter
from tests.test_tui import SIZE, screen_lines, screen_name, text_of, wait_for, words_of

PX4 = SHARED / "data" / "px4_ulog" / "original"  # ../shared, or $STATION_SHARED for a worktree elsewhere


def _settled(app) -> bool:
    s = text_of(app, "#status").strip()
    return s != "" and "…" not in s


def still_gyro_bin(log, seed: int) -> list:
    """Write a still gyro record, 200 s at 50 Hz (a constant drift plus white noise), as an
    ArduPilot DataFlash log with pymavlink's formats; returns the gyro samples as written (float32)."""
    rng = np.random.default_rng(seed)
    w = DataFlashWriter(log)
    for name, value in PARAMS.items():
        w.param(1000, name, value)
    drift = np.array([0.002, -0.001, 0.0005])
    gyros = []
    for k in range(10_000):
        gyro = drift + rng.normal(0, 0.002, 3)
        gyros.append(np.asarray(gyro, dtype=np.float32))
        w.imu(500_000 + k * 20_000, 0, gyro, (0.0, 0.0, -9.8))
    w.close()
    return gyros


async def _open(pilot, app, path):
    await pilot.press("f7")
    await wait_for(pilot, lambda: screen_name(app) == "ImportScreen")
    app.screen.query_one("#path").value = str(path)
    await pilot.press("enter")
    await wait_for(pilot, lambda: _settled(app), timeout_s=60)


def test_a_real_px4_log_shows_what_it_holds_then_the_procedures_own_refusal(tmp_path):
    log = PX4 / "sample_log_small.ulg"
    if not log.exists():
        pytest.skip("../shared/data/px4_ulog is not here")
    # what `station import` reads from the same file: the screen must show the same
    imported = load.read(log, ImportOptions(), "px4")
    cli = run_station("calibrate", log, "--procedure", "gyro-drift")
    assert cli.returncode == 2
    assert cli.stderr.count("\n") == 1  # one line: the refusal, then the reader's warning
    refusal = cli.stderr.strip().split(": ", 1)[1].split("; warning: ")[0]  # past 'station: ', before the warning

    async def story():
        app = make_app(str(tmp_path / "s.db"))
        out = {}
        async with app.run_test(size=SIZE) as pilot:
            await _open(pilot, app, log)
            out["screen"] = "\n".join(screen_lines(app))
            out["found"] = text_of(app, "#found")
            out["device"] = text_of(app, "#device")
            out["status"] = text_of(app, "#status")
            out["options"] = [str(p[0]) for p in app.screen.query_one("#procedure")._options]
            app.screen.query_one("#procedure").value = "gyro-drift"
            await pilot.press("f5")
            await wait_for(pilot, lambda: "Calibrating" not in text_of(app, "#status"), timeout_s=60)
            out["refused"] = words_of(app, "#status")
            out["still"] = screen_name(app)
            # the board-corrected sensor_combined instead (the warning says it holds more samples)
            app.screen.query_one("#source").value = "combined"
            await wait_for(pilot, lambda: "board: true" in text_of(app, "#found"), timeout_s=60)
            out["combined"] = text_of(app, "#found")
        return out

    out = asyncio.run(story())
    found = out["found"]
    # the sensors with their device ids (the loader's), the slots' CAL_*_ID in use, the device
    for kind, s in imported.streams.items():
        assert f"{len(s.t_s)} samples" in found and str(s.device_id) in found, (kind, found)
    assert f"in use: {sum(k.startswith('param.') for k in imported.meta)} calibration parameters" in found
    assert f"CAL_ACC0_ID={imported.meta['param.CAL_ACC0_ID']}" in found.replace("\n", " ").replace("  ", " ")
    assert "sample_log_small.ulg: px4, corrected by the board: false" in found
    assert "device " + load.capture_of(log, imported, "px4", "accel-tabletop")[0].meta["device"] in out["device"]
    assert "Calibrate" in out["screen"] and "Diagnose" in out["screen"]
    assert out["options"] == ["P1 accelerometer", "P3 compass", "P4 gyro drift"]  # registry: code, short
    # 80x24: every line of what it found fits (nothing cut at the right edge)
    assert all(len(line) <= 80 for line in out["screen"].splitlines())
    # the calibration's own refusal, the same words as the command line's, one line
    assert " ".join(refusal.split()).replace(" ", "") in out["refused"].replace(" ", "")
    assert out["still"] == "ImportScreen"
    combined = load.read(log, ImportOptions(source="combined"), "px4")
    assert "corrected by the board: true" in out["combined"]
    assert f"accel {len(combined.streams['accel'].t_s)} samples" in out["combined"]


def test_a_dataflash_log_goes_on_to_results_and_to_a_diagnosis(tmp_path):
    """A still gyro record of 200 s at 50 Hz in a .bin: picked as gyro drift, the screen hands
    the capture the loader built to the Results screen (the drift equals the mean of the log's
    gyro samples), and Diagnose opens the diagnosis of the same capture."""
    log = tmp_path / "00000007.BIN"
    gyros = still_gyro_bin(log, seed=11)

    async def story():
        app = make_app(str(tmp_path / "s.db"))
        out = {}
        async with app.run_test(size=SIZE) as pilot:
            await _open(pilot, app, log)
            out["found"] = text_of(app, "#found")
            app.screen.query_one("#procedure").value = "gyro-drift"
            await pilot.press("f6")
            await wait_for(pilot, lambda: screen_name(app) == "DiagnoseScreen", timeout_s=60)
            out["diag_capture"] = app.screen.capture
            await pilot.press("escape")
            await wait_for(pilot, lambda: screen_name(app) == "ImportScreen")
            await pilot.press("f5")
            # pushed is not yet drawn: on a loaded machine the first lines were read before the
            # compositor had any (IndexError)
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen" and screen_lines(app), timeout_s=120)
            out["title"] = screen_lines(app)[0]
            out["result"] = app.screen.result
        return out

    out = asyncio.run(story())
    assert "10000 samples, 50 Hz" in out["found"] and "00000007.BIN: ardupilot, corrected" in out["found"]
    assert "INS_GYR_ID=2752772" in out["found"]
    # the capture is the one `station import --procedure gyro-drift` writes
    cli = tmp_path / "cli.csv"
    assert run_station("import", log, "--procedure", "gyro-drift", "--out", cli).returncode == 0
    want = read_capture(cli)
    got = out["diag_capture"]
    assert got.meta["procedure"] == "gyro-drift" and got.meta == want.meta
    assert set(got.columns) == set(want.columns)
    for name in want.columns:
        np.testing.assert_array_equal(got.columns[name], want.columns[name])
    assert "P4" in out["title"] or "drift" in out["title"].lower()
    mean = np.mean(np.asarray(gyros, dtype=np.float64), axis=0)
    # on the log's own axes (x forward, y right, z down); in P4's frame (x forward, y up, z right)
    np.testing.assert_allclose(out["result"]["drift_raw"]["value"], mean, rtol=0, atol=1e-9)
    np.testing.assert_allclose(out["result"]["params"]["drift"], [mean[0], -mean[2], mean[1]], rtol=0, atol=1e-9)


def test_a_six_position_capture_offers_the_six_position_fit_on_f8(tmp_path, shared_data):
    """imucal's labelled Ferraris session (6 ±axis positions): the norm fit refuses it and
    pointed to '--method six-position', a CLI option the TUI had no way to give. The refusal
    now offers F8 (in the footer only then), which fits it that way, on to Results."""
    path = shared_data / "imucal_ferraris" / "imucal_ferraris_labelled.capture.csv"

    async def story():
        app = make_app(str(tmp_path / "s.db"))
        async with app.run_test(size=SIZE) as pilot:
            await pilot.press("f7")
            await wait_for(pilot, lambda: screen_name(app) == "ImportScreen")
            assert "f8" not in screen_lines(app)[-1].lower()  # nothing to offer yet
            app.screen.query_one("#path").value = str(path)
            await pilot.press("enter")
            await wait_for(pilot, lambda: "F8" in text_of(app, "#status"), timeout_s=120)
            status = words_of(app, "#status")
            footer = screen_lines(app)[-1]
            await pilot.press("f8")
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen", timeout_s=120)
            await wait_for(pilot, lambda: " RMS " in "\n".join(screen_lines(app)))
            return status, footer, app.screen.result

    status, footer, result = asyncio.run(story())
    assert "the norm-condition fit needs at least 9" in status
    assert status.endswith("F8 calibrates it with the six-position method instead.")
    assert "f8 Six-position fit" in footer
    # the same result as the CLI's --method six-position on the same file
    cli = run_station("calibrate", path, "--method", "six-position", "--json")
    assert cli.returncode == 0, cli.stderr
    import json

    want = json.loads(cli.stdout)
    assert result["method"] == want["method"]
    np.testing.assert_allclose(np.array(result["params"]["B"]), want["params"]["B"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.array(result["params"]["M"]), want["params"]["M"], rtol=0, atol=1e-12)


def test_warnings_past_the_two_shown_are_counted_not_dropped():
    """The summary has room for two warnings at 80x24; the rest are said by count, with the
    command that prints them all (they were dropped without a word)."""
    from station.importers._common import Imported, Stream
    from station.screens.importfile import WIDTH, summary_lines

    t = np.arange(100) / 100.0
    stream = Stream("gyro", t, np.zeros((100, 3)), "rad/s", "raw")
    warnings = [f"warning number {i}" for i in range(5)]
    lines = summary_lines("/logs/flight 12.ulg", "ulog", Imported({"gyro": stream}, {}, warnings))
    text = "\n".join(lines)
    assert "warning number 0" in text and "warning number 1" in text and "warning number 2" not in text
    assert "… and 3 more warnings: station import flight 12.ulg prints them all" in text
    assert all(len(line) <= WIDTH for line in lines)
    two = summary_lines("/logs/a.ulg", "ulog", Imported({"gyro": stream}, {}, warnings[:2]))
    assert not any("more warning" in line for line in two)


def test_a_missing_csv_is_said_missing_without_the_plain_csv_route(tmp_path):
    """F7, a mistyped `/tmp/nonexistent.csv`, Enter: "no such file" came with three lines on
    naming a plain CSV's columns with `station import --map` (the route for a CSV the reader
    cannot name), which sends a new user off to the shell for a typo. A file that is not there
    is said so, alone."""

    async def story():
        app = make_app(str(tmp_path / "s.db"))
        async with app.run_test(size=SIZE) as pilot:
            await _open(pilot, app, tmp_path / "nonexistent.csv")
            return words_of(app, "#status")

    status = asyncio.run(story())
    assert "no such file" in status, status
    assert "plain CSV" not in status and "--map" not in status, status
