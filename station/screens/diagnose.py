"""Diagnose: the `station diagnose` findings (diagnose.md) for a capture — the one just
calibrated, or a stored calibration's — with its plots of measured minus simulated."""

from __future__ import annotations

from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import VerticalScroll
from textual.screen import Screen
from textual.widgets import Static

from station.messages import StoreLoaded
from station.widgets.notices import NoticesMixin
from station.widgets.title import TitleBar, footer


class DiagnoseScreen(NoticesMixin, Screen):
    CSS = """
    DiagnoseScreen #report { padding: 0 1; }
    DiagnoseScreen ToastHolder { display: none; }
    DiagnoseScreen #notices { height: auto; max-height: 4; padding: 0 1; }
    """
    BINDINGS = [Binding("escape", "app.pop_screen", "Back")]

    def __init__(self, capture=None, calibration_id: int | None = None) -> None:
        super().__init__()
        self.capture = capture
        self.calibration_id = calibration_id
        self.report: str | None = None

    def compose(self) -> ComposeResult:
        what = f"calibration #{self.calibration_id}" if self.calibration_id is not None else "this capture"
        yield TitleBar(f"diagnose {what}")
        with VerticalScroll():
            yield Static("Diagnosing: fitting the baseline and the candidate effects…", id="report")
        yield Static("", id="notices")  # under the report, not a toast over its figures
        yield footer()

    def on_mount(self) -> None:
        self.analyse()

    @work(thread=True, exclusive=True, group="diagnose", exit_on_error=False, description="diagnose")
    def analyse(self) -> None:
        try:
            capture = self.capture
            if capture is None:
                from station.capture import Capture

                store = self.app.session.open_store()
                cal = store.calibration(self.calibration_id)
                meta, columns = store.load_capture(cal["capture_id"])
                capture = Capture(meta=meta, columns=columns)
            from station.procedures.diagnose import analyse, format_text

            result, diag, inp = analyse(capture)
            width = max(40, self.size.width - 6)  # padding and the scroll bar: a wider plot wraps
            text = format_text(result, diag, inp, plots=True, plot_width=width, width=width)
            self.post_message(StoreLoaded("diagnose", text))
        except Exception as exc:  # noqa: BLE001 - one line on screen
            self.post_message(StoreLoaded("diagnose", None, error=str(exc)))

    def on_store_loaded(self, message: StoreLoaded) -> None:
        if message.what != "diagnose":
            return
        report = self.query_one("#report", Static)
        if message.error:
            self.report = ""
            report.update(f"[b red]Cannot diagnose: {message.error}[/]")
        else:
            self.report = message.data
            report.update(Text.from_ansi(message.data))
