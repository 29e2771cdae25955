"""Help: keys and what each screen does (Escape or F1 closes it)."""

from __future__ import annotations

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical, VerticalScroll
from textual.screen import ModalScreen
from textual.widgets import Static

from station.widgets.notices import NoticesMixin
from station.widgets.title import footer

HELP = """\
[b]Calibration station: keys[/]   (esc, F1 or ? closes this; ↑ ↓ scroll)

[b]Everywhere[/]  F1 ? help · ctrl+q quit · tab/shift+tab move · enter choose
            F2 history · ctrl+p command palette
[b]Connect[/]     F5 start · F6 resume a P1 · F7 import a file · F2 history
            Average (s): seconds per position or row, or the record's
            length (P4, noise run); shorter by default on the simulator
[b]Import[/]      enter read the file · F5 calibrate · F6 diagnose · esc back
            F8 the other method a refusal offers (six-position)
[b]P1[/]          s skip · r redo (the current average, or the last captured
            position when done) · enter on a step: redo it · a abort
            (captured positions kept for Resume) · f fit now (≥ 9)
            simulated: p place the unit as asked
[b]P2[/]          m type a row (ax ay az speed, enter) · esc back · s skip
            r redo · enter on a step: redo it · a abort · f fit (≥ 10)
            simulated: p mount and spin as asked
[b]P3, P4[/]      f finish now (P3) · r restart the recording · a abort
            simulated: p sweep, l set level (P3)
            simulated: p rate table (P4 reference IMU)
[b]P5[/]          f finish now · r restart · a abort · simulated: d drive or
            stop, t turns and hills or straight
[b]Noise run[/]   as P4; its result: t accuracy asked · e export · n new run
[b]Results[/]     s save · x reject · d discard · e export (CSV + JSON) ·
            r report · g diagnose · n new run · l the device's limits
            · F2 history · w the notes above the tables (a long
            warning goes on below them: ↓ End scroll, w again back)
[b]History[/]     up/down device · p next parameter · tab to the calibrations,
            g diagnose the one under the cursor · l the device's limits
            · i its recalibration interval (the line over its
            calibrations says when it falls due) · e the one under the
            cursor for a flight controller (ArduPilot .param, PX4,
            QGroundControl .params, C header, JSON) · escape back
[b]Diagnose[/]    (g on Results or History, F6 on Import) the effects in the
            capture that the calibration model leaves out, named as
            `station diagnose` names them · ↑ ↓ scroll the report ·
            esc stops it and goes back (nothing is saved or changed)

[b]P1 in short[/]  Put the unit in each of the 12 positions the drawing
shows and let go. When it is still and in position the station waits a
moment, then averages for the set time (the source asks 3–5 minutes)
and moves on. "WRONG FACE UP" means another face is up: the message
under it says how far off it is (a quarter turn, upside down).
"""


class HelpScreen(NoticesMixin, ModalScreen):
    """The keys. Every line of HELP fits the box at 80 columns with its scroll bar (72
    columns of text): a wrapped line lost its indent and read as another screen's."""

    CSS = """
    HelpScreen { align: center middle; }
    HelpScreen #help { width: 78; max-height: 22; border: round $accent; background: $surface; padding: 0 1; }
    /* the notices of the run underneath on the rows above the keys (the box gives them room),
       not toasts over the box */
    HelpScreen ToastHolder { display: none; }
    HelpScreen #under { dock: bottom; margin-bottom: 1; height: auto; max-height: 4; }
    HelpScreen #notices { height: auto; background: $surface; padding: 0 1; }
    """
    BINDINGS = [
        Binding("escape", "app.pop_screen", "Close"),
        Binding("f1", "app.pop_screen", "Close", show=False),
        Binding("question_mark", "app.pop_screen", "Close", show=False),
    ]

    def compose(self) -> ComposeResult:
        with VerticalScroll(id="help"):
            yield Static(HELP)
        with Vertical(id="under"):  # (a container: "HelpScreen Static" stays the keys)
            yield Static("", id="notices")
        yield footer()  # its own keys: the screen underneath showed its keys here, dead while this is open
