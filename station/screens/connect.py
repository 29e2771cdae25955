"""Connect: choose the source (the built-in simulated device or a serial port and its
protocol), the device under test (serial number, model; or one already registered) and
the averaging time, then start P1 (or resume an interrupted run)."""

from __future__ import annotations

import os

from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import Screen
from textual.widgets import Button, Input, Label, Select, Static

from station.formatting import due_when
from station.messages import Connected, SourceFailed, StoreLoaded
from station.procedures import registry
from station.textsafe import tui_markup, tui_text
from station.widgets.field import Field
from station.widgets.title import TitleBar, footer


def failure_text(exc: BaseException, port: str = "") -> str:
    """Connect's line for a source that did not open, with what to do next: it said only the
    system's reason ("Cannot connect: /dev/ttyUSB3: cannot open: No such file or directory"),
    and a database that could not be written was "Cannot connect" too."""
    import sqlite3

    from station.device.reader import PortError

    text = str(exc)
    if isinstance(exc, sqlite3.Error):  # the device opened: registering it or the settings failed
        return f"Cannot use the database: {text}: nothing was saved; ctrl+q, then start with --db another file"
    if not isinstance(exc, PortError):
        return f"Cannot connect: {text}"
    if port and text.startswith(f"{port}: cannot open: "):  # "PORT: cannot open: WHY": the port is in its field
        text = f"cannot open the port: {text[len(port) + len(': cannot open: ') :]}"
    low = text.lower()
    if "no such file" in low:
        what = "check the path and the cable (Source lists the ports found)"
    elif "permission denied" in low:
        what = "this user may not open it: add it to the port's group (dialout), log in again"
    elif "busy" in low:
        what = "another program has it open: close that program"
    else:
        what = "check the port or URL, the cable and the device's power"
    return f"Cannot connect: {text}: {what}"


SIM = "sim"
OTHER = "other"
# what a lab's report states, remembered between sessions: settings name -> input
LAB_FIELDS = {"operator": "#operator", "place": "#place", "reference_equipment": "#reference"}


class ConnectScreen(Screen):
    CSS = """
    ConnectScreen #form { padding: 0 1; height: auto; }
    ConnectScreen .row { height: 1; margin-bottom: 1; }
    ConnectScreen .row Label { width: 16; }
    ConnectScreen #source { width: 1fr; }
    ConnectScreen #protocol { width: 20; }
    ConnectScreen #port { width: 1fr; }
    ConnectScreen #serial, ConnectScreen #model, ConnectScreen #known { width: 1fr; }
    ConnectScreen #operator, ConnectScreen #place, ConnectScreen #reference { width: 1fr; }
    ConnectScreen .row Label.inner { width: auto; padding: 0 1; }
    ConnectScreen Input:focus, ConnectScreen Select:focus > SelectCurrent { background: $accent 30%; }
    ConnectScreen Button:focus { text-style: bold reverse; }
    ConnectScreen #average { width: 12; }
    ConnectScreen #buttons { height: 1; margin-top: 1; }
    ConnectScreen #buttons Button { margin-right: 2; }
    ConnectScreen #due { color: $warning; padding: 0 1; height: auto; }
    ConnectScreen #status { padding: 0 1; height: auto; }
    /* notices are lines under the buttons here, not toasts over them (80x24) */
    ConnectScreen ToastHolder { display: none; }
    ConnectScreen #notices { padding: 0 1; height: auto; max-height: 3; text-wrap: wrap; text-overflow: ellipsis; }
    ConnectScreen #title { text-style: bold; padding: 0 1; }
    """

    BINDINGS = [
        Binding("f5", "start", "Start"),
        Binding("f6", "resume", "Resume"),
        Binding("f2", "history", "History"),
        Binding("f7", "import_file", "Import file"),
    ]

    def compose(self) -> ComposeResult:
        s = self.app.session
        yield TitleBar("connect a device")
        yield Static("Connect a device and start a guided calibration", id="title")
        yield Static("", id="due")
        with Vertical(id="form"):
            with Horizontal(classes="row"):
                yield Label("Source")
                yield Select(
                    self._source_options(), value=self._default_source(), allow_blank=False, id="source", compact=True
                )
                yield Select(
                    [("station protocol", "station"), ("MAVLink", "mavlink")],
                    value="station",
                    allow_blank=False,
                    id="protocol",
                    compact=True,
                )
            with Horizontal(classes="row"):
                yield Label("Port or URL")
                yield Field(
                    placeholder="/dev/ttyUSB0, socket://host:port (when Source is Other)", id="port", compact=True
                )
            with Horizontal(classes="row"):
                yield Label("Serial number")
                yield Field(value=s.device_id, placeholder="default: what it reports", id="serial", compact=True)
                yield Label("model", classes="inner")
                yield Field(value=s.model, placeholder="e.g. ADXL335 triad", id="model", compact=True)
            with Horizontal(classes="row"):
                yield Label("Registered")
                yield Select([], prompt="pick a registered device", id="known", compact=True)
            # entered once, remembered in the database (settings), written into each capture
            with Horizontal(classes="row"):
                yield Label("Operator")
                yield Field(value=s.extra.get("operator", ""), placeholder="your name", id="operator", compact=True)
                yield Label("place", classes="inner")
                yield Field(value=s.extra.get("place", ""), placeholder="lab, bench", id="place", compact=True)
            with Horizontal(classes="row"):
                yield Label("Reference")
                yield Field(
                    value=s.extra.get("reference_equipment", ""),
                    placeholder="reference equipment (table, turntable, IMU: model and serial)",
                    id="reference",
                    compact=True,
                )
            with Horizontal(classes="row"):
                yield Label("Procedure")
                guided = registry.guided()
                yield Select(
                    [(v, k) for k, v in guided.items()],
                    value=s.procedure if s.procedure in guided else registry.DEFAULT,
                    allow_blank=False,
                    id="procedure",
                    compact=True,
                )
            with Horizontal(classes="row"):
                yield Label("Average (s)")
                yield Field(value=f"{self._average_default():g}", id="average", type="number", compact=True)
                yield Label(self._average_means(), id="average-means", classes="inner")
            with Horizontal(id="buttons"):
                yield Button("Start \\[F5]", id="start", variant="primary", compact=True)
                yield Button("Resume \\[F6]", id="resume", compact=True, disabled=True)
                yield Button("History \\[F2]", id="history", compact=True)
                yield Button("Import file \\[F7]", id="import", compact=True)
        yield Static("", id="status")
        yield Static("", id="notices")
        yield footer()

    def _picked(self) -> tuple[str, bool]:
        """The procedure picked and whether the source is the simulated device (before the
        form exists: the session's)."""
        s = self.app.session
        if self.query("#procedure") and self.query("#source"):
            return str(self.query_one("#procedure", Select).value), self.query_one("#source", Select).value == SIM
        procedure = s.procedure if s.procedure in registry.guided() else registry.DEFAULT
        return procedure, self._default_source() == SIM

    def _average_default(self) -> float:
        """What "Average (s)" shows: the time given (--average-s, or typed for an earlier
        run), else the default for the procedure on this source."""
        s = self.app.session
        if not s.average_default:
            return s.average_s
        return registry.default_average_s(*self._picked())

    def _average_means(self) -> str:
        return registry.average_text(*self._picked())

    @on(Select.Changed, "#procedure")
    @on(Select.Changed, "#source")
    def _procedure_picked(self) -> None:
        """Another procedure or source: what "Average (s)" means, and its default when the
        operator has not typed one (the value shown is the previous default)."""
        self.query_one("#average-means", Label).update(self._average_means())
        box = self.query_one("#average", Input)
        if self.app.session.average_default and box.value.strip() == getattr(self, "_offered", None):
            box.value = self._offered = f"{self._average_default():g}"
        if self.query("#resume"):  # (a Select's first Changed can come before the buttons are mounted)
            self._check_resume()  # only P1 resumes: the button and F6 follow the procedure picked

    def _source_options(self):
        opts = [("Built-in simulated device", SIM)]
        try:
            from station.device.ports import list_ports

            opts += [(f"{p.device}  {p.description}"[:60], p.device) for p in list_ports()]
        except Exception:  # noqa: BLE001 - no port listing: the simulator and Other still work
            pass
        opts.append(("Other port or URL (below)", OTHER))
        return opts

    def _default_source(self):
        src = self.app.session.source
        if src is not None and getattr(src, "kind", "") == "serial":
            return OTHER
        return SIM

    def on_mount(self) -> None:
        self._offered = self.query_one("#average", Input).value.strip()  # the default shown, not typed
        src = self.app.session.source
        if src is not None and getattr(src, "kind", "") == "serial":
            self.query_one("#port", Input).value = src.port
            self.query_one("#protocol", Select).value = src.protocol
        self.call_after_refresh(self.load_devices)
        self.show_due(getattr(self.app, "due", []))
        self.show_notices()
        self.call_after_refresh(self.show_notices)  # again once laid out: the rows under the buttons
        self._check_resume()
        self.query_one("#start", Button).focus()

    def on_screen_resume(self) -> None:
        self.query_one("#start", Button).focus()  # back from a run: the same keys as at start-up
        self.show_notices()
        self._check_resume()
        self.load_devices()

    # ------------------------------------------------------------ database

    @work(thread=True, exclusive=True, group="connect-db", exit_on_error=False, description="list devices")
    def load_devices(self) -> None:
        try:
            store = self.app.session.open_store()
            devices = store.list_devices() if store is not None else []
            self.post_message(StoreLoaded("devices", devices))
            if store is not None:
                self.post_message(StoreLoaded("settings", store.settings()))
        except Exception as exc:  # noqa: BLE001
            self.post_message(StoreLoaded("devices", [], error=str(exc)))

    def on_store_loaded(self, message: StoreLoaded) -> None:
        if message.what == "settings":  # fill what the operator has not typed yet
            for key, widget in LAB_FIELDS.items():
                box = self.query_one(widget, Input)
                if not box.value and message.data.get(key):
                    box.value = message.data[key]
                    self.app.session.extra.setdefault(key, message.data[key])
        if message.what == "devices":
            known = self.query_one("#known", Select)
            self._devices = {d["id"]: d for d in message.data}
            known.set_options([(tui_text(f"{d['id']}  {d.get('model') or ''}".strip()), d["id"]) for d in message.data])

    def show_due(self, due) -> None:
        bad = [d for d in due or [] if d["status"] in ("overdue", "due", "never calibrated")]
        text = ""
        if bad:
            text = (
                "Recalibration "
                + "; ".join(
                    f"{tui_markup(d['device_id'])} {due_when(d) if d['status'] == 'due' else d['status']}"
                    + (f" ({-d['days_left']:.0f} d)" if d["status"] == "overdue" else "")
                    for d in bad[:3]
                )
                + ("; …" if len(bad) > 3 else "")
            )
        for label in self.query("#due"):  # none yet when the due list arrives before this screen is composed
            label.update(text)
            self.call_after_refresh(self.show_notices)  # a due line of two rows leaves one fewer under the buttons

    @on(Select.Changed, "#known")
    def _known_picked(self, event: Select.Changed) -> None:
        d = getattr(self, "_devices", {}).get(event.value)
        if d:
            self.query_one("#serial", Input).value = d["id"]
            self.query_one("#model", Input).value = d.get("model") or ""
            self._check_resume()

    @on(Input.Changed, "#port")
    def _port_typed(self, event: Input.Changed) -> None:
        """A port typed while Source is the simulated device means that port: Source follows
        (the operator sees it switch to Other), so Start never silently runs the simulator."""
        source = self.query_one("#source", Select)
        if event.value.strip() and source.value == SIM:
            source.value = OTHER

    @on(Input.Changed, "#serial")
    def _serial_changed(self) -> None:
        self._check_resume()

    # ------------------------------------------------------------ resume

    def _resume_path(self) -> str | None:
        from station.procedures.state import default_state_path

        s = self.app.session
        if not s.resume_dir() or not registry.resumes(str(self.query_one("#procedure", Select).value)):
            return None  # resume files are P1's (Resume continues an interrupted P1)
        serial = self.query_one("#serial", Input).value.strip() or (
            getattr(s.source, "device_id", "") if s.source is not None else ""
        )
        if not serial and self.query_one("#source", Select).value == SIM:
            from station.sources import SimSource

            serial = SimSource.device_id_for(0, self.query_one("#procedure", Select).value)
        if not serial:
            return None
        return default_state_path(serial, base=s.resume_dir())

    def _check_resume(self) -> None:
        path = self._resume_path()
        button = self.query_one("#resume", Button)
        ok = False
        if path and os.path.exists(path):
            try:
                import json

                with open(path, encoding="utf-8") as fh:
                    state = json.load(fh)
                n = sum(st["status"] == "captured" for st in state["steps"])
                # nothing captured: nothing to continue (an abort before the first position)
                ok = state.get("phase") != "done" and 0 < n < len(state["steps"])
                if ok:
                    button.label = f"Resume {n}/{len(state['steps'])} \\[F6]"
                    button.refresh(layout=True)  # its width follows the label ("[F6]" was cut off)
            except (OSError, ValueError, KeyError, TypeError):
                ok = False
        changed = button.disabled == ok
        button.disabled = not ok
        if not ok:
            button.label = "Resume \\[F6]"
            button.refresh(layout=True)
        if changed:
            self.refresh_bindings()  # F6 in the footer only when there is a run to resume

    def check_action(self, action: str, parameters) -> bool | None:
        if action == "resume":
            buttons = self.query("#resume")
            return bool(buttons) and not buttons.first(Button).disabled
        return True

    # ------------------------------------------------------------ start

    @on(Button.Pressed, "#start")
    def action_start(self) -> None:
        self._start_new()

    def _start_new(self) -> None:
        """Start a new run; with an interrupted P1 to resume, after asking: the new run's first
        position replaced the resume file, and the positions captured before (minutes each at
        the source's averaging time) were gone without a word."""
        from station.screens.decide import ConfirmScreen

        resume = self.query_one("#resume", Button)
        if resume.disabled or self.app.session.scripted:
            self._connect(resume=False)
            return
        kept = str(resume.label).removeprefix("Resume ").split(" ")[0]  # "3/12"
        self.app.push_screen(
            ConfirmScreen(
                f"Start a new run? The interrupted run's {kept} positions are discarded once the new "
                "one captures its first. F6 (Resume) continues them instead."
            ),
            lambda yes: self._connect(resume=False) if yes else None,
        )

    @on(Button.Pressed, "#resume")
    def action_resume(self) -> None:
        if not self.query_one("#resume", Button).disabled:
            self._connect(resume=True)

    @on(Button.Pressed, "#history")
    def action_history(self) -> None:
        from station.screens.history import HistoryScreen

        self.app.push_screen(HistoryScreen())

    @on(Button.Pressed, "#import")
    def action_import_file(self) -> None:
        from station.screens.importfile import ImportScreen

        self.app.push_screen(ImportScreen())

    @on(Input.Submitted)
    def _submitted(self) -> None:
        self._start_new()

    def _connect(self, resume: bool) -> None:
        s = self.app.session
        try:
            average = float(self.query_one("#average", Input).value)
            if not average > 0:
                raise ValueError
        except ValueError:
            self._status("Average (s) must be a positive number of seconds", error=True)
            self.query_one("#average", Input).focus()  # where the fix is typed
            return
        procedure = self.query_one("#procedure", Select).value
        shortest = registry.min_average_s(procedure)
        if average < shortest:  # refused now, not after the whole record
            what = registry.average_means(procedure)
            self._status(f"Average (s) {average:g} is too short: at least {shortest:g} s, {what}", error=True)
            self.query_one("#average", Input).focus()
            return
        if s.average_default and self.query_one("#average", Input).value.strip() != self._offered:
            s.average_default = False  # typed: kept for the next run, whatever the source
        s.average_s = average
        s.resume = resume
        s.procedure = procedure
        s.model = self.query_one("#model", Input).value.strip()
        s.device_id = self.query_one("#serial", Input).value.strip()
        for key, widget in LAB_FIELDS.items():
            s.extra[key] = self.query_one(widget, Input).value.strip()
        choice = self.query_one("#source", Select).value
        port = self.query_one("#port", Input).value.strip()
        if choice == OTHER and not port and not (s.source is not None and s.source.kind == "serial"):
            self._status("Type a port or URL, or choose the simulated device", error=True)
            return
        if choice == SIM and port:  # chosen again after the port was typed: which one is meant?
            self._status(
                f"Source is the simulated device but port {port} is typed: clear the port, or choose Other port or URL",
                error=True,
            )
            return
        if choice not in (SIM, OTHER) and not port:
            port = str(choice)  # a port picked from the list
        self.query_one("#start", Button).disabled = True
        self._status("Connecting…")
        self.open_source(choice, port, self.query_one("#protocol", Select).value)

    def show_notices(self) -> None:
        """The status line and the app's current notices under the buttons (a toast, bottom
        right, covered the buttons at 80x24), in the rows there are between the buttons and the
        footer (3 at 80x24). A refused port (2 rows), the start-up reminder and a notice from
        the run took 5 rows: the screen scrolled and the newest notice was under the footer.
        The status, Connect's latest outcome (an error says what to do next), is kept whole;
        the notices newest first, the newest error among them always, as many as fit; how many
        are not shown is said on the first line."""
        from textual.content import Content

        from station.widgets.notices import current_notices, notice_markup

        if not (self.query("#notices") and self.query("#status")):
            return
        width = max(self.size.width - 2, 20)  # the lines' padding
        buttons = self.query_one("#buttons").region
        rows = max(self.size.height - 1 - buttons.bottom, 1) if buttons.height else 3  # above the footer

        def rows_of(markup: str) -> int:
            return len(Content.from_markup(markup).wrap(width))

        status = self.query_one("#status", Static)
        notices = current_notices(self.app)
        line = self.query_one("#notices", Static)
        if not (self._status_text or notices):  # two empty lines, as they always were
            status.styles.max_height = line.styles.max_height = None
            line.update("")
            line.display = True
            return
        status_rows = min(rows_of(self._status_text), rows) if self._status_text else 0
        status.styles.max_height = status_rows
        free = rows - status_rows
        order = notices[::-1]  # newest first, the newest error before them all
        errors = [n for n in order if n.severity == "error"]
        if errors:
            order.remove(errors[0])
            order.insert(0, errors[0])
        if sum(rows_of(notice_markup(n)) for n in notices) <= free:
            shown = notices
        else:
            room, kept = free - 1, []  # a line says how many are not shown
            for n in order:
                if rows_of(notice_markup(n)) > room:
                    break
                kept.append(n)
                room -= rows_of(notice_markup(n))
            shown = [n for n in notices if n in kept]
        lines = [notice_markup(n) for n in shown]
        dropped = len(notices) - len(shown)
        if dropped and free >= 1:
            more = f"[dim]{dropped} more notice{'s' if dropped > 1 else ''} not shown[/]"
            if not shown and order:  # one row: the count, and as much of the newest (error) as fits
                newest = "newest error" if order[0].severity == "error" else "newest"
                more = f"[dim]{dropped} notices, the {newest}:[/] " + notice_markup(order[0])
            lines.insert(0, more)
        line.update("\n".join(lines))
        line.styles.max_height = free
        line.display = bool(lines) and free > 0
        if notices:  # again when the first goes, so its line goes as the toast would have
            self.set_timer(max(min(n.time_left for n in notices), 0.0) + 0.05, self.show_notices)

    def on_resize(self) -> None:
        self.call_after_refresh(self.show_notices)

    _status_text = ""

    def _status(self, text: str, error: bool = False) -> None:
        text = tui_markup(text)  # device ids, ports and errors come from outside
        self._status_text = f"[b red]{text}[/]" if error else text
        self.query_one("#status", Static).update(self._status_text)
        self.show_notices()

    @work(thread=True, exclusive=True, group="connect", exit_on_error=False, description="open the device")
    def open_source(self, choice, port: str, protocol: str) -> None:
        s = self.app.session
        try:
            src = s.source
            if choice == SIM:
                from station.sources import SimSource

                if src is None or src.kind != "sim" or src.procedure != s.procedure:
                    src = SimSource(seed=0, procedure=s.procedure, speed=float(s.extra.get("sim_speed", 1.0)))
            else:
                from station.sources import SerialSource

                if src is None or src.kind != "serial" or (port and port != src.port):
                    src = SerialSource(port or src.port, protocol=protocol)
            if getattr(src, "_t0", None) is None and src.kind == "sim":
                src.start()
            elif src.kind == "serial" and not src.reader.running:
                src.start()
            device_id = s.device_id or src.device_id or "unknown"
            site = s.extra.get("site")  # `station --site`, else the one remembered
            if s.db_path:
                from db.store import Store
                from station.sources import parse_site, site_text

                store = s.open_store() or Store(s.db_path)
                s.extra["_store"] = store
                store.set_settings({k: s.extra.get(k, "") for k in LAB_FIELDS})
                remembered = store.settings().get("site")
                if site:
                    store.set_settings({"site": site_text(site)})
                elif remembered:
                    try:
                        site = parse_site(remembered)
                    except ValueError:
                        site = None
                known = store.get_device(device_id)
                if known is None or (s.model and known.get("model") != s.model):
                    store.add_device(device_id, model=s.model or None)
            if src.kind == "serial" and site and not src.site:
                src.site = dict(site)  # a serial device does not know where it is
            self.post_message(Connected(src, device_id))
        except Exception as exc:  # noqa: BLE001 - shown as one line
            self.post_message(SourceFailed(failure_text(exc, port)))

    def on_source_failed(self, message: SourceFailed) -> None:
        self.query_one("#start", Button).disabled = False
        self._status(message.error, error=True)

    def on_connected(self, message: Connected) -> None:
        s = self.app.session
        s.source = message.source
        s.device_id = message.device_id
        s.guide = None
        self.query_one("#start", Button).disabled = False
        self._status(f"Connected: {getattr(message.source, 'label', '')}, device {message.device_id}")
        self.app.push_screen(registry.screen_for(s.procedure))
