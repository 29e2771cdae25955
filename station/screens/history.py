"""History: devices, their calibrations over time, a drift plot of one parameter, and
the due and overdue reminders."""

from __future__ import annotations

import math

from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.coordinate import Coordinate
from textual.screen import Screen
from textual.widgets import DataTable, Static
from textual_plotext import PlotextPlot

from db.params import DRIFT_MIN_CALIBRATIONS
from station.procedures import registry
from station.timeaxis import time_axis
from station.widgets.notices import NoticesMixin
from station.widgets.title import TitleBar, footer


def _short(procedure: str) -> str:
    """P1..P5 for the table (the procedure's name is on its Results and in the report)."""
    return registry.short_code(procedure)


from station.formatting import due_status, due_when  # noqa: E402
from station.messages import StoreLoaded  # noqa: E402
from station.textsafe import safe, tui_markup  # noqa: E402

STATUS_WIDTH = 7  # the devices table's status column: "overdue"
DEVICE_WIDTH = 12  # the devices table's id column: a longer id pushed n and status out of the 26 columns


def short_id(device_id: str, width: int = DEVICE_WIDTH) -> str:
    """``device_id`` in ``width`` characters: its start and its end (serial numbers of one model
    differ at the end), an ellipsis between."""
    if len(device_id) <= width:
        return device_id
    head = (width - 1) // 2
    return device_id[:head] + "…" + device_id[-(width - 1 - head) :]


def next_due_text(device: dict | None, due: dict | None) -> str:
    """One line over a device's calibrations: when it falls due (``formatting.due_when``), or
    that it never does, having no recalibration interval (the TUI registers devices without
    one, so a new unit's first calibration leaves it so: ``station due`` would never name it).
    Says the key that sets the interval (``i``)."""
    interval = (device or {}).get("interval_days")
    if due is None:
        if not interval:
            return "never due: no recalibration interval (i sets one)"
        return f"not scheduled yet, interval {interval:g} d"
    when = due_when(due)
    line = f"{when}, interval {interval:g} d" if interval else f"{when}, no interval (i sets one)"
    # why, for a date within the 30 days the header lists (its rows say only when)
    soon = due.get("days_left") is not None and due["days_left"] <= 30
    return f"{line}\n{due['reason']}" if soon and due.get("reason") else line


def _rate_text(d: dict, k: float, unit: str) -> str:
    """The plot title's trend of one parameter (``Store.drift`` entry ``d``, shown = stored * k):
    rate ± σ per year and how many σ, * when significant (it can move the due date); under
    three calibrations, no rate (two points, minutes apart, showed -9.49e+05 °/h/yr)."""
    rate, sigma = d.get("rate_per_year"), d.get("rate_sigma_per_year")
    if d.get("n", 0) < DRIFT_MIN_CALIBRATIONS or not isinstance(rate, (int, float)):
        return f"  trend: {DRIFT_MIN_CALIBRATIONS}+ calibrations"
    text = f"  {rate * k:+.2g}"
    if isinstance(sigma, (int, float)):
        text += f"±{abs(sigma * k):.1g}"
    text += f" {unit}/yr" if unit else "/yr"
    s = d.get("significance_sigmas")
    if isinstance(s, (int, float)):
        text += f" {s:.1f}σ" + ("*" if d.get("significant") else "")
    return text


class HistoryScreen(NoticesMixin, Screen):
    SUB_TITLE = "devices and calibrations"
    CSS = """
    HistoryScreen #due { height: auto; padding: 0 1; color: $warning; }
    HistoryScreen #devices { width: 26; height: 1fr; }
    HistoryScreen DataTable:focus { border-left: thick $accent; }
    HistoryScreen #right { width: 1fr; height: 1fr; border-left: vkey $secondary; }
    HistoryScreen #next { height: auto; padding: 0 1; }
    HistoryScreen #calibrations { height: 1fr; }
    HistoryScreen #calnote { height: auto; padding: 0 1; color: $warning; display: none; }
    HistoryScreen #plot { height: 1fr; min-height: 8; }
    /* notices under the plot, not a toast over its last points and date axis (the reminder
       that brings the operator here says F2) */
    HistoryScreen ToastHolder { display: none; }
    HistoryScreen #notices { height: auto; max-height: 4; padding: 0 1; }
    """
    BINDINGS = [
        Binding("escape", "app.pop_screen", "Back"),
        Binding("p", "next_param", "Next param"),  # short: the footer keeps to 80 columns with e
        Binding("g", "diagnose", "Diagnose"),
        Binding("l", "limits", "Limits"),
        Binding("i", "interval", "Interval"),
        Binding("e", "firmware", "Firmware"),
    ]

    def __init__(self) -> None:
        super().__init__()
        self.devices: list[dict] = []
        self.due: list[dict] = []
        self.history: list[dict] = []
        self.drift: list[dict] = []
        self.param_index = 0
        self.device_id: str | None = None

    def compose(self) -> ComposeResult:
        yield TitleBar("devices and calibrations")
        yield Static("", id="due")
        with Horizontal():
            yield DataTable(id="devices", cursor_type="row", zebra_stripes=True)
            with Vertical(id="right"):
                yield Static("", id="next")
                yield DataTable(id="calibrations", cursor_type="row", zebra_stripes=True)
                # the highlighted calibration's back-dated note (station.store.back_dated_line)
                yield Static("", id="calnote")
                yield PlotextPlot(id="plot")
        yield Static("", id="notices")
        yield footer()

    def on_mount(self) -> None:
        t = self.query_one("#devices", DataTable)
        t.add_columns("device", "n")
        # fixed width: "overdue" fits whatever render sees the rows first (the snapshot raced on it);
        # the longer words are said shorter (formatting.due_status): "never calibrated" read "never c"
        t.add_column("status", width=STATUS_WIDTH)
        c = self.query_one("#calibrations", DataTable)
        c.add_columns("#", "time (UTC)", "proc", "residual", "state")
        self.load()

    @work(thread=True, exclusive=True, group="history", exit_on_error=False, description="read devices")
    def load(self) -> None:
        try:
            store = self.app.session.open_store()
            if store is None:
                self.post_message(StoreLoaded("devices", {"devices": [], "due": []}))
                return
            self.post_message(
                StoreLoaded("devices", {"devices": store.list_devices(), "due": store.due(within_days=30)})
            )
        except Exception as exc:  # noqa: BLE001
            self.post_message(StoreLoaded("devices", {"devices": [], "due": []}, error=str(exc)))

    @work(thread=True, exclusive=True, group="history-device", exit_on_error=False, description="read a device")
    def load_device(self, device_id: str) -> None:
        try:
            store = self.app.session.open_store()
            from db.store import MAX_INTERVAL_DAYS

            # every date ahead, not only the 30 days the header lists: the device's next due date
            due = [d for d in store.due(within_days=2 * MAX_INTERVAL_DAYS) if d["device_id"] == device_id]
            data = {
                "id": device_id,
                "history": store.history(device_id),
                "drift": store.drift(device_id),
                "device": store.get_device(device_id),
                "due": due[0] if due else None,
            }
            self.post_message(StoreLoaded("device-history", data))
        except Exception as exc:  # noqa: BLE001
            self.post_message(StoreLoaded("device-history", None, error=str(exc)))

    def on_store_loaded(self, message: StoreLoaded) -> None:
        if message.error:
            self.query_one("#due", Static).update(f"[b red]database: {message.error}[/]")
            return
        if message.what == "devices":
            self.devices = message.data["devices"]
            self.due = message.data["due"]
            status = {d["device_id"]: d for d in self.due}
            t = self.query_one("#devices", DataTable)
            ids = [d["id"] for d in self.devices]
            # read again (an interval or limits set here): the cursor stays on the device it was
            # on; a clear() put it back on the first, whose due line then showed under the other's
            keep = self.device_id if self.device_id in ids else (ids[0] if ids else None)
            cells = []
            for d in self.devices:
                st = status.get(d["id"])
                # calibrated without an interval: never due, not "ok" (`station due` never names it)
                word = due_status(st) if st else ("ok" if d.get("interval_days") else "no int")
                cells.append((tui_markup(short_id(d["id"])), str(d["n_calibrations"]), word))
            if t.row_count and [k.value for k in t.rows] == ids:  # the same devices: the cells only
                for i, row in enumerate(cells):
                    for j, value in enumerate(row):
                        t.update_cell_at(Coordinate(i, j), value)
            else:
                t.clear()
                for device_id, row in zip(ids, cells, strict=True):
                    t.add_row(*row, key=device_id)
                if keep is not None:
                    t.move_cursor(row=ids.index(keep))
            bad = [d for d in self.due if d["status"] in ("overdue", "due")]
            # one row per device, when (as `station due --within` says it); why is said over the
            # highlighted device's calibrations (#next): three reasons of two rows each here left
            # the drift plot three rows at 80x24
            rows = [f"{short_id(d['device_id'], 40)}: {due_when(d)}" for d in bad[:3]]
            if len(bad) > 3:
                rows.append(f"… and {len(bad) - 3} more (status column)")
            text = "\n".join(tui_markup(r) for r in rows)
            if not self.devices:
                text = "No devices yet: calibrate one (Connect → Start P1) or run `station demo`."
            self.query_one("#due", Static).update(text)
            if keep is not None:
                self.load_device(keep)
        elif message.what == "device-history" and message.data:
            same = message.data["id"] == self.device_id  # a second load of the same device
            self.device_id = message.data["id"]
            self.history = message.data["history"]
            self.drift = [d for d in message.data["drift"] if d["n"] >= 1]
            said = next_due_text(message.data.get("device"), message.data.get("due"))
            self.query_one("#next", Static).update("\n".join(tui_markup(x) for x in said.split("\n")))
            from station.procedures.review import residual_of, shown_residual

            c = self.query_one("#calibrations", DataTable)
            c.clear()
            for h in reversed(self.history):
                res = h["residual_rms"]
                in_use = h["accepted"] and h.get("superseded_by") is None
                # in the unit its Results screen shows it in (P4: °/h), and what its RMS is taken
                # over where that screen says (P4: per sample), on a second line of the row: the
                # column has 12 characters at 80x24
                res, unit = shown_residual({"procedure": h["procedure"], "residual_rms": res})
                of = residual_of({"procedure": h["procedure"]})
                decision = (h.get("review") or {}).get("decision")
                state = (
                    "in use"
                    if in_use
                    else ("rejected" if not h["accepted"] else ("override" if decision == "override" else "old"))
                )
                c.add_row(
                    str(h["id"]),
                    h["time"][:16].replace("T", " "),
                    tui_markup(_short(h["procedure"])),
                    (f"{res:.3g} {unit}" + (f" RMS\n{of}" if of else "")) if isinstance(res, (int, float)) else "—",
                    state,
                    key=str(h["id"]),
                    height=2 if of and isinstance(res, (int, float)) else 1,
                )
            self.show_note(c.cursor_row)
            # keep the parameter the operator chose when the same device is read again
            # (the first row highlight can ask for it a second time)
            self.param_index = self.param_index % len(self.drift) if (same and self.drift) else 0
            self.plot()

    def on_data_table_row_highlighted(self, event: DataTable.RowHighlighted) -> None:
        if event.cursor_row != event.data_table.cursor_row:
            return  # a row the cursor has left since (clear() passes the first on its way)
        if event.data_table.id == "devices":
            if event.row_key is not None and event.row_key.value != self.device_id:
                self.load_device(event.row_key.value)
        elif event.data_table.id == "calibrations":
            self.show_note(event.cursor_row)

    def show_note(self, row: int) -> None:
        """Under the calibrations, the highlighted one's back-dated note: a calibration dated
        before it that was saved after it (which, its date, when saved), as `history` says it;
        nothing (no line taken from the plot) for the others."""
        from station.store import back_dated_line

        by_id = {h["id"]: h for h in self.history}
        newest_first = list(reversed(self.history))  # the table's order
        h = newest_first[row] if 0 <= row < len(newest_first) else None
        before = [by_id[i] for i in (h or {}).get("back_dated_before") or [] if i in by_id]
        note = back_dated_line(h, before, judged=False) if h is not None else None  # 2 rows at 80x24
        label = self.query_one("#calnote", Static)
        label.update(tui_markup(note) if note else "")
        label.display = bool(note)

    def action_diagnose(self) -> None:
        """Diagnose the calibration under the cursor of the calibrations table."""
        from station.screens.diagnose import DiagnoseScreen

        table = self.query_one("#calibrations", DataTable)
        if table.row_count == 0:
            self.notify("No calibration to diagnose", severity="warning")
            return
        row = table.get_row_at(table.cursor_row)
        self.app.push_screen(DiagnoseScreen(calibration_id=int(row[0])))

    def action_firmware(self) -> None:
        """The highlighted calibration as a flight controller's parameters (station.screens.firmware)."""
        from station.screens.firmware import FirmwareScreen

        table = self.query_one("#calibrations", DataTable)
        if table.row_count == 0 or not self.device_id:
            self.notify("No calibration to export", severity="warning")
            return
        row = table.get_row_at(table.cursor_row)
        self.app.push_screen(FirmwareScreen(int(row[0]), self.device_id))

    def action_limits(self) -> None:
        """View and edit the highlighted device's absolute limits (station.screens.limits)."""
        from station.screens.limits import LimitsScreen

        if not self.device_id:
            self.notify("No device to set limits for", severity="warning")
            return
        self.app.push_screen(LimitsScreen(self.device_id))

    def action_interval(self) -> None:
        """Set the highlighted device's recalibration interval (station.screens.interval)."""
        from station.screens.interval import IntervalScreen

        if not self.device_id:
            self.notify("No device to set an interval for", severity="warning")
            return

        def changed(done: bool | None) -> None:
            if done:  # the due dates moved: read the devices (and this device) again, and the reminder
                self.load()
                self.app.load_due()

        self.app.push_screen(IntervalScreen(self.device_id), changed)

    def action_next_param(self) -> None:
        if self.drift:
            self.param_index = (self.param_index + 1) % len(self.drift)
            self.plot()

    def plot(self) -> None:
        w = self.query_one("#plot", PlotextPlot)
        plt = w.plt
        plt.clear_data()
        plt.clear_figure()
        if not self.drift:
            plt.title(safe(f"{self.device_id or ''}: no accepted calibrations to plot"))
            w.refresh()
            return
        d = self.drift[self.param_index]
        axis = time_axis(d["times"], n_ticks=3)
        x = axis["x"]
        k, unit = self._unit(d)  # shown = stored * k, in the unit its Results screen shows
        values = [v * k for v in d["values"]]
        plt.plot(x, values, marker="dot")
        if all(isinstance(s, (int, float)) and math.isfinite(s) for s in d["sigmas"] or []) and d["sigmas"]:
            plt.plot(x, [v + s * k for v, s in zip(values, d["sigmas"])], color="gray")
            plt.plot(x, [v - s * k for v, s in zip(values, d["sigmas"])], color="gray")
        plt.xlim(*axis["xlim"])
        plt.xticks(axis["ticks"], axis["labels"])
        plt.title(
            f"{safe(d['param'])} [{unit or '1'}] {self.param_index + 1}/{len(self.drift)}{_rate_text(d, k, unit)}"
        )
        plt.xlabel(axis["label"])
        w.refresh()

    def _unit(self, d: dict) -> tuple[float, str]:
        """(factor, unit) of the plotted parameter: shown = stored * factor."""
        from station.procedures.review import display_unit, param_unit

        for h in reversed(self.history):
            if h["procedure"] == d["procedure"]:
                result = dict(h["extra"], procedure=h["procedure"], params=h["params"])
                return display_unit(result, d["param"]) or (1.0, param_unit(result, d["param"]))
        return 1.0, ""
