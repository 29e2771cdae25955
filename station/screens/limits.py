"""A device's absolute limits, viewed and edited where a bench engineer looks for the
device: History, ``l`` on the highlighted device; Results, ``l`` after a calibration.

The same store call as ``station devices add ID --limit NAME=LOW:HIGH`` (``Store.add_device``,
so the change is anchored and ``station verify`` sees any edit made behind the station's
back) and the same syntax (``station.commands.devices.parse_limit``): ``NAME=LOW:HIGH``
sets one (either end may be empty), ``NAME=`` removes it. Each limit is shown with its
unit and the value of the calibration in use, so the engineer sees what it is checked on.

Limits are shown and typed in the unit the Results screen shows the parameter in (P4's
drift in °/h, the compass's soft iron as a ratio) and stored in the parameter's stored
unit, through ``station.procedures.review``'s one conversion (``shown_value`` /
``stored_value``); the unit comes from the result on screen, else the calibrations of the
device (``review.unit_context``).
"""

from __future__ import annotations

import math

from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Input, Static

from station.messages import StoreLoaded
from station.textsafe import tui_markup
from station.widgets.field import Field


def _fmt(x) -> str:
    return "…" if x is None else format(float(x), "g")


def _scalar(params: dict, name: str):
    """The value of ``name`` (``B``, ``B[0]``, ``M[0][1]``, ``beam1.dK``) in ``params``, or None."""
    import re

    node = params
    for part in re.findall(r"[^.\[\]]+|\[\d+\]", name):
        try:
            node = node[int(part[1:-1])] if part.startswith("[") else node[part]
        except (KeyError, IndexError, TypeError, ValueError):
            return None
    return node


class LimitsScreen(ModalScreen):
    """The limits of ``device_id``; dismisses with True when something was changed."""

    CSS = """
    LimitsScreen { align: center middle; }
    LimitsScreen #box { width: 78; height: auto; max-height: 22; border: round $primary; background: $surface;
                        padding: 0 1; }
    LimitsScreen #current { height: auto; max-height: 9; }
    LimitsScreen #params { height: auto; max-height: 3; color: $text-muted; }
    LimitsScreen #error { height: auto; color: $error; }
    LimitsScreen Input:focus { border: tall $accent; }
    """
    BINDINGS = [Binding("escape", "close", "Back", priority=True)]

    def __init__(self, device_id: str, result: dict | None = None) -> None:
        """``result``: the result on screen (Results), the first to tell a parameter's unit."""
        super().__init__()
        self.device_id = device_id
        self.result = result
        self.limits: dict = {}
        self.contexts: list[dict] = [result] if result else []  # review.unit_context's results
        self.changed = False

    def compose(self) -> ComposeResult:
        with Vertical(id="box"):
            yield Static(f"[b]Limits of {tui_markup(self.device_id)}[/]: absolute, in the units shown", id="head")
            yield Static("reading…", id="current")
            yield Static("", id="params")
            yield Static("NAME=LOW:HIGH sets one (an end may be empty), NAME= removes it:")
            yield Field(placeholder="e.g. B=-0.5:0.5  M[0][0]=0.98:1.02  S=0.9:", id="edit")
            yield Static("Enter apply · esc back")
            yield Static("", id="said")
            yield Static("", id="error")

    def on_mount(self) -> None:
        self.query_one("#edit", Input).focus()
        self.load()

    @work(thread=True, exclusive=True, group="limits", exit_on_error=False, description="read the device")
    def load(self) -> None:
        try:
            s = self.app.session
            if not s.db_path:
                raise RuntimeError("no database (start the station with --db or STATION_DB)")
            store = s.open_store()  # None: nothing saved yet (the first save or limit makes it)
            device = store.get_device(self.device_id) if store is not None else None
            if device is None:  # a new unit (Results of its first run): a limit set here registers it
                device = {"limits": {}, "new": True}
            in_use = {}
            history = store.history(self.device_id) if store is not None else []
            for h in history:  # oldest first: the newest accepted wins
                if h["accepted"]:
                    in_use[h["procedure"]] = h
            data = {"limits": device.get("limits") or {}, "in_use": in_use, "history": history, "new": "new" in device}
            self.post_message(StoreLoaded("limits", data))
        except Exception as exc:  # noqa: BLE001 - one line in the box
            self.post_message(StoreLoaded("limits", None, error=str(exc)))

    def on_store_loaded(self, message: StoreLoaded) -> None:
        message.stop()
        if message.error:
            self.query_one("#current", Static).update("")
            self.query_one("#error", Static).update(tui_markup(message.error))
            return
        from station.procedures import registry
        from station.procedures.review import record_result, shown_unit, shown_value, unit_context

        self.limits = message.data["limits"]
        in_use = message.data["in_use"]
        # the units: the result on screen, the calibrations in use, then any of the device's (newest first)
        self.contexts = ([self.result] if self.result else []) + [
            record_result(h) for h in [*in_use.values(), *reversed(message.data["history"])]
        ]
        lines = []
        for name, (low, high) in sorted(self.limits.items()):
            ctx = unit_context(name, self.contexts)
            now = None
            for h in in_use.values():
                v = _scalar(h["params"], name)
                if v is not None:
                    now = v
                    break
            shown = ""
            if isinstance(now, (int, float)) and math.isfinite(now):
                inside = (low is None or now >= low) and (high is None or now <= high)
                shown = f"   in use {shown_value(ctx, name, now):.6g}" + ("" if inside else "  [b red]OUTSIDE[/]")
            low, high = (None if x is None else shown_value(ctx, name, x) for x in (low, high))
            unit = shown_unit(ctx, name) if ctx else ""
            lines.append(f"{tui_markup(name):<12} {_fmt(low):>10} … {_fmt(high):<10} {tui_markup(unit)}" + shown)
        none = "no limits set" + ("; the first one registers this new unit" if message.data["new"] else "")
        self.query_one("#current", Static).update("\n".join(lines) or tui_markup(none))
        blocks = []
        for proc, h in in_use.items():
            entry = registry.get(proc)
            code = entry.code if entry is not None else proc
            names = [k for k, v in h["params"].items() if not isinstance(v, (str, bool)) and v is not None]
            blocks.append(f"{code}: {', '.join(names)}")
        self.query_one("#params", Static).update(
            tui_markup("parameters in use: " + "; ".join(blocks)) if blocks else "no accepted calibration yet"
        )

    @on(Input.Submitted, "#edit")
    def apply(self, event: Input.Submitted) -> None:
        from station.commands.devices import parse_limit

        text = event.value.strip()
        if not text:
            return
        try:
            name, pair = parse_limit(text)
        except ValueError as exc:
            self.query_one("#said", Static).update("")
            self.query_one("#error", Static).update(tui_markup(str(exc)))
            return
        if pair is None and name not in self.limits:
            self.query_one("#error", Static).update(tui_markup(f"no limit {name!r} to remove"))
            return
        self.store_limit(name, pair)

    def _stored_pair(self, name: str, pair):
        """A typed pair (in the unit shown) in the parameter's stored unit."""
        from station.procedures.review import stored_value, unit_context

        if pair is None:
            return None
        ctx = unit_context(name, self.contexts)
        return [None if x is None else stored_value(ctx, name, x) for x in pair]

    def _shown_text(self, name: str, pair) -> str:
        from station.procedures.review import shown_unit, unit_context

        ctx = unit_context(name, self.contexts)
        unit = shown_unit(ctx, name) if ctx else ""
        return f"{name} = {_fmt(pair[0])} … {_fmt(pair[1])}" + (f" {unit}" if unit and unit != "1" else "")

    @work(thread=True, exclusive=True, group="limits-save", exit_on_error=False, description="store a limit")
    def store_limit(self, name: str, pair) -> None:
        try:
            from db.store import Store

            s = self.app.session
            store = s.open_store()
            if store is None:  # a new user's first entry makes the database (the session's one Store)
                store = s.extra["_store"] = Store(s.db_path)
            store.add_device(self.device_id, limits={name: self._stored_pair(name, pair)})
            self.app.call_from_thread(self._stored, name, pair)
        except Exception as exc:  # noqa: BLE001 - one line in the box, nothing changed
            self.app.call_from_thread(self.query_one("#error", Static).update, tui_markup(f"not stored: {exc}"))

    def _stored(self, name: str, pair) -> None:
        self.changed = True
        self.query_one("#edit", Input).value = ""
        said = f"removed {name}" if pair is None else self._shown_text(name, pair)
        self.query_one("#error", Static).update("")
        self.query_one("#said", Static).update(tui_markup(f"stored: {said}"))
        self.load()

    def action_close(self) -> None:
        self.dismiss(self.changed)
