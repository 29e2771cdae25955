"""Diagnose: the `station diagnose` findings (diagnose.md) for a capture — the one just
calibrated, or a stored calibration's — with its plots of measured minus simulated."""

from __future__ import annotations

import threading
import time

from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import VerticalScroll
from textual.screen import Screen
from textual.widgets import Static

from station.messages import DiagnoseStep, StoreLoaded
from station.textsafe import tui_markup
from station.widgets.notices import NoticesMixin
from station.widgets.title import TitleBar, footer


class DiagnoseScreen(NoticesMixin, Screen):
    """The report, drawn when the diagnosis (in a process of its own: station.diagnose_process)
    is done; until then the step it is at and the time it has taken, each second. Escape stops
    it (nothing is written by a diagnosis: nothing is left half done) and goes back."""

    CSS = """
    DiagnoseScreen #report { padding: 0 1; }
    DiagnoseScreen ToastHolder { display: none; }
    DiagnoseScreen #notices { height: auto; max-height: 4; padding: 0 1; }
    """
    BINDINGS = [Binding("escape", "back", "Back")]

    def __init__(self, capture=None, calibration_id: int | None = None) -> None:
        super().__init__()
        self.capture = capture
        self.calibration_id = calibration_id
        self.report: str | None = None
        self.step = "starting" if capture is not None else "reading the capture from the database"
        self._t0 = time.monotonic()
        self._process = None  # the station.diagnose_process.DiagnosisProcess, once started
        self._stopped = False  # escape (or the screen gone): no process is started after it
        self._lock = threading.Lock()
        self._ticker = None

    def compose(self) -> ComposeResult:
        what = f"calibration #{self.calibration_id}" if self.calibration_id is not None else "this capture"
        yield TitleBar(f"diagnose {what}")
        with VerticalScroll():
            yield Static(self._working(), id="report")
        yield Static("", id="notices")  # under the report, not a toast over its figures
        yield footer()

    def on_mount(self) -> None:
        self._t0 = time.monotonic()
        self._ticker = self.set_interval(1.0, self._tick)
        self.analyse()

    def _working(self) -> str:
        elapsed_s = time.monotonic() - self._t0
        return (
            f"Diagnosing ({elapsed_s:.0f} s): {self.step}…\n\n"
            "A diagnosis fits the baseline model and each candidate effect: 5 s to a few minutes "
            "(longer on a busy machine).\n[b]Esc[/] stops it and goes back; nothing is saved or changed."
        )

    def _tick(self) -> None:
        if self.report is None:
            self.query_one("#report", Static).update(self._working())

    @work(thread=True, exclusive=True, group="diagnose", exit_on_error=False, description="diagnose")
    def analyse(self) -> None:
        from station.diagnose_process import DiagnosisProcess

        try:
            capture = self.capture
            if capture is None:
                from station.capture import Capture

                store = self.app.session.open_store()
                cal = store.calibration(self.calibration_id)
                meta, columns = store.load_capture(cal["capture_id"])
                capture = Capture(meta=meta, columns=columns)
            width = max(40, self.size.width - 6)  # padding and the scroll bar: a wider plot wraps
            process = DiagnosisProcess(capture, width)
            with self._lock:
                if self._stopped:  # escape came first
                    return
                self._process = process
            process.start()
            with self._lock:
                if self._stopped:  # escape came while it started
                    process.cancel()
            for msg in process.messages():
                if "step" in msg:
                    self.post_message(DiagnoseStep(msg["step"]))
                elif "text" in msg:
                    self.post_message(StoreLoaded("diagnose", msg["text"]))
                elif "error" in msg:
                    self.post_message(StoreLoaded("diagnose", None, error=msg["error"]))
        except Exception as exc:  # noqa: BLE001 - one line on screen
            self.post_message(StoreLoaded("diagnose", None, error=str(exc)))

    def on_diagnose_step(self, message: DiagnoseStep) -> None:
        self.step = message.step
        self._tick()

    def on_store_loaded(self, message: StoreLoaded) -> None:
        if message.what != "diagnose":
            return
        if self._ticker is not None:
            self._ticker.stop()
        report = self.query_one("#report", Static)
        if message.error:
            self.report = ""
            report.update(f"[b red]Cannot diagnose: {tui_markup(message.error)}[/]")
        else:
            self.report = message.data
            report.update(Text.from_ansi(message.data))

    def _stop(self) -> bool:
        """Stop a diagnosis still running; whether there was one."""
        with self._lock:
            was_running = not self._stopped and self.report is None
            self._stopped = True
            process = self._process
        if process is not None:
            process.cancel()
        return was_running

    def action_back(self) -> None:
        if self._stop():
            self.notify("Diagnosis stopped: nothing was saved or changed.", timeout=4)
        self.app.pop_screen()

    def on_unmount(self) -> None:
        self._stop()  # the app quitting, or the screen gone another way: the process goes too
