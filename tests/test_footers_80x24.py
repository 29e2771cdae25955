"""Every screen's footer at 80 columns shows every key it offers, whole: the screen's own
bindings (the simulated bench's keys included), then ^q Quit and f1 Help last. It used to
cut the last ones ("^q Qu", "n New" on Results). The real app under its pilot; the screens
of the procedures on the built-in device (a clock the test never advances: nothing needs
to happen for a footer), Results of a P1, History of a seeded database."""

from __future__ import annotations

import asyncio

import pytest

from station.app import make_app
from station.sources import SimSource
from tests.test_tui import BenchClock, screen_lines, screen_name, wait_for
from tests.tui_data import p1_result, seed_history

SIZE = (80, 24)


def shown_keys(app) -> list[str]:
    """'key label' of every binding the footer should show on the current screen."""
    out = []
    for active in app.screen.active_bindings.values():
        b = active.binding
        if b.show and active.enabled:
            out.append(f"{app.get_key_display(b)} {b.description}")
    return out


def footer_line(app) -> str:
    return screen_lines(app)[-1]


def check(app) -> tuple[list[str], str]:
    keys, line = shown_keys(app), footer_line(app)
    return [k for k in keys if k not in line], line


@pytest.mark.parametrize(
    "procedure",
    ["accel-tabletop", "accel-centrifuge", "compass", "gyro-drift", "gyro-reference", "gyro-noise", "ldv"],
)
def test_a_procedures_footer_fits(procedure):
    async def story():
        src = SimSource(seed=1, procedure=procedure, clock=BenchClock())
        app = make_app(None, device=src)
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: "f5 Start" in footer_line(app))
            missing, line = check(app)
            assert not missing, (missing, line)
            await pilot.press("f5")
            await wait_for(
                pilot,
                lambda: screen_name(app) != "ConnectScreen" and getattr(app.screen, "guide", None) is not None,
            )
            await wait_for(pilot, lambda: "f1 Help" in footer_line(app))
            return check(app), screen_name(app)

    (missing, line), name = asyncio.run(story())
    assert not missing, (name, missing, line)
    assert line.rstrip().endswith("^q Quit f1 Help"), line
    if procedure in ("accel-tabletop", "compass", "gyro-reference", "ldv"):
        assert "(sim)" in line  # the simulated bench's keys are there, whole


def test_results_and_history_footers_fit(tmp_path):
    from station.screens.results import ResultsScreen

    db = str(tmp_path / "s.db")
    seed_history(db, "IMU-7", n=2)

    async def story():
        app = make_app(db, start="history")
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: screen_name(app) == "HistoryScreen" and "l Limits" in footer_line(app))
            history = check(app)
            cap, result = p1_result("IMU-8")
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen" and "s Save" in footer_line(app))
            return history, check(app)

    history, results = asyncio.run(story())
    for missing, line in (history, results):
        assert not missing, (missing, line)
        assert line.rstrip().endswith("^q Quit f1 Help"), line
    assert "n New run" in results[1]
