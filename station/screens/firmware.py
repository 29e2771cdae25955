"""A stored calibration as a flight controller's parameters, from History: ``e`` on the
highlighted calibration.

The console had no way to it: a bench engineer at the TUI found `station export` only in the
README. This box is that command (``station.firmware_export.export`` on the stored
calibration and its capture's metadata, the slot and device id as the capture says them),
written as ``<device>-cal<ID>.<ext>`` in the export folder (the current one), atomically; a
format the calibration cannot go to is refused in the export's own words, nothing written.
"""

from __future__ import annotations

import os

from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import ModalScreen
from textual.widgets import Input, Static

from station.textsafe import tui_markup
from station.widgets.field import Field
from station.widgets.title import footer

# format -> file extension, as the firmware's tools load them (README "Firmware parameters")
FORMATS = {"ardupilot": "param", "px4": "txt", "qgc": "params", "c-header": "h", "json": "json"}


def export_name(device_id: str, calibration_id: int, fmt: str) -> str:
    """``IMU-7-cal12.param``: the device (no folder in it), the calibration and the format's extension."""
    from station.procedures.state import file_name_part

    return f"{file_name_part(device_id)}-cal{calibration_id}.{FORMATS[fmt]}"


class FirmwareScreen(ModalScreen):
    """Export calibration ``calibration_id`` of ``device_id``; stays open for another format."""

    CSS = """
    FirmwareScreen { align: center middle; }
    FirmwareScreen #box { width: 72; height: auto; border: round $primary; background: $surface; padding: 0 1; }
    FirmwareScreen #said { height: auto; }
    FirmwareScreen Input:focus { border: tall $accent; }
    /* History's notice lines show under the box: a toast over them cut them */
    FirmwareScreen ToastHolder { display: none; }
    """
    BINDINGS = [Binding("escape", "app.pop_screen", "Back", priority=True)]

    def __init__(self, calibration_id: int, device_id: str) -> None:
        super().__init__()
        self.calibration_id = calibration_id
        self.device_id = device_id

    def compose(self) -> ComposeResult:
        with Vertical(id="box"):
            yield Static(
                f"[b]Calibration #{self.calibration_id} of {tui_markup(self.device_id)} for a flight controller[/]"
            )
            yield Static("Format: " + ", ".join(FORMATS))
            yield Field(placeholder="ardupilot", id="format")
            yield Static("Enter writes the file in the current folder · esc back")
            yield Static("", id="said")
        yield footer()

    def on_mount(self) -> None:
        self.query_one("#format", Input).focus()

    @on(Input.Submitted, "#format")
    def submitted(self, event: Input.Submitted) -> None:
        fmt = event.value.strip().lower() or "ardupilot"
        if fmt not in FORMATS:
            self._say(f"[b red]no format {tui_markup(fmt)!s}: one of {', '.join(FORMATS)}[/]")
            return
        self._say("Writing…")
        self.write(fmt)

    @work(thread=True, exclusive=True, group="firmware", exit_on_error=False, description="export the calibration")
    def write(self, fmt: str) -> None:
        from station.fileio import atomic_write_text
        from station.firmware_export import export

        try:
            store = self.app.session.open_store()
            if store is None:
                raise RuntimeError("no station database")
            cal = store.calibration(self.calibration_id)
            meta = store.capture_info(cal["capture_id"])["meta"] if cal["capture_id"] is not None else {}
            text = export(cal, meta, fmt)
            folder = self.app.session.extra.get("export_dir") or os.getcwd()
            path = os.path.join(folder, export_name(self.device_id, self.calibration_id, fmt))
            atomic_write_text(path, text)
            said = f"[b green]Wrote {tui_markup(os.path.basename(path))}[/] in {tui_markup(folder)}"
        except Exception as exc:  # noqa: BLE001 - one line in the box, nothing written
            said = f"[b red]Not exported: {tui_markup(str(exc))}[/]"
        self.app.call_from_thread(self._say, said)

    def _say(self, text: str) -> None:
        self.query_one("#said", Static).update(text)
