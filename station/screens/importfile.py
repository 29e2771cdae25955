"""Import: calibrate a capture file recorded elsewhere (any procedure; P5 LDV runs come
this way, from the vehicle's logger). The conditioning check is the procedure's own: an
ill-conditioned LDV velocity set is refused with one line saying what to drive."""

from __future__ import annotations

import os

from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import Screen
from textual.widgets import Input, Static

from station.messages import CalibrationReady
from station.widgets.title import TitleBar, footer


class ImportScreen(Screen):
    CSS = """
    ImportScreen #body { padding: 1 1; }
    ImportScreen #path { margin: 1 0; }
    ImportScreen #status { height: auto; }
    """
    BINDINGS = [Binding("escape", "app.pop_screen", "Back")]

    def compose(self) -> ComposeResult:
        yield TitleBar("import a capture file")
        with Vertical(id="body"):
            yield Static(
                "Capture file (station-capture CSV, ../shared/spec/capture-format.md). Its\n"
                "'procedure' metadata says how to calibrate it; P5 (LDV) checks that the\n"
                "velocities turn enough to separate the beam angles."
            )
            yield Input(placeholder="path/to/capture.csv, then Enter", id="path")
            yield Static("", id="status")
        yield footer()

    def on_mount(self) -> None:
        self.query_one("#path", Input).focus()

    @on(Input.Submitted, "#path")
    def _go(self, event: Input.Submitted) -> None:
        path = os.path.expanduser(event.value.strip())
        if not path:
            return
        self.query_one("#status", Static).update(f"Reading and calibrating {path}…")
        self.calibrate(path)

    @work(thread=True, exclusive=True, group="import", exit_on_error=False, description="calibrate a file")
    def calibrate(self, path: str) -> None:
        from station.calibrate import calibrate_capture
        from station.capture import read_capture

        try:
            capture = read_capture(path)
        except Exception as exc:  # noqa: BLE001 - InputError: file:line: what is wrong
            self.post_message(CalibrationReady(None, None, error=str(exc)))
            return
        previous = None
        try:
            store = self.app.session.open_store()
            device = capture.meta.get("device")
            if store is not None and device:
                hist = [c for c in store.history(device, capture.procedure) if c["accepted"]]
                previous = hist[-1] if hist else None
        except Exception:  # noqa: BLE001 - no comparison then
            previous = None
        try:
            self.post_message(CalibrationReady(capture, calibrate_capture(capture), previous=previous))
        except Exception as exc:  # noqa: BLE001 - UnsupportedError: one line
            self.post_message(CalibrationReady(capture, None, error=str(exc), previous=previous))

    def on_calibration_ready(self, message: CalibrationReady) -> None:
        status = self.query_one("#status", Static)
        if message.result is None:
            status.update(f"[b red]{message.error}[/]")
            return
        from station.screens.results import ResultsScreen

        self.app.session.device_id = message.capture.meta.get("device") or self.app.session.device_id
        self.app.switch_screen(ResultsScreen(message.capture, message.result, None, message.previous))
