"""Results: coefficients ± 1σ with units, the change from the calibration in use (in
sigma), pass or fail against the device's tolerances, limits and the fit's own checks,
the residual per position; save (a FAIL only as rejected with a reason or as an override
with a note), reject, discard, export, report."""

from __future__ import annotations

import math
import os

from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical, VerticalScroll
from textual.css.query import NoMatches
from textual.screen import Screen
from textual.widgets import DataTable, Static

from station.formatting import num, sigma
from station.messages import Exported, Saved, StoreLoaded
from station.procedures import registry
from station.procedures.review import (
    assess,
    param_rows,
    residual_of,
    residual_table,
    review_record,
    shown_residual,
    shown_rows,
)
from station.screens.export import export_files, exported_text
from station.store import kind_added
from station.textsafe import tui_markup
from station.widgets.notices import NoticesMixin
from station.widgets.title import TitleBar, footer

# a longer parameter name is shown on two lines, split after its block ("reference." over
# "declination_deg"): the compass's 25-character reference names made its table 86 columns wide
# at 80x24, the tol column cut off behind a horizontal scrollbar
NAME_WIDTH = 16


def _two_lines(name: str) -> str:
    """``name`` as the parameter table shows it: on two lines, split after its first ".", when it
    is longer than NAME_WIDTH and has one; as it is otherwise."""
    block, dot, field = name.partition(".")
    return f"{block}.\n{field}" if len(name) > NAME_WIDTH and dot and block and field else name


def _change(x) -> str:
    """Δ/σ as the table shows it: one decimal, none from 100 on (-3107 rather than -3107.0: a
    unit against another's calibration; the column stays narrow enough for tol at 80 columns)."""
    big = isinstance(x, (int, float)) and math.isfinite(x) and abs(x) >= 100
    return num(x, "+.0f" if big else "+.1f")


class ResultsScreen(NoticesMixin, Screen):
    SUB_TITLE = "P1 result"
    # the parameters have the focus (its bar shows it; arrows and PgDn scroll them at once),
    # not the summary's scroll container, which nothing showed as focused
    AUTO_FOCUS = "#params"
    CSS = """
    ResultsScreen #notes { height: auto; max-height: 7; }
    /* the notes take the keys (w) where a long warning goes on below their 7 lines: shown as the
       tables show it, and the line under them says how many lines are left and how to reach them */
    ResultsScreen #notes:focus { border-left: thick $accent; }
    ResultsScreen #more { height: auto; padding: 0 1; color: $warning; }
    ResultsScreen #summary { height: auto; padding: 0 1; }
    ResultsScreen #tables { height: 1fr; }
    ResultsScreen DataTable:focus { border-left: thick $accent; }
    /* the parameters as tall as they are (at most two thirds), the per-position rows below
       take the rest: P2's 9 parameters left blank lines above 5 of its 60 rows at 80x24 */
    ResultsScreen #params { height: auto; max-height: 67%; scrollbar-size-vertical: 1; }
    ResultsScreen.-no-residuals #params { height: 1fr; max-height: 100%; }
    ResultsScreen #residuals { height: 1fr; }
    ResultsScreen #saved { height: auto; padding: 0 1; text-style: bold; }
    /* notices are lines under the tables here, not toasts over them (80x24: a toast covered
       the residuals and the last parameters for up to 8 s) */
    ResultsScreen ToastHolder { display: none; }
    ResultsScreen #notices { height: auto; max-height: 4; padding: 0 1; }
    """

    BINDINGS = [
        Binding("s", "save", "Save"),
        Binding("x", "reject", "Reject"),
        Binding("d", "discard", "Discard"),
        Binding("e", "export", "Export"),
        Binding("r", "report", "Report"),
        Binding("g", "diagnose", "Diagnose"),
        Binding("n", "new", "New run"),
        Binding("f2", "history", "History", show=False),  # F1 lists it: the footer keeps to 80 columns
        Binding("l", "limits", "Limits", show=False),  # F1 lists it too
        Binding("w", "notes", "Notes", show=False),  # F1 lists it; the line under cut notes says it
    ]

    def __init__(self, capture, result: dict | None, error: str | None = None, previous: dict | None = None):
        super().__init__()
        self.capture = capture
        self.result = result
        self.error = error
        self.previous = previous
        self.tolerances: dict = {}
        self.device: dict = {}
        self.assessment = None
        self.decision: str | None = None
        self.calibration_id: int | None = None
        self.discarded = False

    def compose(self) -> ComposeResult:
        proc = (self.result or {}).get("procedure") or self.capture.meta.get("procedure", "")
        yield TitleBar(registry.result_title(proc))
        with VerticalScroll(id="notes"):
            yield Static("", id="summary")
        yield Static("", id="more")
        with Vertical(id="tables"):
            yield DataTable(id="params", zebra_stripes=True, cursor_type="row")
            yield DataTable(id="residuals", zebra_stripes=True, cursor_type="row")
        yield Static("", id="saved")
        yield Static("", id="notices")
        yield footer()

    def on_mount(self) -> None:
        notes = self.query_one("#notes", VerticalScroll)
        self.query_one("#more", Static).display = False
        self.watch(notes, "scroll_y", lambda _y: self._more(), init=False)
        self.watch(notes, "virtual_size", lambda _s: self._more(), init=False)
        self.load_device()

    def on_resize(self) -> None:
        self.call_after_refresh(self._more)

    def _more(self) -> None:
        """The line under the notes while some of them are below their box (80x24: a second
        long warning went on out of sight, with nothing but a 2-cell scroll bar to say so)."""
        try:  # (called after a refresh: the screen may be gone by then)
            notes = self.query_one("#notes", VerticalScroll)
            more = self.query_one("#more", Static)
        except NoMatches:
            return
        hidden = round(notes.max_scroll_y - notes.scroll_y)
        more.display = hidden > 0
        if hidden > 0:
            where = "↓ or end scrolls them" if notes.has_focus else "[b]w[/] goes to them, ↓ scrolls"
            more.update(f"▼ {hidden} more line{'s' if hidden != 1 else ''} of the notes above: {where}")

    def action_notes(self) -> None:
        """The notes above the tables take the keys (↑ ↓ PgUp PgDn End scroll them); again: back
        to the parameters."""
        notes = self.query_one("#notes", VerticalScroll)
        if notes.has_focus:
            self.query_one("#params", DataTable).focus()
        else:
            notes.focus()
        self.call_after_refresh(self._more)

    @work(thread=True, exclusive=True, group="results-db", exit_on_error=False, description="read the device")
    def load_device(self) -> None:
        try:
            store = self.app.session.open_store()
            # a capture that names no device is judged against no device's tolerances and limits
            dev = store.get_device(self.app.session.device_id) if store is not None and self._named() else None
            self.post_message(StoreLoaded("device", dev))
        except Exception as exc:  # noqa: BLE001
            self.post_message(StoreLoaded("device", None, error=str(exc)))

    def on_store_loaded(self, message: StoreLoaded) -> None:
        if message.what == "reference":  # the reference changed under a save: judge again
            self.previous, self.decision = message.data, None
            self.draw()
            self.query_one("#saved", Static).update(
                f"[b yellow]Not saved: {tui_markup(message.error)}; judged again against it above: s saves[/]"
            )
            if self.app.session.autosave and not (self.assessment is not None and self.assessment.failed):
                self.action_save()
            return
        if message.what != "device":
            return
        self.device = message.data or {}
        self.tolerances = self.device.get("tolerances") or {}
        self.draw()
        if self.app.session.autosave and self.result is not None:
            if self.assessment is not None and self.assessment.failed:
                self.notify("FAIL: not saved without a decision (s)", severity="error", timeout=8)
            else:
                self.action_save()

    def draw(self) -> None:
        summary = self.query_one("#summary", Static)
        params = self.query_one("#params", DataTable)
        residuals = self.query_one("#residuals", DataTable)
        if self.result is None:
            summary.update(
                f"[b red]No calibration: {tui_markup(self.error)}[/]\n"
                f"{self.capture.n_rows} rows recorded; e exports them as a capture file."
            )
            params.display = residuals.display = False
            return
        r = self.result
        a = self.assessment = assess(r, self.previous, self.device)
        rows, word, reasons = a.rows, a.verdict, a.reasons
        style = {"pass": "b green", "fail": "b white on red"}.get(word, "b")
        prev = (
            f"previous #{self.previous['id']} of {self.previous['time'][:16].replace('T', ' ')}"
            if self.previous
            else "no previous calibration"
        )
        entry = registry.get(r.get("procedure"))
        module = entry.load() if entry is not None else None
        res, unit = shown_residual(r)  # in the unit the parameters below are shown in
        # what the RMS is over where a procedure says (P4: per sample; its diagnosis: block means)
        of = residual_of(r)
        rest = (
            f"residual {num(res, '.3g')} {unit} RMS{' ' + of if of else ''} · "
            f"{registry.count_text(r.get('procedure'), r.get('n_positions', self.capture.n_rows))}"
        )
        # the previous calibration on the next line when the whole would not fit 80 columns
        # (it wrapped between its date and its time); 1 + " WORD " + " " + rest, as drawn
        sep = " · " if 1 + len(word) + 3 + len(rest) + 3 + len(prev) <= 79 else "\n"
        lines = [f"[{style}] {word.upper()} [/] {rest}{sep}{prev}"]
        lines += [f"[red]✗ {tui_markup(x)}[/]" for x in reasons]
        lines += [tui_markup(x) for x in getattr(module, "results_lines", lambda _r: [])(r)]  # its own lines
        lines += [f"[yellow]warning: {tui_markup(w)}[/]" for w in (r.get("warnings") or [])]
        if a.failed:
            lines.append("[b]s[/] decides: save as rejected (reason) or accept as override (note) · [b]n[/] re-do")
        summary.update("\n".join(lines))
        params.clear(columns=True)
        # ok beside the value and its unit: at 80x24 with a calibration in use the table is
        # wider than the screen, and "ok" as its last column was scrolled off
        params.add_columns("param", "value", "± 1σ", "unit", "ok", "in use", "Δ/σ", "tol")
        for row in shown_rows(r, rows):
            ok = {True: "✓", False: "✗", None: ""}[row.ok]
            params.add_row(
                _two_lines(row.name),
                num(row.value, ".7g"),
                sigma(row.sigma),
                row.unit,
                ok,
                num(row.previous, ".7g"),
                _change(row.change_sigma),
                num(row.tolerance, ".3g"),
                height=None,  # a name on two lines (_two_lines) is a row of two
            )
        gyro = r.get("gyro")  # a P1 session's second triad (docs/tabletop-gyro.md)
        if isinstance(gyro, dict) and isinstance(gyro.get("params"), dict):
            prev_g = ((self.previous or {}).get("extra") or {}).get("gyro")
            for row in shown_rows(gyro, param_rows(gyro, prev_g if isinstance(prev_g, dict) else None)):
                params.add_row(
                    "gyro " + row.name,
                    num(row.value, ".7g"),
                    sigma(row.sigma),
                    row.unit,
                    "",
                    num(row.previous, ".7g"),
                    _change(row.change_sigma),
                    "",
                )
            lines.append(
                f"gyro: {gyro.get('n_rotations')} turns between {gyro.get('n_holds')} holds · gravity "
                f"carried to {num(gyro.get('direction_rms_deg'), '.3g')}° RMS"
            )
            summary.update("\n".join(lines))
        elif isinstance(gyro, dict) and gyro.get("error"):
            # the whole reason, escaped: cut at 60 characters it lost what to correct
            lines.append(f"[yellow]gyro not calibrated: {tui_markup(str(gyro['error']))}[/]")
            summary.update("\n".join(lines))
        residuals.clear(columns=True)
        headers, rows_res = residual_table(self.capture, r)  # in the summary's residual unit
        residuals.display = bool(rows_res)
        # without per-position rows (P3, P4, P5) the parameters take the whole height: at 80x24
        # the compass's 19 rows scrolled in 11 lines above 7 blank ones
        self.set_class(not rows_res, "-no-residuals")
        if rows_res:
            residuals.add_columns(*headers)
            for row in rows_res:
                residuals.add_row(*row)

    # ------------------------------------------------------------ actions

    def _can_save(self) -> bool:
        if self.result is None:
            self.notify("Nothing to save: the fit failed", severity="error")
            return False
        if self.calibration_id is not None:
            self.notify(f"Already saved as calibration #{self.calibration_id}")
            return False
        if not self.app.session.db_path:
            self.notify("No database: start with --db PATH to save", severity="error")
            return False
        if not self._named():
            self.query_one("#saved", Static).update(
                "[b red]Not saved: the capture names no device. A log: esc, type its device id "
                "on the import screen. A capture file: add a '# device:' line, or make it with "
                "station import ... --device ID[/]"
            )
            return False
        return True

    def _named(self) -> bool:
        """Whether the capture names its device: one that does not (a CSV imported without
        --device, opened with F7) is not saved under the device the session last used."""
        return self.capture is None or bool(str(self.capture.meta.get("device") or "").strip())

    def action_save(self) -> None:
        if not self._can_save():
            return
        if self.assessment is not None and self.assessment.failed:
            from station.screens.decide import DecideScreen

            self.app.push_screen(DecideScreen(self.assessment.reasons, failed=True), self._decided)
            return
        self._start_save("accepted", "")

    def action_reject(self) -> None:
        if not self._can_save():
            return
        from station.screens.decide import DecideScreen

        reasons = self.assessment.reasons if self.assessment is not None else []
        failed = self.assessment is not None and self.assessment.failed
        self.app.push_screen(DecideScreen(reasons, failed=failed), self._decided)

    def _decided(self, answer) -> None:
        if answer:
            self._start_save(*answer)

    def _start_save(self, decision: str, note: str) -> None:
        self.decision = decision
        self.query_one("#saved", Static).update("Saving…")
        self.save(decision, note)

    @work(thread=True, exclusive=True, group="save", exit_on_error=False, description="save the calibration")
    def save(self, decision: str = "accepted", note: str = "") -> None:
        s = self.app.session
        try:
            from db.store import ReferenceChanged
            from station.store import run_start, save_result

            for key in ("operator", "place", "reference_equipment"):  # entered on Connect
                if s.extra.get(key) and not self.capture.meta.get(key):
                    self.capture.meta[key] = s.extra[key]
            review = review_record(self.assessment or assess(self.result), decision, note)
            review["previous_calibration_id"] = self.previous["id"] if self.previous else None
            # the run's start, with its time of day; None when not this capture's run (an imported file)
            started = run_start(self.capture, getattr(s.guide, "started", None))
            try:
                cal_id = save_result(
                    s.db_path,
                    self.capture,
                    self.result,
                    device_id=s.device_id,
                    operator=s.extra.get("operator") or None,
                    accepted=decision != "rejected",
                    review=review,
                    time=started if isinstance(started, str) else None,
                    judged_reference=self.previous,
                )
            except ReferenceChanged as exc:
                # another process (a second station, calibrate --save) saved a new reference while
                # this result was on screen: nothing saved; judged again against it, as calibrate does
                store = s.open_store()
                # the one in use at the result's own time (a back-dated capture's is not the latest)
                now = store.reference(exc.device_id, exc.procedure, before=exc.at) if store is not None else None
                self.post_message(StoreLoaded("reference", now, error=str(exc)))
                return
            guide = s.guide
            state_path = getattr(guide, "state_path", None)
            if state_path and os.path.exists(state_path):
                os.unlink(state_path)
            from station.store import later_line

            try:
                note = later_line(s.db_path, cal_id)
            except Exception:  # noqa: BLE001 - saved all the same; the note is only a courtesy
                note = None
            self.post_message(Saved(cal_id, note=note))
        except Exception as exc:  # noqa: BLE001
            self.post_message(Saved(None, error=str(exc)))

    def on_saved(self, message: Saved) -> None:
        label = self.query_one("#saved", Static)
        if message.error:
            # what to do with the result still on screen: it is lost on quit unless kept somehow
            label.update(
                f"[b red]Not saved: {tui_markup(message.error)}[/]: "
                "[b]e[/] exports the capture and result to files; [b]s[/] tries again"
            )
            return
        self.calibration_id = message.calibration_id
        how = {
            "rejected": "[b red]Saved as REJECTED calibration",
            "override": "[b yellow]Saved (override) as calibration",
        }.get(self.decision, "[b green]Saved as calibration")
        label.update(f"{how} #{message.calibration_id} for {tui_markup(self.app.session.device_id)}[/]")
        if message.note:  # a back-dated result: where it went in the history, as calibrate --save says it
            self.notify(message.note[:1].upper() + message.note[1:], severity="information", timeout=15, markup=False)
        added = kind_added(self.device, self.result or {})
        if added:  # as calibrate --save says it: the device id may name another unit
            self.notify(
                f"{self.device['id']} was registered for {', '.join(self.device['sensor_kinds'])}, not {added}: "
                f"{added} is now among its sensor kinds (another unit's id?)",
                severity="warning",
                timeout=10,
                markup=False,
            )
        if self.app.session.exit_when_saved:
            self.set_timer(1.0, self.app.exit)

    def action_discard(self) -> None:
        if self.calibration_id is not None:
            self.notify("Already saved; the history keeps it", severity="warning")
            return
        self.discarded = True
        self.query_one("#saved", Static).update("Discarded (not saved).  n new run · ctrl+q quit")

    def action_export(self) -> None:
        self.export()

    @work(thread=True, exclusive=True, group="export", exit_on_error=False, description="export")
    def export(self) -> None:
        from station.calibrate import jsonable

        export_files(
            self,
            self.capture,
            self.capture.meta.get("procedure", "capture"),
            lambda: None if self.result is None else jsonable(self.result),
        )

    def on_exported(self, message: Exported) -> None:
        if message.error:
            self.notify(f"Export failed: {message.error}", severity="error")
        else:
            self.notify(exported_text(message.paths), timeout=8)
            self.exported = message.paths

    def action_report(self) -> None:
        if self.calibration_id is None:
            self.notify("Save first (s): the report is of a stored calibration", severity="warning")
            return
        self.report()

    @work(thread=True, exclusive=True, group="report", exit_on_error=False, description="write the report")
    def report(self) -> None:
        from station.commands.report import write_report

        try:
            folder = self.app.session.extra.get("export_dir") or os.getcwd()
            path = os.path.join(folder, f"calibration-{self.calibration_id}.html")
            store = self.app.session.open_store()
            write_report(store, self.calibration_id, path)
            self.post_message(Exported([path]))
        except Exception as exc:  # noqa: BLE001 - one line on screen
            self.post_message(Exported([], error=str(exc)))

    def action_diagnose(self) -> None:
        from station.screens.diagnose import DiagnoseScreen

        self.app.push_screen(DiagnoseScreen(capture=self.capture))

    def action_new(self) -> None:
        """A new run; asked first when it would lose a result neither saved nor discarded (one
        key dropped a whole run's result unasked, where ctrl+q asks)."""
        from station.screens.decide import new_run

        unsaved = self.result is not None and self.calibration_id is None and not self.discarded
        new_run(self, "This result is not saved and is lost (s saves it, e exports it)." if unsaved else None)

    def action_limits(self) -> None:
        """View and edit the device's absolute limits (as from History); the verdict is drawn
        again with them while the result is not saved yet."""
        from station.screens.limits import LimitsScreen

        if not self.app.session.device_id or not self._named():
            why = "" if self._named() else ": the capture names none"
            self.notify(f"No device to set limits for{why}", severity="warning")
            return
        self.app.push_screen(LimitsScreen(self.app.session.device_id, self.result), self._limits_closed)

    def _limits_closed(self, changed) -> None:
        if not changed:
            return
        if self.calibration_id is not None:
            self.notify(f"Limits saved; calibration #{self.calibration_id} keeps the verdict it was saved with")
            return
        self.load_device()  # the device's record again: tolerances and limits, then draw()

    def action_history(self) -> None:
        from station.screens.history import HistoryScreen

        self.app.push_screen(HistoryScreen())
