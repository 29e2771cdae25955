"""The TUI at 80x24, through the real app and its pilot (s28-io).

- F1's keys had no Diagnose entry (the screen `g` and F6 open, its keys, that Esc stops it).
- Results: the notes above the tables hold at most 7 lines; a second long warning went on below
  them out of sight, with nothing but a 2-cell scroll bar to say so, and no key said how to reach
  it. Now a line under the notes says how many lines are left and the key (w) that takes them.
"""

from __future__ import annotations

import asyncio

from station.app import make_app
from tests.test_tui import SIZE, screen_lines, screen_name, wait_for
from tests.tui_data import p1_result

FIRST = (
    "the placement of x_down disagrees with its label by 12.5° (more than the 10° the gauge assumes): "
    "the table's vector condition is weakened; the norm condition still holds"
)
SECOND = (
    "the temperature moved 6.2 °C during the run (from 21.4 to 27.6 °C): the bias drifts with it and the "
    "fit averages over it; a run at one temperature, or a temperature model (P1 with temp_c), gives a "
    "calibration that holds at the end of the run as at its start (the last words of this warning)"
)


def test_f1_help_has_a_diagnose_entry_reached_at_80x24(tmp_path):
    async def story():
        app = make_app(str(tmp_path / "s.db"))
        async with app.run_test(size=SIZE) as pilot:
            await pilot.press("f1")
            await wait_for(pilot, lambda: screen_name(app) == "HelpScreen")
            box = app.screen.query_one("#help")
            seen = []
            while True:  # page through the box as a user does, keeping what each page shows
                seen += screen_lines(app)
                if box.scroll_y >= box.max_scroll_y:
                    break
                y = box.scroll_y
                await pilot.press("pagedown")
                await wait_for(pilot, lambda y=y: box.scroll_y > y)
            seen += screen_lines(app)
            return seen

    lines = [line.strip(" │▁▂▃▄▅▆▇█") for line in asyncio.run(story())]
    at = next((i for i, line in enumerate(lines) if line.startswith("Diagnose ")), None)
    assert at is not None, "\n".join(lines)
    entry = " ".join(" ".join(lines[at : at + 4]).split())
    for words in ("g on Results or History, F6 on Import", "station diagnose", "esc stops it and goes back"):
        assert words in entry, entry
    assert all(len(line) <= 80 for line in lines)


def test_a_long_second_warning_is_reached_by_the_keys_the_screen_names(tmp_path):
    from station.screens.results import ResultsScreen

    cap, result = p1_result("IMU-8")
    result["warnings"] = [FIRST, SECOND]

    async def story():
        app = make_app(str(tmp_path / "s.db"), device_id="IMU-8")
        async with app.run_test(size=SIZE) as pilot:
            await app.push_screen(ResultsScreen(cap, result, None, None))
            await wait_for(pilot, lambda: app.screen.query_one("#residuals").row_count == 12)
            # the screen says that the notes go on, and which key takes them
            await wait_for(pilot, lambda: any("more lines of the notes above" in x for x in screen_lines(app)))
            first = screen_lines(app)
            hint = next(x for x in first if "more lines of the notes above" in x)
            key = hint.split(":")[-1].split()[0]  # 'w goes to them, ↓ scrolls'
            assert "the last words of this warning" not in " ".join(first)
            await pilot.press(key)
            notes = app.screen.query_one("#notes")
            await wait_for(pilot, lambda: notes.has_focus)
            await pilot.press("end")
            await wait_for(pilot, lambda: notes.scroll_y >= notes.max_scroll_y > 0)
            await wait_for(pilot, lambda: not any("more lines" in x for x in screen_lines(app)))
            shown = screen_lines(app)
            await pilot.press(key)  # again: back to the parameters
            await wait_for(pilot, lambda: app.screen.query_one("#params").has_focus)
            return first, hint, shown

    first, hint, shown = asyncio.run(story())
    assert "w goes to them" in hint, hint
    text = " ".join(" ".join(x.strip(" █▄▆") for x in shown).split())
    assert "(the last words of this warning)" in text, "\n".join(shown)
    assert all(len(x) <= 80 for x in first + shown) and len(first) == len(shown) == 24
