"""What a bench engineer new to the station met on the TUI at 80x24 (real app under its
pilot, the built-in simulated device on a clock the test advances)."""

from __future__ import annotations

import asyncio

from station.app import make_app
from station.sources import SimSource
from tests.test_tui import SIZE, BenchClock, run_bench, text_of, wait_for


def test_p1_quarter_turn_prompt_is_shown_whole_at_80x24():
    """Asked for x_up with the unit on y_up, the prompt was cut at the panel's edge:
    "Wrong face up: 90° off, a quarter turn; put the face" (the rest, "shown up", lost)."""

    async def story():
        clock = BenchClock()
        src = SimSource(seed=1, clock=clock)
        app = make_app(None, device=src, start="procedure", average_s=60.0)
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: getattr(app.screen, "guide", None) is not None)
            src.place("y_up")  # asked for x_up: a quarter turn off
            await run_bench(pilot, src, clock, lambda: "quarter turn" in app.screen.guide.status().message)
            message = app.screen.guide.status().message
            await wait_for(pilot, lambda: "quarter turn" in text_of(app, "#message"))
            shown = " ".join(text_of(app, "#message").split())
            assert shown == message, (shown, message)

    asyncio.run(story())
