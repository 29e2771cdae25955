"""TUI Import: a PX4 log without sensor_selection whose board has two accelerometers and two
gyros warned "give --instance N to name its slot", a command-line flag the screen had no place
for. The screen has an instance choice for PX4 logs (``station import --instance``); the
warning there names it, and picking slot 0 reads the log as `--instance 0` does: no warning,
the device named by CAL_ACC0_ID."""

from __future__ import annotations

import asyncio

import pytest

from station.app import make_app
from station.importers import load, px4
from station.importers.options import ImportOptions
from tests.test_tui import SIZE, screen_lines, text_of, wait_for
from tests.test_tui_import import PX4, _open, _settled


def _found(app) -> str:
    """The whole summary (its end is below the 24th row: the screen scrolls)."""
    return str(app.screen.query_one("#found").render())


def test_a_px4_warning_about_the_sensor_slot_is_answered_on_the_screen(tmp_path):
    log = PX4 / "sample.ulg"
    if not log.exists():
        pytest.skip("../shared/data/px4_ulog is not here")
    auto = load.read(log, ImportOptions(), "px4")
    assert any("give --instance N" in w for w in auto.warnings)  # the file still says it
    slot0 = load.read(log, ImportOptions(instance=0, procedure="accel-tabletop"), "px4")
    assert slot0.warnings == []
    want = px4.default_device(slot0, "accel")

    async def story():
        app = make_app(str(tmp_path / "s.db"))
        out = {}
        async with app.run_test(size=SIZE) as pilot:
            await _open(pilot, app, log)
            out["found"] = _found(app)
            out["screen"] = screen_lines(app)
            app.screen.query_one("#instance").value = "0"
            await wait_for(pilot, lambda: "voter" not in _found(app) and _settled(app), timeout_s=60)
            out["found0"] = _found(app)
            out["device0"] = text_of(app, "#device")
            out["status0"] = text_of(app, "#status")
        return out

    out = asyncio.run(story())
    found = " ".join(out["found"].split())
    assert "voter chose" in found and "--instance" not in found, found
    assert "pick its slot under instance" in found, found
    assert all(len(line) <= 80 for line in out["screen"])
    assert "instance auto" in "\n".join(out["screen"])  # the choice is on the screen, at 80x24
    assert "warning" not in out["found0"], out["found0"]
    assert f"device {want}" in out["device0"], out["device0"]
    assert "Pick the procedure" in out["status0"]
