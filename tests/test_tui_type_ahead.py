"""Keys typed ahead: a burst of keys (a paste without bracketed paste, `tmux send-keys F7 'path'
Enter`, a fast typist) that opens a screen and types into its field. Textual sent every key of
the burst to the widget focused when it was read, and ran a screen's own binding (F7 Import,
l Limits) only once that key had bubbled back to the App: the text after it had gone to the old
screen's button or table, came back up after the new screen opened, and was dropped there
(qa-s25b). The App now hands the widgets one key at a time (station.app.StationApp.on_event).

The burst is posted into the real app's queue as its terminal driver posts what one read gives,
with no pause between keys (Pilot.press waits for the app to be idle after each key, which hides
the fault); tests/test_e2e_tmux.py sends the same burst through tmux."""

from __future__ import annotations

import asyncio

from textual import events

from station.app import make_app
from tests.station_run import run_station
from tests.test_tui import SIZE, screen_name, text_of, wait_for


def _burst(app, *keys: str) -> None:
    """``keys`` as one read from the terminal: Textual key names, or text typed character by character."""
    for k in keys:
        if k in ("f7", "enter", "escape") or len(k) == 1:
            app.post_message(events.Key(k, {"enter": "\r", "escape": "\x1b"}.get(k, k if len(k) == 1 else None)))
        else:
            for ch in k:
                app.post_message(
                    events.Key(
                        {"/": "slash", ".": "full_stop", "-": "minus", "=": "equals_sign", ":": "colon"}.get(ch, ch), ch
                    )
                )


def test_a_burst_opens_import_types_the_path_and_sets_a_limit(tmp_path):
    capture = tmp_path / "p4.csv"
    res = run_station(
        "simulate", "--procedure", "gyro-drift", "--seed", 403000, "--option", "duration_s=60", "--out", capture
    )
    assert res.returncode == 0, res.stderr
    db = str(tmp_path / "station.db")

    async def story():
        app = make_app(db)
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen" and app.focused is not None)
            _burst(app, "f7", str(capture), "enter")
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen" and " RMS " in text_of(app, "#summary"))
            _burst(app, "l", "drift=-2000:2000", "enter")
            await wait_for(pilot, lambda: "stored: drift = -2000" in text_of(app, "#said"))
            said = text_of(app, "#said")
            _burst(app, "escape")
            await wait_for(pilot, lambda: screen_name(app) == "ResultsScreen" and " PASS " in text_of(app, "#summary"))
            return said

    said = asyncio.run(story())
    assert "stored: drift = -2000 … 2000 °/h" in said
