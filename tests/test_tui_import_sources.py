"""TUI Import: the source a log is read from, as `station import --source` reads it (s29-io).

The screen offered a source choice for PX4 logs only ('PX4: auto', 'raw topics', 'combined'),
from a list of its own, while the command line read ArduPilot DataFlash logs from IMU, ACC/GYR
(--source raw) and now the batch sampler's ISBH/ISBD (--source batch). Both now read one
registry (station.importers.options.SOURCES). And a log that names no device (ArduPilot) could be
calibrated on the screen but never saved ("the capture names no device"): the screen asks for the
device id where the log gives none, as `station import --device` does.

The .bin is WRITTEN BY PYMAVLINK'S OWN DataFlash encoder (tests/test_import_ardupilot_batch.py's
BatchWriter, on test_import_ardupilot's DataFlashWriter): a tabletop run in ISBH/ISBD blocks with
IMU records beside it 1 m/s^2 off, so that the two sources cannot be taken for each other.
"""

from __future__ import annotations

import asyncio
import json
import sqlite3

import numpy as np

from station.app import make_app
from station.importers.options import SOURCES, source_values
from station.screens.importfile import source_options
from tests.station_run import run_station
from tests.test_import_ardupilot_batch import _write_batch_log
from tests.test_tui import SIZE, screen_lines, screen_name, text_of, wait_for
from tests.test_tui_import import _open, _settled


def _found(app) -> str:
    return " ".join(str(app.screen.query_one("#found").render()).split())


def test_the_command_line_and_the_screen_read_one_registry_of_sources():
    """`station import --source` takes every source the registry has, the screen offers each
    format's (its words, the same values)."""
    from station.cli import build_parser

    parser = build_parser()
    imp = next(a for a in parser._subparsers._group_actions[0].choices["import"]._actions if a.dest == "source")
    assert tuple(imp.choices) == source_values() and {"auto", "raw", "combined", "batch"} <= set(imp.choices)
    for fmt, sources in SOURCES.items():
        assert source_options(fmt) == [(s.label, s.value) for s in sources]
        assert all(s.value in imp.help for s in sources)
        assert all(len(s.label) <= 12 for s in sources)  # the choice is 16 columns at 80x24


def test_a_batch_log_is_read_from_the_source_picked_and_its_calibration_saved(tmp_path):
    log = tmp_path / "00000031.BIN"
    w = _write_batch_log(log, 700201, imu_hz=50)
    db = tmp_path / "station.db"

    async def story():
        app = make_app(str(db))
        out = {}
        async with app.run_test(size=SIZE) as pilot:
            await _open(pilot, app, log)
            out["auto"] = _found(app)
            out["screen_auto"] = screen_lines(app)
            out["options"] = [(str(label), value) for label, value in app.screen.query_one("#source")._options]
            app.screen.query_one("#source").value = "batch"
            await wait_for(pilot, lambda: "ISBD accel[0]" in _found(app) and _settled(app), timeout_s=60)
            out["batch"] = _found(app)
            out["screen"] = screen_lines(app)
            app.screen.query_one("#procedure").value = "accel-tabletop"
            await wait_for(pilot, lambda: app.screen.query_one("#device-id").display)
            app.screen.query_one("#device-id").value = "quad-7-imu0"
            await pilot.press("f5")
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen" and screen_lines(app), timeout_s=120)
            await pilot.press("s")
            await wait_for(pilot, lambda: app.screen.calibration_id is not None, timeout_s=60)
            out["saved"] = text_of(app, "#saved")
        return out

    out = asyncio.run(story())
    assert out["options"] == [("AP: auto", "auto"), ("ACC/GYR", "raw"), ("IMU", "combined"), ("ISB batch", "batch")]
    # auto: the IMU records, and the batches named in the screen's words (not the flag)
    assert "(IMU[0])" in out["auto"], out["auto"]
    assert "the log also has ISBH/ISBD batches of raw IMU samples: source 'ISB batch' reads them" in out["auto"]
    assert "--source" not in out["auto"]
    choice = next(line for line in out["screen_auto"] if "Calibrate [F5]" in line)
    assert "AP: auto" in choice and "PX4" not in choice, choice  # the choice said 'PX4: auto' on an ArduPilot log
    assert "device id, needed to save" in "\n".join(out["screen_auto"])  # the log names no device
    assert f"accel {len(w.acc)} samples, 1000 Hz" in out["batch"] and "(ISBD accel[0])" in out["batch"], out["batch"]
    screen = "\n".join(out["screen"])
    assert "ISB batch" in screen and all(len(line) <= 80 for line in out["screen"]), screen  # the choice, at 80x24
    assert "Saved" in out["saved"], out["saved"]

    with sqlite3.connect(db) as conn:
        conn.row_factory = sqlite3.Row
        caps = conn.execute("SELECT * FROM captures").fetchall()
        cals = conn.execute("SELECT * FROM calibrations").fetchall()
    assert len(caps) == 1 and len(cals) == 1
    cap, cal = caps[0], cals[0]
    assert (cap["device_id"], cap["procedure"], cap["n_rows"]) == ("quad-7-imu0", "accel-tabletop", len(w.acc))
    assert json.loads(cap["meta"])["import_source"] == "ISBD accel[0]"
    assert (cal["device_id"], cal["accepted"], cal["capture_id"]) == ("quad-7-imu0", 1, cap["id"])
    # the calibration saved is the command line's of the same source, and its truth within its uncertainty
    cli = run_station("calibrate", log, "--procedure", "accel-tabletop", "--source", "batch", "--json")
    assert cli.returncode == 0, cli.stderr
    want = json.loads(cli.stdout)
    params, sigma = json.loads(cal["params"]), json.loads(cal["uncertainty"])
    np.testing.assert_allclose(params["B"], want["params"]["B"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(params["M"], want["params"]["M"], rtol=0, atol=1e-12)
    assert np.all(np.abs(np.array(params["B"]) - w.B) <= 3 * np.array(sigma["B"])), (params["B"], sigma["B"])
    np.testing.assert_allclose(params["M"], w.M, atol=0.01)
