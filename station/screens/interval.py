"""A device's recalibration interval, set where its due date is shown: History, ``i`` on
the highlighted device.

The TUI registers a new unit without an interval, so after its first calibration it is
never due (``station due`` names it on stderr only). This box is the same store call as
``station devices add ID --interval-days N`` (``Store.add_device``: the change is anchored,
the schedule recomputed, and ``station verify`` sees any edit made behind the station's
back), refused as that option is: a number of days, positive, at most 100 years.
"""

from __future__ import annotations

import math

from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Input, Static

from station.textsafe import tui_markup
from station.widgets.field import Field
from station.widgets.title import footer


def parse_interval_days(text: str, max_days: float) -> float:
    """``text`` as an interval in days (``365``, ``365 d``, ``182.5``); ValueError saying why not."""
    raw = text.strip().removesuffix("days").removesuffix("d").strip()
    try:
        days = float(raw)
    except ValueError:
        raise ValueError(f"not a number of days: {text.strip()!r}") from None
    if not math.isfinite(days) or not 0 < days <= max_days:
        raise ValueError(f"the interval must be positive, at most {max_days:g} days (100 years), got {raw}")
    return days


class IntervalScreen(ModalScreen):
    """The interval of ``device_id``; dismisses with True when it was changed."""

    CSS = """
    IntervalScreen { align: center middle; }
    IntervalScreen #box { width: 60; height: auto; border: round $primary; background: $surface; padding: 0 1; }
    IntervalScreen #error { height: auto; color: $error; }
    IntervalScreen Input:focus { border: tall $accent; }
    /* History's notice lines show under the box: a toast over them cut them */
    IntervalScreen ToastHolder { display: none; }
    """
    BINDINGS = [Binding("escape", "close", "Back", priority=True)]

    def __init__(self, device_id: str) -> None:
        super().__init__()
        self.device_id = device_id
        self.changed = False

    def compose(self) -> ComposeResult:
        with Vertical(id="box"):
            yield Static(f"[b]Recalibration interval of {tui_markup(self.device_id)}[/]", id="head")
            yield Static("reading…", id="current")
            yield Static("Days from its last accepted calibration to the next:")
            yield Field(placeholder="e.g. 365", id="edit")
            yield Static("Enter apply · esc back")
            yield Static("", id="error")
        yield footer()

    def on_mount(self) -> None:
        self.query_one("#edit", Input).focus()
        self.load()

    @work(thread=True, exclusive=True, group="interval", exit_on_error=False, description="read the device")
    def load(self) -> None:
        try:
            store = self.app.session.open_store()
            device = store.get_device(self.device_id) if store is not None else None
            days = (device or {}).get("interval_days")
            text = f"now: {days:g} days" if days else "now: none, so it is never due"
            self.app.call_from_thread(self.query_one("#current", Static).update, text)
        except Exception as exc:  # noqa: BLE001 - one line in the box
            self.app.call_from_thread(self._refused, str(exc))

    @on(Input.Submitted, "#edit")
    def apply(self, event: Input.Submitted) -> None:
        from db.store import MAX_INTERVAL_DAYS

        try:
            days = parse_interval_days(event.value, MAX_INTERVAL_DAYS)
        except ValueError as exc:
            self._refused(str(exc))
            return
        self.store_interval(days)

    @work(thread=True, exclusive=True, group="interval-save", exit_on_error=False, description="store the interval")
    def store_interval(self, days: float) -> None:
        try:
            store = self.app.session.open_store()
            if store is None or store.get_device(self.device_id) is None:
                raise RuntimeError(f"no device {self.device_id!r} in the database")
            store.add_device(self.device_id, interval_days=days)
            self.changed = True
            self.app.call_from_thread(self.dismiss, True)
        except Exception as exc:  # noqa: BLE001 - one line in the box, nothing changed
            self.app.call_from_thread(self._refused, f"not stored: {exc}")

    def _refused(self, text: str) -> None:
        self.query_one("#error", Static).update(tui_markup(text))

    def action_close(self) -> None:
        self.dismiss(self.changed)
