"""Snapshot tests of every screen at 80x24 and 120x40 (pytest-textual-snapshot).

Deterministic: seeded simulator on a fake clock that the test advances in 1 s steps
(waiting until the worker has consumed each step), fixed captures and database dates,
notifications cleared before the picture. Update after a deliberate UI change with
``pytest tests/test_tui_snapshots.py --snapshot-update`` and look at the report.
"""
from __future__ import annotations

import time

import pytest

from station.app import make_app
from station.sources import SimSource

SIZES = [(80, 24), (120, 40)]


class FakeClock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


async def _settle(pilot, cond, timeout_s=20.0):
    end = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > end:
            raise AssertionError("snapshot set-up timed out")
        await pilot.pause(0.02)


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_connect_snapshot(snap_compare, size):
    app = make_app(None, device=SimSource(seed=0, clock=FakeClock()))
    assert snap_compare(app, terminal_size=size)


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_procedure_snapshot(snap_compare, size):
    """The demo mid-run: x_up and x_down captured, y_up still and in position."""
    clock = FakeClock()
    src = SimSource(seed=0, clock=clock)
    app = make_app(None, device=src, demo=True, average_s=3.0, settle_s=1.0)

    async def run_before(pilot):
        await _settle(pilot, lambda: getattr(app.screen, "guide", None) is not None)
        guide = app.screen.guide
        for k in range(1, 18):  # 17 s of device time in 1 s steps, each consumed before the next
            clock.t = float(k)
            await _settle(pilot, lambda: guide.status().t_s >= clock.t - 1e-6)
        await _settle(pilot, lambda: app.screen.last_status is not None
                      and app.screen.last_status.t_s >= clock.t - 1e-6)
        await pilot.pause(0.2)
        app.clear_notifications()
        await pilot.pause(0.05)

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_results_snapshot(snap_compare, size):
    from station.screens.results import ResultsScreen

    from tests.tui_data import p1_result

    cap, result = p1_result()
    app = make_app(None, device_id=cap.meta["device"])

    async def run_before(pilot):
        await app.push_screen(ResultsScreen(cap, result, None, None))
        await _settle(pilot, lambda: app.screen.query_one("#params").row_count > 0)
        await pilot.pause(0.1)

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_history_snapshot(snap_compare, size, tmp_path):
    from tests.tui_data import seed_history

    db = str(tmp_path / "station.db")
    seed_history(db, "IMU-7", n=3, interval_days=365, start_year=2021)
    app = make_app(db, start="history")

    async def run_before(pilot):
        await _settle(pilot, lambda: type(app.screen).__name__ == "HistoryScreen"
                      and app.screen.query_one("#calibrations").row_count == 3)
        await pilot.pause(0.2)
        app.clear_notifications()
        await pilot.pause(0.05)

    assert snap_compare(app, terminal_size=size, run_before=run_before)


def test_help_snapshot(snap_compare):
    app = make_app(None)
    assert snap_compare(app, terminal_size=(80, 24), press=["f1"])
