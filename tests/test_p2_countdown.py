"""P2's countdown says what holds the average back: while the centrifuge's measured rate is
not the asked speed it says so ("not at the asked speed"), not "when still" (which it said
whatever was wrong); its stillness line says "steady at speed", not "still", while the table
spins. The real app on the built-in centrifuge, its clock advanced by the test."""

from __future__ import annotations

import asyncio

from station.app import make_app
from station.sources import SimSource
from tests.test_tui import SIZE, BenchClock, run_bench, screen_name, wait_for


def test_the_countdown_names_a_wrong_speed():
    clock = BenchClock()
    src = SimSource(seed=22, clock=clock, procedure="accel-centrifuge", max_batch_s=5.0)
    seen = []

    async def story():
        app = make_app(None, device=src, average_s=2.0, settle_s=1.0)
        async with app.run_test(size=SIZE) as pilot:
            await pilot.press("f5")
            await wait_for(pilot, lambda: screen_name(app) == "CentrifugeScreen" and app.screen.guide is not None)
            g = app.screen.guide
            await run_bench(pilot, src, clock, lambda: g.phase == "change", step_s=1.0)
            await pilot.press("p")  # mount and spin up: the rate ramps through wrong speeds

            def look():
                st = app.screen.last_status
                if st is not None and st.phase in ("place", "settle", "average") and st.t_s >= clock.t_s - 0.05:
                    seen.append(
                        (
                            st.at_speed,
                            st.phase,
                            str(app.screen.query_one("#countdown").render()),
                            str(app.screen.query_one("#stability").render()),
                        )
                    )
                return g.n_captured >= 1

            await run_bench(pilot, src, clock, look, step_s=0.2, max_device_s=120)

    asyncio.run(story())
    off = [text for at_speed, _, text, _ in seen if not at_speed]
    on = [text for at_speed, phase, text, _ in seen if at_speed and phase == "place"]
    assert off and all("not at the asked speed" in t and "when still" not in t for t in off), off
    assert all("not at the asked speed" not in t for t in on), on
    # the stillness detector's line: a table spinning at a steady rate is steady (at speed),
    # never "still"
    averaging = [bar for at_speed, phase, _, bar in seen if at_speed and phase == "average"]
    assert averaging and all("steady at speed" in b for b in averaging), averaging
    assert all("still" not in b.lower() for *_, b in seen), [b for *_, b in seen if "still" in b.lower()]
