"""A new user at 80x24 over SSH, and what earlier testers left open (qa-s27t): the quit
question under a toast, a diagnosis that said nothing for a minute and could not be stopped,
the Connect screen's status lines without end. The real app under its pilot, a real SQLite
file, the simulated device."""

from __future__ import annotations

import asyncio

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
