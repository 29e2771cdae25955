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
def test_tabletop_snapshot(snap_compare, size):
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
        # the guide's events (and their notices) are posted before the update that carries
        # this time: once it is shown, nothing more is on its way
        await _settle(
            pilot, lambda: app.screen.last_status is not None and app.screen.last_status.t_s >= clock.t - 1e-6
        )
        app.clear_notifications()

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_results_snapshot(snap_compare, size):
    from station.screens.results import ResultsScreen
    from tests.tui_data import p1_result

    cap, result = p1_result()
    app = make_app(None, device_id=cap.meta["device"])

    async def run_before(pilot):
        await app.push_screen(ResultsScreen(cap, result, None, None))
        # drawn in one go once the device's record is read (a worker)
        await _settle(pilot, lambda: app.screen.query_one("#params").row_count > 0)

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_history_snapshot(snap_compare, size, tmp_path, monkeypatch):
    """The due line counts days from the clock: held at the day the picture was taken, or the
    picture would change every day ("overdue by 1005 d")."""
    from datetime import UTC, datetime

    from tests.tui_data import seed_history

    monkeypatch.setattr("db.params.now_utc", lambda: datetime(2026, 11, 29, 12, 0, tzinfo=UTC))
    db = str(tmp_path / "station.db")
    seed_history(db, "IMU-7", n=3, interval_days=365, start_year=2021)
    app = make_app(db, start="history")

    async def run_before(pilot):
        await _settle(
            pilot,
            lambda: (
                type(app.screen).__name__ == "HistoryScreen" and app.screen.query_one("#calibrations").row_count == 3
            ),
        )
        # three workers: the devices, the device's history and drift (rows and plot in one
        # handler), and the app's due list whose reminder is a notice: wait for all of them,
        # then take the notice away (it raced the picture when a fixed pause stood here)
        await _settle(
            pilot, lambda: len(app.screen.drift) > 0 and "IMU-7" in str(app.screen.query_one("#due").render())
        )
        await _settle(pilot, lambda: len(app.due) > 0 and len(app._notifications) > 0)
        app.clear_notifications()

    assert snap_compare(app, terminal_size=size, run_before=run_before)


def test_help_snapshot(snap_compare):
    app = make_app(None)
    assert snap_compare(app, terminal_size=(80, 24), press=["f1"])


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_centrifuge_snapshot(snap_compare, size):
    """P2 after the noise rest: row 1 typed by hand (✓), the guide waits for the change."""
    clock = FakeClock()
    src = SimSource(seed=0, clock=clock, procedure="accel-centrifuge")
    app = make_app(None, device=src, start="procedure", average_s=30.0, settle_s=1.0)

    async def run_before(pilot):
        await _settle(pilot, lambda: getattr(app.screen, "guide", None) is not None)
        guide = app.screen.guide
        for k in range(1, 6):
            clock.t = float(k)
            await _settle(pilot, lambda: guide.status().t_s >= clock.t - 0.011)
        for name, value in zip(("ax", "ay", "az", "speed"), ("1.04291", "0.24922", "2.11027", "6.2832")):
            app.screen.query_one(f"#in-{name}").value = value
        app.screen.query_one("#in-speed").focus()
        await pilot.press("enter", "escape")
        await _settle(
            pilot,
            lambda: (
                guide.n_captured == 1 and app.screen.last_status is not None and app.screen.last_status.n_captured == 1
            ),
        )
        app.clear_notifications()

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@pytest.mark.parametrize("size", SIZES, ids=lambda s: f"{s[0]}x{s[1]}")
def test_noise_snapshot(snap_compare, size):
    """The noise result for a fixed record: white noise plus a slow random walk (seeded)."""
    import numpy as np

    from station.capture import Capture
    from station.procedures.noise import noise_report
    from station.screens.noise import AllanScreen

    rng = np.random.default_rng(7)
    n, fs = 60_000, 100.0
    y = rng.normal(scale=2e-4, size=(n, 3)) + np.cumsum(rng.normal(scale=2e-8, size=(n, 3)), axis=0)
    report = noise_report(y, fs, "rad/s")
    cap = Capture(
        meta={"station-capture": "1", "procedure": "gyro-drift", "gyro_unit": "rad/s"},
        columns={"t": np.arange(n) / fs, "gx": y[:, 0], "gy": y[:, 1], "gz": y[:, 2]},
    )
    app = make_app(None, device_id="IMU-0042")

    async def run_before(pilot):
        await app.push_screen(AllanScreen(cap, report))
        await _settle(pilot, lambda: "P4 needs" in str(app.screen.query_one("#table").render()))

    assert snap_compare(app, terminal_size=size, run_before=run_before)
