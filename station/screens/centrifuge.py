"""Centrifuge (P2): the guided step list "mount in orientation k, spin at ω rad/s". The
station averages the accelerometer once its output is steady at speed (the stability bar
and countdown are the P1 widgets); or the operator types the averages and the measured
speed (``m``, then Enter). At the end, or ``f`` with at least 10 rows, the table of
averages is fitted and the Results screen shows it.

Same pattern as the P1 screen: a thread worker drains the source and feeds the guide
(``station.procedures.centrifuge_guide``), posting replaceable LiveUpdates and GuideEvents.
"""
from __future__ import annotations

import threading

from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import Screen
from textual.widgets import Footer, Input, Label, OptionList, Static
from textual.worker import get_current_worker

from station.messages import CalibrationReady, GuideEvent, LiveUpdate, SourceFailed
from station.screens._common import GuidedScreenMixin, _n, source_rate_hz
from station.widgets.live import CountdownBar, StabilityBar
from station.widgets.steps import StepList
from station.widgets.title import TitleBar

FIELDS = ("ax", "ay", "az", "speed")


class CentrifugeScreen(GuidedScreenMixin, Screen):
    CSS = """
    CentrifugeScreen #steps { width: 22; height: 1fr; border: round $primary; }
    CentrifugeScreen #right { width: 1fr; height: 1fr; padding: 0 1; }
    CentrifugeScreen #prompt { height: 3; }
    CentrifugeScreen #indicators { height: 2; }
    CentrifugeScreen #indicators Static { height: 1; }
    CentrifugeScreen #readouts { height: 3; margin-top: 1; }
    CentrifugeScreen #manual-title { height: 1; margin-top: 1; color: $text-muted; }
    CentrifugeScreen #manual { height: 1; }
    CentrifugeScreen #manual Label { width: 6; }
    CentrifugeScreen #manual Input { width: 1fr; margin-right: 1; }
    CentrifugeScreen #entry-error { height: 1; color: $error; }
    CentrifugeScreen #message { height: 2; text-style: bold; }
    CentrifugeScreen #progress { height: 1; color: $text-muted; }
    """

    BINDINGS = [
        Binding("m", "manual", "Type values"),
        Binding("s", "skip", "Skip"),
        Binding("r", "redo", "Redo"),
        Binding("a", "abort", "Abort"),
        Binding("f", "finish", "Fit now"),
        Binding("escape", "leave_entry", "Back", show=False),
    ]

    def __init__(self) -> None:
        super().__init__()
        self._lock = threading.Lock()
        self.guide = None
        self.last_status = None
        self.updates = 0
        self._fitting = False
        self._shown: dict[str, object] = {}

    def compose(self) -> ComposeResult:
        yield TitleBar("P2 accelerometer, centrifuge")
        with Horizontal():
            yield StepList(id="steps")
            with Vertical(id="right"):
                yield Static("", id="prompt")
                with Vertical(id="indicators"):
                    yield StabilityBar(id="stability")
                    yield CountdownBar(id="countdown")
                yield Static("", id="readouts")
                yield Static("m: type ax ay az, speed (rad/s), Enter; Esc back", id="manual-title")
                with Horizontal(id="manual"):
                    for name in FIELDS:
                        yield Input(placeholder=name, id=f"in-{name}", compact=True)
                yield Static("", id="entry-error")
                yield Static("", id="message")
                yield Static("", id="progress")
        yield Footer()

    def on_mount(self) -> None:
        self.query_one("#steps").border_title = "Orientation @ ω"
        self.query_one("#steps").focus()
        self.stream()

    # ------------------------------------------------------------ the worker

    def _make_guide(self, src):
        from station.procedures.centrifuge_guide import CentrifugeConfig, CentrifugeGuide

        s = self.app.session
        kw = {k: s.extra[k] for k in ("speeds_rad_s", "n_orientations", "radius_m", "g_mps2") if k in s.extra}
        cfg = CentrifugeConfig(average_s=s.average_s, settle_s=s.settle_s, **kw)
        return CentrifugeGuide(sample_rate_hz=source_rate_hz(src),
                               units=src.units, device_id=s.device_id or src.device_id, config=cfg)

    @work(thread=True, exclusive=True, group="stream", exit_on_error=False, description="read the device")
    def stream(self) -> None:
        s = self.app.session
        worker = get_current_worker()
        src = s.source
        if not self._start_guide(src, lambda: self._make_guide(src)):
            return
        self.post_message(GuideEvent("ready"))
        operator = None
        if s.scripted:
            from station.procedures.centrifuge_guide import CentrifugeOperator

            operator = CentrifugeOperator(src.place)
        guide = self.guide
        self._pump(worker, src, lambda b: guide.update(b.t_s, b.accel, b.gyro, b.temp_c), guide.status, operator)

    # ------------------------------------------------------------ drawing

    def _put(self, selector: str, text) -> None:
        """Update a Static only when its text changed (each update costs a repaint)."""
        if self._shown.get(selector) != text:
            self._shown[selector] = text
            self.query_one(selector, Static).update(text, layout=False)  # fixed heights: no re-layout

    def on_live_update(self, message: LiveUpdate) -> None:
        st = message.status
        self.last_status = st
        self.updates += 1
        g = self.guide
        if g is None:
            return
        step = g.step
        if step is None:
            prompt = "[b]All steps done[/b]"
        elif st.phase == "noise":
            prompt = f"[b]{step.prompt}[/b]\nFirst keep the centrifuge stopped: the noise is measured"
        else:
            prompt = (f"[b]{step.prompt}[/b]\nRadius {g.config.radius_m:g} m. Remount or change the speed, then "
                      "hold it steady")
        self._put("#prompt", prompt)
        self.query_one(StabilityBar).show(st)
        self.query_one(CountdownBar).show(st, g.config.average_s)
        r, stats = st.raw, message.stats
        au = self.app.session.source.units.get("accel_unit") or "raw"
        self._put("#readouts", 
            f"accel {_n(r[0], '9.5f')} {_n(r[1], '9.5f')} {_n(r[2], '9.5f')} {au}\n"
            f"table rate from the gyro {_n(st.table_rate_rad_s, '.3f')} rad/s\n"
            f"{_n(stats.rate_hz, '.0f')} Hz   errors {stats.parse_errors}   dropped {stats.dropped}"
            + ("" if stats.connected else "   DISCONNECTED"))
        self._put("#message", st.message)
        self._put("#progress", 
            f"{st.n_captured}/{len(g.steps)} captured, {st.n_skipped} skipped · t={_n(st.t_s, '.0f')} s")

    def on_guide_event(self, message: GuideEvent) -> None:
        g = self.guide
        if g is None:
            return
        with self._lock:
            self.query_one(StepList).show(g.steps, g.index if g.index is not None else -1)
        if message.kind == "captured":
            self.notify(f"{message.detail.strip()} captured", timeout=2)
        elif message.kind == "restarted":
            self.notify(f"{message.detail.strip()}: output changed, averaging restarted", severity="warning",
                        timeout=3)
        elif message.kind == "done":
            self.fit()

    def on_source_failed(self, message: SourceFailed) -> None:
        self._put("#message", f"[b red]device: {message.error}[/]")

    # ------------------------------------------------------------ operator actions

    def _changed(self) -> None:
        with self._lock:
            events = self.guide.take_events()
        for kind, detail in events:
            self.post_message(GuideEvent(kind, detail))
        self.post_message(GuideEvent("changed"))

    def action_manual(self) -> None:
        self.query_one("#in-ax", Input).focus()

    def action_leave_entry(self) -> None:
        self.query_one("#steps").focus()

    @on(Input.Submitted)
    def _entered(self, event: Input.Submitted) -> None:
        from station.procedures.centrifuge_guide import ManualEntryError

        if self.guide is None:
            return
        ids = [f"#in-{n}" for n in FIELDS]
        k = ids.index(f"#{event.input.id}")
        values = [self.query_one(i, Input).value for i in ids]
        if k < 3 and not all(v.strip() for v in values[k + 1:]):
            self.query_one(ids[k + 1], Input).focus()  # Enter moves on until the row is full
            return
        try:
            with self._lock:
                step = self.guide.enter_manual(*values)
        except ManualEntryError as exc:
            self.query_one("#entry-error", Static).update(str(exc))
            return
        self.query_one("#entry-error", Static).update("")
        for i in ids:
            self.query_one(i, Input).value = ""
        self.query_one("#in-ax", Input).focus()
        self.notify(f"{step.label.strip()} entered by hand", timeout=2)
        self._changed()

    def action_skip(self) -> None:
        if self.guide is not None:
            with self._lock:
                self.guide.skip()
            self._changed()

    def action_redo(self) -> None:
        if self.guide is not None:
            with self._lock:
                self.guide.redo()
            self._changed()

    @on(OptionList.OptionSelected, "#steps")
    def _step_selected(self, event: OptionList.OptionSelected) -> None:
        if self.guide is not None and event.option.id is not None:
            with self._lock:
                self.guide.select(int(event.option.id))
            self._changed()

    def action_abort(self) -> None:
        self._abort("P2 aborted: nothing saved")

    def action_finish(self) -> None:
        from station.procedures.centrifuge_guide import MIN_FIT_ROWS

        ok = False
        if self.guide is not None:
            with self._lock:
                ok = self.guide.finish()
        if ok:
            self._changed()
        else:
            self.notify(f"P2 needs at least {MIN_FIT_ROWS} captured rows to fit", severity="warning")

    # ------------------------------------------------------------ the fit

    @work(thread=True, exclusive=True, group="fit", exit_on_error=False, description="fit P2")
    def fit(self) -> None:
        self._fit("accel-centrifuge")

    def on_calibration_ready(self, message: CalibrationReady) -> None:
        self._show_results(message, message.previous)
