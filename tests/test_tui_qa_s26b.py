"""TUI defects found by a QA pass (s26): the History plot's date axis for a calibration dated in
year 1, the export's file names stamped in UTC as everything else, and the Import screen's
wording of a slot a secondary sensor lacks. The real app through Textual's pilot, at 80x24."""

from __future__ import annotations

import asyncio
import datetime as _dt
import re
import time

from station.app import make_app
from station.timeaxis import time_axis
from tests.test_tui import SIZE, history_shown, screen_lines, text_of, wait_for
from tests.tui_data import p1_result


def test_the_history_plot_labels_a_date_in_year_1_as_a_date():
    """A capture may carry `date: 0001-01-01` (a logger's zero date): the plot's axis said
    `1-01-01` (strftime's %Y on glibc gives the year unpadded), no date anyone reads as one."""
    axis = time_axis(["0001-01-01T00:00:00Z", "0999-06-01T00:00:00Z", "2026-03-01T00:00:00Z"], n_ticks=3)
    assert axis["labels"][0] == "0001-01-01" and all(re.fullmatch(r"\d{4}-\d\d-\d\d", x) for x in axis["labels"])
    one_day = time_axis(["0001-01-01T10:00:00Z", "0001-01-01T12:00:00Z"], n_ticks=2)
    assert one_day["labels"] == ["01-01 10:00", "01-01 12:00"]  # under two days: month, day and time


def test_history_of_a_calibration_dated_year_1_shows_no_1_01_01_label(tmp_path):
    from station.store import save_result

    db = str(tmp_path / "station.db")
    for k, date in enumerate(["0001-01-01", "2026-03-01"]):
        cap, result = p1_result("IMU-1", drift=0.02 * k, date=date)
        save_result(db, cap, result, device_id="IMU-1", operator="test")

    async def story():
        app = make_app(db, start="history")
        async with app.run_test(size=SIZE) as pilot:
            await history_shown(pilot, app, 2)
            await wait_for(pilot, lambda: "2026-03-01" in text_of(app, "#plot"))
            return text_of(app, "#plot"), screen_lines(app)

    plot, lines = asyncio.run(story())
    assert not re.search(r"(?<![0-9])1-01-01", plot), plot
    assert "0001-01-01" in plot, plot
    assert all(len(line) <= 80 for line in lines)


def test_export_stamps_its_file_names_in_utc_as_the_station_does_elsewhere(tmp_path, monkeypatch):
    """The Results screen's export (e) named its files with the local time (`now()`), while the
    database, captures, reports and `station export` (the calibration's `time`) say UTC. On a
    computer set to UTC+14 the stamp was 14 hours off the UTC time everywhere else."""
    from station.screens.results import ResultsScreen

    monkeypatch.setenv("TZ", "Etc/GMT-14")  # POSIX sign: 14 hours ahead of UTC
    time.tzset()
    cap, result = p1_result("IMU-7")

    async def story():
        app = make_app(str(tmp_path / "station.db"), device_id="IMU-7")
        app.session.extra["export_dir"] = str(tmp_path)
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(pilot, lambda: app.screen.query_one("#params").row_count > 0)
            await pilot.press("e")
            await wait_for(pilot, lambda: getattr(app.screen, "exported", None))
            return app.screen.exported

    try:
        assert time.localtime().tm_gmtoff == 14 * 3600
        before = _dt.datetime.now(_dt.UTC).replace(microsecond=0)
        paths = asyncio.run(story())
        after = _dt.datetime.now(_dt.UTC)
    finally:
        monkeypatch.undo()
        time.tzset()
    stamps = {re.search(r"-(\d{8}-\d{6})Z\.(csv|json)$", p)[1] for p in paths}
    assert len(stamps) == 1 and len(paths) == 2, paths
    stamped = _dt.datetime.strptime(stamps.pop(), "%Y%m%d-%H%M%S").replace(tzinfo=_dt.UTC)
    assert before <= stamped <= after, (before, stamped, after)
