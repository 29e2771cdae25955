"""A device's absolute limits, viewed and edited where a bench engineer looks for the
device: History, ``l`` on the highlighted device; Results, ``l`` after a calibration.

The same store call as ``station devices add ID --limit NAME=LOW:HIGH`` (``Store.add_device``,
so the change is anchored and ``station verify`` sees any edit made behind the station's
back) and the same syntax (``station.commands.devices.parse_limit``): ``NAME=LOW:HIGH``
sets one (either end may be empty), ``NAME=`` removes it. Each limit is shown with its
unit and the value of the calibration in use, so the engineer sees what it is checked on.

Limits are shown and typed in the unit the Results screen shows the parameter in (P4's
drift in °/h, the compass's soft iron as a ratio) and stored in the parameter's stored
unit, converted and refused as ``--limit`` is (``station.commands.devices.typed_limit``):
the unit comes from the result on screen, else the calibrations of the device; a limit
whose unit they cannot tell yet (soft iron with no compass calibration) is one line in
the box and nothing is stored.
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
from station.widgets.notices import NoticesMixin
from station.widgets.title import footer

_BOX_TEXT_WIDTH = 74  # #box: 78 columns less its border and padding

GENERIC_EXAMPLE = "e.g. NAME=LOW:HIGH, a name from the parameters in use"


def example_for(procedure: str | None) -> str:
    """The edit box's placeholder for a device calibrated with ``procedure``: its module's
    ``LIMIT_EXAMPLE`` (its own parameter names, in the units shown: P4's drift in °/h),
    else the syntax alone."""
    from station.procedures import registry

    entry = registry.get(procedure) if procedure else None
    if entry is None:
        return GENERIC_EXAMPLE
    return getattr(entry.load(), "LIMIT_EXAMPLE", None) or GENERIC_EXAMPLE


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


class LimitsScreen(NoticesMixin, ModalScreen):
    """The limits of ``device_id``; dismisses with True when something was changed."""

    CSS = """
    LimitsScreen { align: center middle; }
    LimitsScreen #box { width: 78; height: auto; max-height: 22; border: round $primary; background: $surface;
                        padding: 0 1; }
    LimitsScreen #current { height: auto; max-height: 12; }
    LimitsScreen #params { height: auto; max-height: 3; color: $text-muted; }
    LimitsScreen #error { height: auto; color: $error; }
    /* the notices of the screen underneath in the box, not toasts over its field */
    LimitsScreen ToastHolder { display: none; }
    LimitsScreen #notices { height: auto; max-height: 4; }
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
            yield Field(placeholder=example_for((self.result or {}).get("procedure")), id="edit")
            yield Static("Enter apply · esc back")
            yield Static("", id="said")
            yield Static("", id="error")
            yield Static("", id="notices")
        yield footer()  # this box's keys: the screen underneath showed its own, dead while it is open

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
        from station.commands.devices import unit_contexts
        from station.procedures import registry
        from station.procedures.review import flatten, limit_in, shown_limit, shown_value, unit_context

        self.limits = message.data["limits"]
        in_use = message.data["in_use"]
        # the units: the result on screen, the calibrations in use, then any of the device's (newest first)
        self.contexts = ([self.result] if self.result else []) + unit_contexts(message.data["history"])
        lines = []
        for name, lim in sorted(self.limits.items()):
            ctx = unit_context(name, self.contexts)
            bounds = limit_in(ctx, name, lim)  # in the stored unit of the calibrations in use
            now = None
            for h in in_use.values():
                v = _scalar(h["params"], name)
                if v is not None:
                    now = v
                    break
            # a block (drift, B, M) is limited element by element: its values in use, min … max
            values = [x for x in flatten(now).values() if x is not None and math.isfinite(x)]
            shown = ""
            if values and bounds is not None:
                low, high = bounds
                inside = all((low is None or x >= low) and (high is None or x <= high) for x in values)
                shows = sorted(shown_value(ctx, name, x) for x in values)
                span = f"{shows[0]:.6g}" if len(shows) == 1 else f"{shows[0]:.6g} … {shows[-1]:.6g}"
                shown = f"in use {span}" + ("" if inside else "  OUTSIDE")
            low, high, unit = shown_limit(ctx, name, lim)
            line = f"{name:<12} {_fmt(low):>10} … {_fmt(high):<10} {unit}"
            text = tui_markup(line)
            if shown:  # beside the limit when it fits the box (80x24), else under it: never cut off
                sep = "   " if len(line) + 3 + len(shown) <= _BOX_TEXT_WIDTH else "\n" + " " * 13
                text += sep + shown.replace("OUTSIDE", "[b red]OUTSIDE[/]")
            lines.append(text)
        none = "no limits set" + ("; the first one registers this new unit" if message.data["new"] else "")
        self.query_one("#current", Static).update("\n".join(lines) or tui_markup(none))
        blocks = []
        for proc, h in in_use.items():
            entry = registry.get(proc)
            code = entry.code if entry is not None else proc
            names = [k for k, v in h["params"].items() if not isinstance(v, (str, bool)) and v is not None]
            blocks.append(f"{code}: {', '.join(names)}")
        if not self.result:  # History: the device's newest calibration tells its parameters
            newest = message.data["history"][-1]["procedure"] if message.data["history"] else None
            self.query_one("#edit", Input).placeholder = example_for(newest)
        self.query_one("#params", Static).update(
            tui_markup("parameters in use: " + "; ".join(blocks)) if blocks else "no accepted calibration yet"
        )

    @on(Input.Submitted, "#edit")
    def apply(self, event: Input.Submitted) -> None:
        text = event.value.strip()
        if text:
            self.store_limit(text)

    @work(thread=True, exclusive=True, group="limits-save", exit_on_error=False, description="store a limit")
    def store_limit(self, text: str) -> None:
        """``text`` converted and refused as ``station devices add --limit`` does
        (``devices.typed_limit``, with the units the result on screen and the device's
        calibrations tell), read from the store at the moment it is stored; a refusal is one
        line in the box and stores nothing (a new user's database is not made)."""
        try:
            from db.store import Store
            from station.commands.devices import parse_limit, typed_limit, unit_contexts

            s = self.app.session
            store = s.open_store()  # None: no database yet
            device = store.get_device(self.device_id) if store is not None else None
            history = store.history(self.device_id) if device is not None else []
            contexts = ([self.result] if self.result else []) + unit_contexts(history)
            try:
                name, stored, unit = typed_limit(text, contexts)
            except ValueError as exc:  # a bad entry, or a unit the calibrations cannot tell yet
                self.app.call_from_thread(self._refused, str(exc))
                return
            if stored is None and name not in ((device or {}).get("limits") or {}):
                self.app.call_from_thread(self._refused, f"no limit {name!r} to remove")
                return
            if store is None:  # a new user's first entry makes the database (the session's one Store)
                store = s.extra["_store"] = Store(s.db_path)
            store.add_device(self.device_id, limits={name: stored})
            typed = parse_limit(text)[1]  # as typed, for the line that says what was stored
            self.app.call_from_thread(self._stored, name, typed, unit)
        except Exception as exc:  # noqa: BLE001 - one line in the box, nothing changed
            self.app.call_from_thread(self._refused, f"not stored: {exc}")

    def _refused(self, text: str) -> None:
        self.query_one("#said", Static).update("")
        self.query_one("#error", Static).update(tui_markup(text))

    def _stored(self, name: str, pair, unit: str) -> None:
        self.changed = True
        self.query_one("#edit", Input).value = ""
        said = f"removed {name}" if pair is None else f"{name} = {_fmt(pair[0])} … {_fmt(pair[1])}"
        if pair is not None and unit and unit != "1":
            said += f" {unit}"
        self.query_one("#error", Static).update("")
        self.query_one("#said", Static).update(tui_markup(f"stored: {said}"))
        self.load()

    def action_close(self) -> None:
        self.dismiss(self.changed)
