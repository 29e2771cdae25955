"""Import: calibrate or diagnose a file recorded elsewhere.

A station capture is calibrated as its 'procedure' metadata says (P5 LDV runs come this
way, from the vehicle's logger; the conditioning check is the procedure's own). A log — PX4
``.ulg``, ArduPilot ``.bin``/``.tlog``, ROS bag/MCAP, EuRoC/Kalibr CSV — is read by the same
loader as ``station import`` (``station.importers.load``: :func:`read`, then
:func:`capture_of` and :func:`checked` for the procedure picked here); the screen shows what
it found (sensors, rates, device ids, the calibration parameters in use) before the operator
picks the procedure and goes on to a calibration or a diagnosis. The source a PX4 or ArduPilot
log is read from is ``station import --source``'s, from the same registry
(``station.importers.options.SOURCES``); a log that names no device gets a device-id field
(``--device``), without which its result cannot be saved.
"""

from __future__ import annotations

import os
import re

from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, VerticalScroll
from textual.message import Message
from textual.screen import Screen
from textual.widgets import Button, Input, Select, Static

from station.messages import CalibrationReady
from station.textsafe import tui_markup
from station.widgets.field import Field
from station.widgets.title import TitleBar, footer


def procedure_label(name: str) -> str:
    """The procedure picker's words for ``name``: its code and what it calibrates (registry)."""
    from station.importers._common import NAME
    from station.procedures import registry

    p = registry.get(name)
    return f"{p.code} {p.short or NAME.get(p.sensor_kind, p.sensor_kind)}" if p is not None else name


def procedure_options(kinds=None) -> list[tuple[str, str]]:
    """(label, name) of every procedure a log can feed (with ``kinds``: whose sensor it has)."""
    from station.importers.options import primary
    from station.procedures import registry

    return [(procedure_label(n), n) for n in registry.importable() if kinds is None or primary(n) in kinds]


# A CSV whose columns the reader cannot name needs a column map, given on the command line
PLAIN_CSV_ROUTE = (
    "A plain CSV needs its columns named: in a shell, station import FILE --procedure P "
    "--map t=COL,ax=COL,... --unit accel=UNIT,... --out CAPTURE, then import that capture here."
)


class LogRead(Message):
    """A worker read a log: its format and the importer's :class:`Imported` (or an error)."""

    def __init__(
        self,
        path: str,
        fmt: str | None,
        imported,
        error: str | None = None,
        source: str = "auto",
        hint: str = "",
        instance: int | None = None,
    ) -> None:
        super().__init__()
        self.source = source
        self.instance = instance
        self.hint = hint  # a line under the error: what to do instead
        self.path = path
        self.fmt = fmt
        self.imported = imported
        self.error = error


class CaptureBuilt(Message):
    """The capture of the log for the procedure picked, on its way to a diagnosis."""

    def __init__(self, capture, error: str | None = None) -> None:
        super().__init__()
        self.capture = capture
        self.error = error


WIDTH = 76  # 80 columns less the padding and the scroll bar
SHOWN_WARNINGS = 2  # warnings the summary has room for at 80x24
# a reader's warning's "give --instance N" (station import's flag), said as this screen's choice
INSTANCE_HERE = "pick its slot under instance"
_FLAG = re.compile(r"--instance (\d+)")


def source_options(fmt: str | None) -> list[tuple[str, str]]:
    """(label, value) of the sources ``fmt`` is read from (``station import --source``): the one
    registry, station.importers.options.SOURCES; PX4's where the format has none."""
    from station.importers.options import SOURCES

    return [(s.label, s.value) for s in SOURCES.get(fmt or "", SOURCES["px4"])]


_SOURCE_FLAG = re.compile(r"--source (\w+)")


def in_screen_terms(text: str, fmt: str | None = None) -> str:
    """A reader's warning or refusal worded with ``station import``'s flag, in this screen's
    terms: ``--instance N`` is the slot picked under instance (``instance N``), "give
    --instance N" is picking it there, "--instance 0 or none" is instance 0 or auto. The
    flag appeared as such where the screen read a slot a secondary sensor lacks ("--instance
    1: no MAG[1] ..."), a flag the screen has nowhere to type."""
    from station.importers._common import INSTANCE_ADVICE
    from station.importers.options import SOURCES

    labels = {s.value: s.label for s in SOURCES.get(fmt or "", ())}
    if labels:  # "--source batch reads them": the source picked here, by its words on the screen
        text = _SOURCE_FLAG.sub(
            lambda m: f"source '{labels[m.group(1)]}'" if m.group(1) in labels else m.group(0), text
        )
    text = text.replace(INSTANCE_ADVICE, INSTANCE_HERE).replace("--instance 0 or none", "instance 0 or auto")
    return _FLAG.sub(r"instance \1 (the slot picked)", text).replace("--instance", "instance")


INSTANCES = 4  # the slots offered (PX4's CAL_*0_ID … CAL_*3_ID; ArduPilot and MAVLink have 3)
# the logs read with station import --instance: what the instance chooses in each
SLOT_HELP = {
    "px4": "the sensor's slot: uORB instance, CAL_*n_ID",
    "ardupilot": "the IMU and compass: IMU[n], MAG[n]",
    "tlog": "the IMU: RAW_IMU, SCALED_IMU2, SCALED_IMU3",
}


def _wrapped(items: list[str], indent: str, max_lines: int) -> list[str]:
    """``items`` joined by two spaces, wrapped at WIDTH, at most ``max_lines`` (then '+N more')."""
    lines: list[str] = []
    line = indent
    for i, item in enumerate(items):
        last = len(lines) + 1 == max_lines
        if len(line) + len(item) + 2 > WIDTH - (12 if last else 0) and line.strip():
            if last:
                lines.append(line + f"(+{len(items) - i} more)")
                return lines
            lines.append(line.rstrip())
            line = indent
        line += item + "  "
    if line.strip():
        lines.append(line.rstrip())
    return lines


def summary_lines(path: str, fmt: str, imported) -> list[str]:
    """What the loader found, as plain text lines of at most 76 characters (markup-escape them)."""
    import textwrap

    import numpy as np

    from station.textsafe import safe

    meta = imported.meta
    head = f"{os.path.basename(path)}: {fmt}"
    if meta.get("firmware") and meta["firmware"] != fmt:
        head += f", firmware {meta['firmware']}"
    if meta.get("corrected") is not None:
        head += f", corrected by the board: {meta['corrected']}"
    lines = textwrap.wrap(safe(head), WIDTH) or [""]
    short = {"accel": "accel", "gyro": "gyro", "mag": "mag"}
    for kind, s in imported.streams.items():
        t = np.asarray(s.t_s, dtype=float)
        d = np.diff(t)
        d = d[d > 0]
        rate = f"{1.0 / float(np.median(d)):.4g} Hz" if len(d) else "one sample"
        span = float(t[-1] - t[0]) if len(t) else 0.0
        ident = f", id {s.device_id}" if s.device_id else ""
        text = f"{short[kind]:<5} {len(t)} samples, {rate}, {span:.0f} s, {s.unit}{ident} ({s.source})"
        lines += textwrap.wrap(safe(text), WIDTH, initial_indent="  ", subsequent_indent="        ")
    if not imported.streams:
        lines.append("  no accelerometer, gyro or magnetometer data")
    params = {k[len("param.") :]: v for k, v in meta.items() if k.startswith("param.")}
    if params:
        lines.append(f"in use: {len(params)} calibration parameters")
        ids = [k for k in params if k.endswith("_ID") or k.endswith("DEV_ID")]
        rest = [k for k in params if k not in ids]
        lines += _wrapped([safe(f"{k}={params[k]}") for k in ids + rest], "  ", 3)
    else:
        lines.append("in use: no calibration parameters in the log (an export cannot compose)")
    for w in imported.warnings[:SHOWN_WARNINGS]:
        w = in_screen_terms(w, fmt)  # the flags are this screen's choices
        lines += textwrap.wrap(safe(f"warning: {w}"), WIDTH, subsequent_indent="  ")
    more = len(imported.warnings) - SHOWN_WARNINGS
    if more > 0:  # the screen has room for two; the rest are not dropped unsaid
        text = f"… and {more} more warning{'s' if more > 1 else ''}: station import {os.path.basename(path)} prints them all"
        lines += textwrap.wrap(safe(text), WIDTH, subsequent_indent="  ")
    return lines


class ImportScreen(Screen):
    CSS = """
    ImportScreen #body { padding: 0 1; }
    ImportScreen #path { margin: 1 0 0 0; }
    ImportScreen #status { height: auto; }
    ImportScreen #found { height: auto; margin-top: 1; }
    ImportScreen #device { height: auto; }
    ImportScreen #device-id { display: none; width: 60; }
    ImportScreen #device-id.shown { display: block; }
    ImportScreen #choose { height: 1; display: none; }
    ImportScreen #choose.shown { display: block; }
    ImportScreen #choose Select { width: 24; margin-right: 2; }
    ImportScreen #choose #source { width: 16; }
    ImportScreen #slot { height: 1; display: none; }
    ImportScreen #slot.shown { display: block; }
    ImportScreen #slot Select { width: 16; margin-right: 2; }
    ImportScreen #choose Button { margin-right: 2; }
    """
    BINDINGS = [
        Binding("escape", "app.pop_screen", "Back"),
        Binding("f5", "calibrate_log", "Calibrate", show=False),
        Binding("f6", "diagnose_log", "Diagnose", show=False),
        Binding("f8", "alternative", "Six-position fit"),  # shown only when a refusal offers it
    ]

    def __init__(self) -> None:
        super().__init__()
        self.path: str | None = None
        self.fmt: str | None = None
        self.imported = None
        self.source = "auto"
        self.instance: int | None = None  # station import --instance (PX4, ArduPilot, MAVLink)
        self.refused = None  # (capture, method): a capture refused with a method it does allow

    def check_action(self, action: str, parameters) -> bool | None:
        if action == "alternative":
            return self.refused is not None  # the key is in the footer only when it can do something
        return True

    def compose(self) -> ComposeResult:
        yield TitleBar("import a log or capture file")
        with VerticalScroll(id="body"):
            yield Static("A station capture, or a log: .ulg, .bin, .tlog, ROS bag/MCAP, EuRoC/Kalibr CSV")
            yield Field(placeholder="path/to/file, then Enter", id="path", compact=True)
            yield Static("", id="status")
            with Horizontal(id="choose"):
                yield Select(procedure_options(), id="procedure", allow_blank=False, compact=True)
                yield Select(
                    source_options("px4"),
                    id="source",
                    allow_blank=False,
                    compact=True,
                )
                yield Button("Calibrate \\[F5]", id="calibrate", variant="primary", compact=True)
                yield Button("Diagnose \\[F6]", id="diagnose", compact=True)
            with Horizontal(id="slot"):  # PX4, ArduPilot, MAVLink: station import --instance
                yield Select(
                    [("instance auto", "auto")] + [(f"instance {n}", str(n)) for n in range(INSTANCES)],
                    id="instance",
                    allow_blank=False,
                    compact=True,
                )
                yield Static(SLOT_HELP["px4"], id="slot-help")
            yield Static("", id="device")
            # a log that names no device (ArduPilot, MAVLink, CSV): the operator names it, as
            # station import --device does; without one the result cannot be saved
            yield Field(placeholder="device id, needed to save (e.g. quad-7-imu0)", id="device-id", compact=True)
            yield Static("", id="found")
        yield footer()

    def on_mount(self) -> None:
        self.query_one("#path", Input).focus()

    def _status(self, text: str) -> None:
        self.query_one("#status", Static).update(text)

    @on(Input.Submitted, "#path")
    def _go(self, event: Input.Submitted) -> None:
        path = os.path.expanduser(event.value.strip())
        if not path:
            return
        self.imported = None
        self.refused = None
        self.refresh_bindings()
        self.query_one("#found", Static).update("")
        self.query_one("#device", Static).update("")
        self.query_one("#device-id").remove_class("shown")
        self.query_one("#choose").remove_class("shown")
        self.query_one("#slot").remove_class("shown")
        self._status(f"Reading {tui_markup(path)}…")
        self.query_one("#source", Select).value = "auto"
        self.query_one("#instance", Select).value = "auto"
        self.instance = None
        self.read_file(path)

    @on(Select.Changed, "#source")
    def _reread(self, event: Select.Changed) -> None:
        """The source the log is read from (``station import --source``, the registry's): PX4's raw
        per-sensor topics or sensor_combined, ArduPilot's IMU, ACC/GYR or ISBH/ISBD batches."""
        from station.importers.options import SOURCES

        if self.imported is None or self.fmt not in SOURCES or event.value == self.source:
            return
        self._status(f"Reading {tui_markup(self.path)} ({event.value})…")
        self.read_file(self.path, str(event.value), self.instance, self._procedure())

    @on(Select.Changed, "#instance")
    def _reread_instance(self, event: Select.Changed) -> None:
        """The sensor's slot (``station import --instance``: PX4's uORB instance, ArduPilot's
        IMU and compass, MAVLink's IMU), read for the procedure picked (PX4: a slot the other
        sensors lack leaves them out, as on the command line)."""
        instance = None if event.value == "auto" else int(event.value)
        if self.imported is None or self.fmt not in SLOT_HELP or instance == self.instance:
            return
        self._status(f"Reading {tui_markup(self.path)} (instance {event.value})…")
        self.read_file(self.path, self.source, instance, self._procedure())

    @work(thread=True, exclusive=True, group="import", exit_on_error=False, description="read a file")
    def read_file(
        self, path: str, source: str = "auto", instance: int | None = None, procedure: str | None = None
    ) -> None:
        from station.errors import StationError
        from station.importers import load
        from station.importers.options import ImportOptions

        try:
            fmt = load.detect(path)
            if fmt is None and os.path.isfile(path) and load.is_station_capture(path):
                self._calibrate_capture(path)
                return
            # no log format, no station capture: a CSV read by its column names (a path that is
            # not there is said so alone: the route to --map is no answer to a typo)
            plain = fmt is None and os.path.exists(path)
            fmt = fmt or "csv"
            try:
                opts = ImportOptions(source=source, instance=instance)
                if instance is not None:  # the procedure's sensor must have the slot, the others may lack it
                    opts.procedure = procedure
                imported = load.read(path, opts, fmt)
            except StationError as exc:
                if not plain:
                    raise
                # the reader's hint names --map, which this screen has nowhere to type
                self.post_message(LogRead(path, None, None, error=str(exc), hint=PLAIN_CSV_ROUTE))
                return
            self.post_message(LogRead(path, fmt, imported, source=source, instance=instance))
        except (StationError, OSError, ValueError) as exc:  # one line: file: what is wrong
            self.post_message(LogRead(path, None, None, error=str(exc)))

    def _calibrate_capture(self, path: str, capture=None, method: str | None = None) -> None:
        """In the worker: calibrate a capture (read from ``path`` unless given) with ``method``
        (None: the procedure's default), compare with the device's last accepted calibration,
        hand the result over; a refusal that names a method the capture allows offers it."""
        from station.calibrate import calibrate_capture
        from station.capture import read_capture
        from station.errors import UnsupportedError

        try:
            capture = capture if capture is not None else read_capture(path)
        except Exception as exc:  # noqa: BLE001 - InputError: file:line: what is wrong
            self.post_message(CalibrationReady(None, None, error=str(exc)))
            return
        previous = None
        try:
            store = self.app.session.open_store()
            device = capture.meta.get("device")
            if store is not None and device:
                from station.store import previous_at

                # at the capture's date: an older log is judged against the calibration of its day
                started = getattr(self.app.session.guide, "started", None)
                previous = previous_at(store, device, capture.procedure, capture, started)
        except Exception:  # noqa: BLE001 - no comparison then
            previous = None
        try:
            self.post_message(CalibrationReady(capture, calibrate_capture(capture, method), previous=previous))
        except UnsupportedError as exc:  # one line, and perhaps a method the capture allows
            alternative = exc.alternative if method is None else None
            self.post_message(CalibrationReady(capture, None, str(exc), previous, alternative=alternative))
        except Exception as exc:  # noqa: BLE001 - one line
            self.post_message(CalibrationReady(capture, None, error=str(exc), previous=previous))

    def action_alternative(self) -> None:
        """F8 after a refusal that offers another method (a P1 capture with the six labelled
        ±axis positions: the six-position solution), the CLI's ``--method``."""
        if self.refused is None:
            return
        capture, method = self.refused
        self.refused = None
        self.refresh_bindings()
        self._status(f"Calibrating {tui_markup(os.path.basename(capture.path or 'the capture'))} ({method})…")
        self.calibrate_with(capture, method)

    @work(thread=True, exclusive=True, group="import", exit_on_error=False, description="calibrate")
    def calibrate_with(self, capture, method: str) -> None:
        self._calibrate_capture(capture.path, capture, method)

    def on_log_read(self, message: LogRead) -> None:
        from station.importers.options import SOURCES

        if message.error:
            hint = f"\n{tui_markup(message.hint)}" if message.hint else ""
            if self.imported is not None and message.path == self.path:
                # a re-read (another slot or source) refused: the choices go back to the read shown,
                # which is still the one F5/F6 would take
                self.query_one("#source", Select).value = self.source
                self.query_one("#instance", Select).value = "auto" if self.instance is None else str(self.instance)
                shown = f"instance {'auto' if self.instance is None else self.instance}"
                label = dict((v, k) for k, v in source_options(self.fmt)).get(self.source, self.source)
                shown += f", source '{label}'" if self.fmt in SOURCES else ""  # its words on the screen
                hint += f"\nStill shown: the log as read with {shown}."
            fmt = self.fmt if self.imported is not None and message.path == self.path else None
            self._status(f"[b red]{tui_markup(in_screen_terms(message.error, fmt))}[/]{hint}")
            return
        from station.importers.options import primary

        self.path, self.fmt, self.imported = message.path, message.fmt, message.imported
        self.source = message.source
        self.instance = message.instance
        source = self.query_one("#source", Select)
        source.display = self.fmt in SOURCES
        if self.fmt in SOURCES:  # this format's sources, the choice showing the one read
            with source.prevent(Select.Changed):
                source.set_options(source_options(self.fmt))
                source.value = self.source
                source.mutate_reactive(Select.value)  # the label of a value that stayed (auto) is redrawn too
        self.query_one("#slot").set_class(self.fmt in SLOT_HELP, "shown")
        self.query_one("#slot-help", Static).update(tui_markup(SLOT_HELP.get(self.fmt, "")))
        kinds = set(self.imported.streams)
        options = procedure_options(kinds)
        fits = [name for _, name in options]
        found = summary_lines(message.path, message.fmt, self.imported)
        self.query_one("#found", Static).update("\n".join(tui_markup(line) for line in found))
        if not fits:
            self._status("[b red]nothing to calibrate: no sensor a procedure needs[/]")
            return
        select = self.query_one("#procedure", Select)
        keep = select.value if select.value in fits else None
        select.set_options(options)
        # a magnetometer alone: the one procedure that calibrates it (load.infer_procedure's rule)
        only_mag = [n for n in fits if primary(n) == "mag"] if kinds == {"mag"} else []
        select.value = keep or (only_mag or fits)[0]
        self.query_one("#choose").add_class("shown")
        self._status("Pick the procedure, then Calibrate (F5) or Diagnose (F6).")
        self._show_device()
        select.focus()

    @on(Select.Changed, "#procedure")
    def _show_device(self) -> None:
        """The device id the capture will carry (PX4: board, uid and the procedure's sensor)."""
        procedure = self._procedure()
        if self.imported is None or procedure is None:
            return
        device = self._log_device(procedure)
        self.query_one("#device", Static).update(f"device {tui_markup(device)}" if device else "")
        self.query_one("#device-id").set_class(not device, "shown")

    def _log_device(self, procedure: str) -> str | None:
        """The device the log names for ``procedure`` (PX4: board, uid and the sensor), or None."""
        from station.importers.options import primary

        if self.fmt == "px4":
            from station.importers import px4

            return px4.default_device(self.imported, primary(procedure))
        return self.imported.meta.get("device")

    def _device(self, procedure: str) -> str | None:
        """The capture's device: the one typed where the log names none (``--device``)."""
        if self._log_device(procedure):
            return None  # capture_of names it, as station import does
        return self.query_one("#device-id", Input).value.strip() or None

    def _procedure(self) -> str | None:
        value = self.query_one("#procedure", Select).value
        return value if isinstance(value, str) else None

    @on(Button.Pressed, "#calibrate")
    def action_calibrate_log(self) -> None:
        procedure = self._procedure()
        if self.imported is None or procedure is None:
            return
        self._status(f"Calibrating {tui_markup(os.path.basename(self.path))} as {procedure}…")
        self.build(procedure, diagnose=False, device=self._device(procedure))

    @on(Button.Pressed, "#diagnose")
    def action_diagnose_log(self) -> None:
        procedure = self._procedure()
        if self.imported is None or procedure is None:
            return
        self._status(f"Preparing {tui_markup(os.path.basename(self.path))} for a diagnosis as {procedure}…")
        self.build(procedure, diagnose=True, device=self._device(procedure))

    @work(thread=True, exclusive=True, group="import", exit_on_error=False, description="import a log")
    def build(self, procedure: str, diagnose: bool, device: str | None = None) -> None:
        from station.errors import StationError
        from station.importers import load

        try:
            capture, _ = load.capture_of(self.path, self.imported, self.fmt, procedure, device)
            capture = load.checked(self.path, capture)
        except (StationError, OSError, ValueError) as exc:
            self.post_message(CaptureBuilt(None, error=str(exc)))
            return
        if diagnose:
            self.post_message(CaptureBuilt(capture))
        else:
            self._calibrate_capture(self.path, capture)

    def on_capture_built(self, message: CaptureBuilt) -> None:
        if message.error:
            self._status(f"[b red]{tui_markup(message.error)}[/]")
            return
        from station.screens.diagnose import DiagnoseScreen

        self.app.session.device_id = message.capture.meta.get("device") or self.app.session.device_id
        self.app.push_screen(DiagnoseScreen(message.capture))

    def on_calibration_ready(self, message: CalibrationReady) -> None:
        if message.result is None:
            text = f"[b red]{tui_markup(message.error)}[/]"
            if message.alternative and message.capture is not None:
                self.refused = (message.capture, message.alternative)
                text += f"\nF8 calibrates it with the {tui_markup(message.alternative)} method instead."
            self._status(text)
            self.refresh_bindings()
            return
        from station.screens.results import ResultsScreen

        self.app.session.device_id = message.capture.meta.get("device") or self.app.session.device_id
        self.app.switch_screen(ResultsScreen(message.capture, message.result, None, message.previous))
