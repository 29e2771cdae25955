"""A bench engineer's first session at 80x24 (QA s26e), each story on the real app under its
pilot with a real SQLite file: a wrong port path says what to do next, a save that fails
says how to keep the result, and the keys a newcomer guesses for help open it."""

from __future__ import annotations

import asyncio

from station.app import make_app
from tests.test_tui import SIZE, screen_lines, screen_name, text_of, wait_for


def _joined(text: str) -> str:
    """A widget's text as one line: the words it wrapped at 80 columns put back together."""
    return " ".join(line.strip() for line in text.splitlines() if line.strip())


def test_a_port_path_that_does_not_exist_says_what_to_do_next(tmp_path):
    """Typing a wrong port and F5 said only 'Cannot connect: /dev/ttyNOPE0: cannot open: No such
    file or directory'. The line now says what to check and where the ports found are listed,
    whole on the 80x24 screen (a path as long as a /dev/serial/by-id/ one), and Start is usable
    again."""
    port = str(tmp_path / "ttyNOPE0")

    async def story():
        app = make_app(str(tmp_path / "station.db"))
        async with app.run_test(size=SIZE) as pilot:
            await wait_for(pilot, lambda: screen_name(app) == "ConnectScreen")
            app.screen.query_one("#port").focus()
            await pilot.press(*port)
            await pilot.press("f5")
            await wait_for(pilot, lambda: "Cannot connect" in text_of(app, "#status"))
            return _joined(text_of(app, "#status")), app.screen.query_one("#start").disabled, screen_lines(app)

    status, start_disabled, lines = asyncio.run(story())
    assert status == (  # the port is in its field above: a long /dev/serial/by-id/ path pushed the rest off
        "Cannot connect: cannot open the port: No such file or directory: check the path and the cable "
        "(Source lists the ports found)"
    )
    assert not start_disabled
    assert all(len(line) <= SIZE[0] for line in lines)
