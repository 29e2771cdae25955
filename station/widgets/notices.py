"""Notices as lines in a screen's own place, not toasts over its content.

At 80x24 a toast (bottom right, 3 to 9 lines, two stacked) covered Connect's buttons, the Results
tables, the P1 and P2 prompts, the History plot, the Allan table, the Diagnose report and the
boxes of Decide, Limits and Help (over which the screen underneath had its notices).
A screen that shows its notices itself hides Textual's ``ToastHolder`` in its CSS, composes a
``Static`` with id ``notices`` and calls :func:`show_notices` from its ``show_notices`` method
(``StationApp.on_notify`` calls that on every notice) and when it is shown again:
:class:`NoticesMixin` does the calling.
"""

from __future__ import annotations

from textual.widgets import Static

from station.textsafe import tui_markup

SEVERITY_STYLE = {"error": "b red", "warning": "yellow"}


def current_notices(app) -> list:
    """The app's notices not expired yet (``StationApp.notices``), oldest first."""
    return [n for n in getattr(app, "notices", []) if not n.has_expired]


def notice_markup(n) -> str:
    """One notice as one markup line (its title first, in its severity's colour)."""
    text = " ".join(f"{n.title}: {n.message}".split()) if n.title else " ".join(n.message.split())
    if not n.markup:
        text = tui_markup(text)
    style = SEVERITY_STYLE.get(n.severity)
    return f"[{style}]{text}[/]" if style else text


def show_notices(screen, limit: int = 2, hide_empty: bool = False) -> None:
    """The app's notices still current (``StationApp.notices``), newest last, at most
    ``limit``, each on its own line(s) in ``screen``'s ``#notices``; drawn again when the
    first of them expires, so the line empties as the toast would have gone. ``hide_empty``:
    the line takes no room while it is empty (Results: the tables keep every line then)."""
    if not screen.query("#notices"):  # not composed yet: its on_mount shows them
        return
    notices = current_notices(screen.app)[-limit:]
    lines = [notice_markup(n) for n in notices]
    line = screen.query_one("#notices", Static)
    line.update("\n".join(lines))
    if hide_empty:  # no blank line taken from the screen while there is nothing to say
        line.display = bool(lines)
    if notices:  # again when the first goes
        screen.set_timer(
            max(min(n.time_left for n in notices), 0.0) + 0.05, lambda: show_notices(screen, limit, hide_empty)
        )


class NoticesMixin:
    """For a Screen (or a ModalScreen) that shows notices in its own place: it composes
    ``Static("", id="notices")`` where a line covers nothing the operator needs and hides
    ``ToastHolder`` in its CSS; this keeps that line current when the screen is mounted, on
    every notice (``StationApp.on_notify``) and when the screen is shown again. The line takes
    no room while it is empty (the screen's layout is then as without it)."""

    NOTICE_LIMIT = 2

    def show_notices(self) -> None:
        show_notices(self, self.NOTICE_LIMIT, hide_empty=True)

    def on_mount(self) -> None:
        self.show_notices()

    def on_screen_resume(self) -> None:
        self.show_notices()
