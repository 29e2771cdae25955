"""TUI Import: a PX4 log without sensor_selection whose board has two accelerometers and two
gyros warned "give --instance N to name its slot", a command-line flag the screen had no place
for. The screen has an instance choice for PX4 logs (``station import --instance``); the
warning there names it, and picking slot 0 reads the log as `--instance 0` does: no warning,
the device named by CAL_ACC0_ID. ArduPilot .bin and MAVLink .tlog logs with two IMUs get the
same choice and a warning that names it (they were read as instance 0 without a word)."""

from __future__ import annotations

import asyncio
import struct

import numpy as np
import pytest

from station.app import make_app
from station.capture import read_capture
from station.importers import load, px4
from station.importers.options import ImportOptions
from tests.station_run import assert_one_line_refusal, run_station
from tests.test_import_ardupilot import write_bin, write_tlog
from tests.test_tui import SIZE, screen_lines, text_of, wait_for, words_of
from tests.test_tui_import import PX4, _open, _settled


def _found(app) -> str:
    """The whole summary (its end is below the 24th row: the screen scrolls)."""
    return str(app.screen.query_one("#found").render())


def _pick_instance(log, instance: str, done, tmp_path) -> dict:
    """Import ``log`` on the real app, set the instance choice to ``instance``, wait until
    ``done(app)``: the summary and screen before; the summary, status (white space folded),
    device line, choice and screen after."""

    async def story():
        app = make_app(str(tmp_path / "s.db"))
        out = {}
        async with app.run_test(size=SIZE) as pilot:
            await _open(pilot, app, log)
            out["found"] = _found(app)
            out["screen"] = screen_lines(app)
            app.screen.query_one("#instance").value = instance
            await wait_for(pilot, lambda: done(app), timeout_s=60)
            out["after"] = _found(app)
            out["status"] = words_of(app, "#status")
            out["device"] = text_of(app, "#device")
            out["value"] = app.screen.query_one("#instance").value
            out["screen_after"] = screen_lines(app)
        return out

    return asyncio.run(story())


def test_a_px4_warning_about_the_sensor_slot_is_answered_on_the_screen(tmp_path):
    log = PX4 / "sample.ulg"
    if not log.exists():
        pytest.skip("../shared/data/px4_ulog is not here")
    auto = load.read(log, ImportOptions(), "px4")
    assert any("give --instance N" in w for w in auto.warnings)  # the file still says it
    slot0 = load.read(log, ImportOptions(instance=0, procedure="accel-tabletop"), "px4")
    # the one warning left is sample.ulg's own dropouts (tests/test_import_px4.py), not the slot
    assert [w for w in slot0.warnings if "the logger dropped messages" not in w] == [], slot0.warnings
    want = px4.default_device(slot0, "accel")

    out = _pick_instance(log, "0", lambda app: "voter" not in _found(app) and _settled(app), tmp_path)
    found = " ".join(out["found"].split())
    assert "voter chose" in found and "--instance" not in found, found
    assert "pick its slot under instance" in found, found
    assert all(len(line) <= 80 for line in out["screen"])
    assert "instance auto" in "\n".join(out["screen"])  # the choice is on the screen, at 80x24
    assert "voter" not in out["after"] and "pick its slot" not in out["after"], out["after"]
    assert f"device {want}" in out["device"], out["device"]
    assert "Pick the procedure" in out["status"], out["status"]


# ------------------------------------------------------------------------- ArduPilot and MAVLink
# .bin and .tlog WRITTEN BY PYMAVLINK'S OWN encoders (tests/test_import_ardupilot.py): two IMUs
# each, instance 0 and 1 (INS_ACC_ID 2753028, INS_ACC2_ID 2818564).


@pytest.mark.parametrize("suffix", ["bin", "tlog"])
def test_an_ardupilot_log_with_two_imus_says_so_and_offers_the_instance(tmp_path, suffix):
    """A .bin / .tlog with two IMUs was read as instance 0 without a word, on the command line
    and on the screen, and the screen had no instance choice (PX4 logs had one)."""
    log = tmp_path / f"two_imus.{suffix}"
    if suffix == "bin":
        write_bin(log)
    else:
        write_tlog(log, second_imu=True)
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", tmp_path / "c.csv")
    assert res.returncode == 0, res.stderr
    assert "2 IMUs (instances 0, 1): instance 0 read; give --instance N to name its slot" in res.stderr, res.stderr
    one = run_station("import", log, "--procedure", "accel-tabletop", "--instance", "1", "--out", tmp_path / "1.csv")
    assert one.returncode == 0 and "IMUs" not in one.stderr, one.stderr  # named: nothing to say
    second = "IMU[1]" if suffix == "bin" else "SCALED_IMU2"

    out = _pick_instance(log, "1", lambda app: second in _found(app) and _settled(app), tmp_path)
    found = " ".join(out["found"].split())
    assert "2 IMUs (instances 0, 1): instance 0 read; pick its slot under instance" in found, found
    assert "--instance" not in found
    shown = "\n".join(out["screen"])
    assert "instance auto" in shown and all(len(line) <= 80 for line in out["screen"]), shown
    after = " ".join(out["after"].split())
    assert "accel 100 samples" in after or "accel 200 samples" in after, after
    assert "id 2818564" in after and "IMUs" not in after, after  # INS_ACC2_ID: the second IMU
    if suffix == "bin":  # one compass: instance 1 has none, and says so
        # in the screen's terms: the slot picked under instance, not station import's flag
        assert "warning: instance 1 (the slot picked): no MAG[1] (its instances: 0), so no mag columns" in after, after
        assert "--instance" not in after, after
    else:
        assert "warning" not in after, after
    assert "Pick the procedure" in out["status"], out["status"]


def test_an_instance_the_log_lacks_leaves_the_read_shown_and_says_so(tmp_path):
    """Instance 2 of a two-IMU .bin is refused in one line; the choice went on saying
    'instance 2' over the instance-0 read that F5 would still have calibrated."""
    log = tmp_path / "two_imus.bin"
    write_bin(log)
    out = _pick_instance(log, "2", lambda app: "instance 2" in text_of(app, "#status"), tmp_path)
    assert "instance 2 (the slot picked): the log has IMU instances 0, 1" in out["status"], out["status"]
    assert "--instance" not in out["status"], out["status"]
    assert out["value"] == "auto"
    # the source too, now that an ArduPilot log has a source choice (its words on the screen)
    assert "Still shown: the log as read with instance auto, source 'AP: auto'." in out["status"], out["status"]
    assert "IMU[0]" in out["after"]
    assert all(len(line) <= 80 for line in out["screen_after"])


def test_a_px4_log_with_three_imus_on_the_raw_topics_says_so(tmp_path):
    """sample_log_small.ulg (a CubeOrange) logs sensor_accel and sensor_gyro three times and
    sensor_mag twice: the raw topics were read as instance 0 without a word (the sensor_combined
    path said which slot to name)."""
    log = PX4 / "sample_log_small.ulg"
    if not log.exists():
        pytest.skip("../shared/data/px4_ulog is not here")
    said = (
        "the log has 3 sensor_accel (instances 0, 1, 2), 3 sensor_gyro (instances 0, 1, 2) and "
        "2 sensor_mag (instances 0, 1): instance 0 read; "
    )
    res = run_station("import", log, "--procedure", "accel-tabletop", "--out", tmp_path / "c.csv")
    assert res.returncode == 0 and said + "give --instance N to name its slot" in res.stderr, res.stderr
    one = run_station("import", log, "--procedure", "accel-tabletop", "--instance", "1", "--out", tmp_path / "1.csv")
    assert one.returncode == 0 and "the log has" not in one.stderr, one.stderr

    out = _pick_instance(log, "1", lambda app: "sensor_accel[1]" in _found(app) and _settled(app), tmp_path)
    assert said + "pick its slot under instance" in " ".join(out["found"].split()), out["found"]
    assert "the log has" not in out["after"], out["after"]


def test_an_ardupilot_log_whose_imus_start_above_0_is_read_from_its_first(tmp_path):
    """Without --instance, a .bin whose IMUs are instances 1 and 2 was refused "accel-tabletop
    needs accelerometer data; this file has magnetometer" (instance 0 of each, and only the
    compass had one), and a .tlog with only SCALED_IMU2 "no RAW_IMU / SCALED_IMU / HIGHRES_IMU
    messages": errors on the first read, before the screen could offer an instance. They read
    from the first instance the log has, as PX4's raw topics do; an --instance a sensor lacks
    says which it has."""
    from pymavlink import mavutil

    from tests.test_import_ardupilot import PARAMS, DataFlashWriter

    bin_log = tmp_path / "from1.bin"
    w = DataFlashWriter(bin_log)
    for name, value in PARAMS.items():
        w.param(1000, name, value)
    for k in range(100):
        for i in (1, 2):
            w.imu(500_000 + k * 2500, i, (0.0, 0.0, 0.0), (0.0, 0.0, -9.8))
        if k % 4 == 0:
            w.mag(500_100 + k * 2500, 0, (200, -150, 420))
    w.close()
    tlog = tmp_path / "only2.tlog"
    out = mavutil.mavlogfile(str(tlog), write=True, source_system=1, source_component=1)
    for k in range(50):
        out.write(struct.pack(">Q", int((1.7e9 + k * 0.02) * 1e6)))
        out.mav.scaled_imu2_send(1000 + k * 20, 11, 12, -990, 1, 2, 3, 0, 0, 0)
    out.close()

    res = run_station("import", bin_log, "--procedure", "accel-tabletop", "--out", tmp_path / "b.csv")
    assert res.returncode == 0, res.stderr
    assert "the log has 2 IMUs (instances 1, 2): instance 1 (IMU), 0 (compass) read" in res.stderr, res.stderr
    assert read_capture(tmp_path / "b.csv").meta["sensor_device_id"] == str(PARAMS["INS_ACC2_ID"])
    res = run_station("import", tlog, "--procedure", "accel-tabletop", "--out", tmp_path / "t.csv")
    assert res.returncode == 0, res.stderr
    assert np.all(read_capture(tmp_path / "t.csv").columns["az"] == -990)  # SCALED_IMU2's
    asked = run_station("import", bin_log, "--procedure", "accel-tabletop", "--instance", "0", "--out", tmp_path / "x")
    assert_one_line_refusal(asked, "--instance 0: no IMU[0] (its instances: 1, 2), so no accel and gyro columns")
    asked = run_station("import", tlog, "--procedure", "accel-tabletop", "--instance", "0", "--out", tmp_path / "x")
    assert_one_line_refusal(asked, "no RAW_IMU / SCALED_IMU / HIGHRES_IMU messages", "it has IMU instances 1")
    # the screen reads it too, and offers the instance
    seen = _pick_instance(bin_log, "2", lambda app: "IMU[2]" in _found(app) and _settled(app), tmp_path)
    assert "accel 100 samples" in seen["found"] and "IMU[1]" in seen["found"], seen["found"]
