"""Procedure: the guided P1 step list with, for the current position, a drawing of how
to place the unit, live readouts, the stability and orientation indicators and the
averaging countdown. Capture is automatic (still, in position, settle time, average);
the operator can skip, redo or abort.

The source is drained and the guide fed on a thread worker; the screen gets a
replaceable LiveUpdate ~15 times a second and a GuideEvent for each capture.
"""

from __future__ import annotations

import os

from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import Screen
from textual.widgets import OptionList, Static
from textual.worker import get_current_worker

from station.formatting import num
from station.messages import CalibrationReady, GuideEvent, LiveUpdate, SourceFailed
from station.screens._common import GuidedScreenMixin, source_rate_hz, start_source
from station.widgets.live import CountdownBar, OrientationIndicator, PlacementView, Readouts, StabilityBar
from station.widgets.notices import NoticesMixin
from station.widgets.steps import StepList
from station.widgets.title import TitleBar, footer


class ProcedureScreen(NoticesMixin, GuidedScreenMixin, Screen):
    SUB_TITLE = "P1 accelerometer, level table"
    CSS = """
    ProcedureScreen #steps { width: 22; height: 1fr; border: round $primary; }
    ProcedureScreen #right { width: 1fr; height: 1fr; padding: 0 1; }
    ProcedureScreen #placement { height: 9; }
    ProcedureScreen #indicators { height: 3; }
    ProcedureScreen #readouts { height: 4; margin-top: 1; }
    /* two lines: a prompt wider than the panel at 80x24 wraps instead of losing its end */
    ProcedureScreen #message { height: auto; max-height: 2; text-style: bold; }
    ProcedureScreen #progress { height: 1; color: $text-muted; }
    /* notices in the free rows under the progress, not toasts over the readouts and the prompt */
    ProcedureScreen ToastHolder { display: none; }
    ProcedureScreen #notices { height: auto; max-height: 3; }
    """

    BINDINGS = [
        Binding("s", "skip", "Skip"),
        Binding("r", "redo", "Redo"),
        Binding("a", "ask_abort", "Abort"),
        Binding("f", "finish", "Fit now"),
        Binding("p", "sim_place", "Place (sim)"),
    ]

    def compose(self) -> ComposeResult:
        yield TitleBar("P1 accelerometer, level table")
        with Horizontal():
            yield StepList(id="steps")
            with Vertical(id="right"):
                yield PlacementView(id="placement")
                with Vertical(id="indicators"):
                    yield StabilityBar(id="stability")
                    yield OrientationIndicator(id="orientation")
                    yield CountdownBar(id="countdown")
                yield Readouts(id="readouts")
                yield Static("", id="message")
                yield Static("", id="progress")
                yield Static("", id="notices")
        yield footer()

    def on_mount(self) -> None:
        self.query_one("#steps").border_title = "Steps"
        self.stream()

    # ------------------------------------------------------------ the worker

    def _make_guide(self):
        from station.procedures.state import default_state_path
        from station.procedures.tabletop_guide import GuideConfig, P1Guide

        s = self.app.session
        src = s.source
        previous = None
        store = s.open_store()
        if store is not None:
            hist = [c for c in store.history(s.device_id, "accel-tabletop") if c["accepted"]]
            previous = hist[-1] if hist else None
        folder = s.resume_dir()
        state_path = default_state_path(s.device_id, base=folder) if folder else None
        rate = source_rate_hz(src)
        kw = dict(nominal=getattr(src, "nominal", None), previous=previous)
        if s.resume and state_path and os.path.exists(state_path):
            guide = P1Guide.load(state_path, sample_rate_hz=rate, **kw)
        else:
            guide = P1Guide(
                sample_rate_hz=rate,
                accel_unit=src.units.get("accel_unit") or "counts",
                device_id=s.device_id,
                config=GuideConfig(average_s=s.average_s, settle_s=s.settle_s),
                site=getattr(src, "site", None),
                state_path=state_path,
                gyro_unit=src.units.get("gyro_unit") or None,
                **kw,
            )
        guide.previous_calibration = previous
        return guide

    @work(thread=True, exclusive=True, group="stream", exit_on_error=False, description="read the device")
    def stream(self) -> None:
        s = self.app.session
        worker = get_current_worker()
        src = s.source
        try:
            if start_source(src) and src.kind == "serial":
                s.device_id = s.device_id or src.device_id or "unknown"
            with self._lock:
                self.guide = s.guide if s.guide is not None else self._make_guide()
                s.guide = self.guide
        except Exception as exc:  # noqa: BLE001 - one line on screen
            self.post_message(SourceFailed(str(exc)))
            return
        self.post_message(GuideEvent("ready"))
        operator = None
        if s.scripted:
            from station.procedures.tabletop_guide import ScriptedOperator

            operator = ScriptedOperator(src.place, reaction_s=1.0, mistakes={"y_down": "y_up"}, mistake_s=6.0)
        guide = self.guide
        self._pump(
            worker, src, lambda b: guide.update(b.t_s, b.accel, b.gyro, b.temp_c), guide.status, operator, with_hz=True
        )

    # ------------------------------------------------------------ drawing

    def on_live_update(self, message: LiveUpdate) -> None:
        st = message.status
        self.last_status = st
        self.updates += 1
        s = self.app.session
        g = self.guide
        if g is None:
            return
        if st.step_name != getattr(self, "_drawn_step", None):
            self._drawn_step = st.step_name
            step = g.steps[st.step_index]
            self.query_one(PlacementView).show(step.name, step.instruction, step.direction)
        self.query_one(StabilityBar).show(st)
        self.query_one(OrientationIndicator).show(st, g.config.angle_tol_deg)
        self.query_one(CountdownBar).show(st, g.config.average_s)
        self.query_one(Readouts).show(st, message.stats, s.source.units)
        self.query_one("#message", Static).update(st.message)
        self.query_one("#progress", Static).update(f"{st.n_captured}/{st.n_steps} captured · t={num(st.t_s, '.0f')} s")

    def on_guide_event(self, message: GuideEvent) -> None:
        g = self.guide
        if g is None:
            return
        with self._lock:
            self.query_one(StepList).show(g.steps, g.index)
        if message.kind == "captured":
            self.notify(f"{message.detail} captured", timeout=2)
        elif message.kind == "restarted":
            self.notify(message.detail, severity="warning", timeout=3)
        elif message.kind == "done":
            self.fit()

    def on_source_failed(self, message: SourceFailed) -> None:
        self.notify(f"device: {message.error}", severity="error", timeout=10)
        self.query_one("#message", Static).update(f"[b red]device: {message.error}[/]")

    # ------------------------------------------------------------ operator actions

    def action_skip(self) -> None:
        if self.guide is not None:
            with self._lock:
                self.guide.skip()
                events = self.guide.take_events()
            for kind, detail in events:
                self.post_message(GuideEvent(kind, detail))
            self.post_message(GuideEvent("changed"))

    def action_redo(self) -> None:
        if self.guide is not None:
            with self._lock:
                self.guide.redo()
            self.post_message(GuideEvent("changed"))

    @on(OptionList.OptionSelected, "#steps")
    def _step_selected(self, event: OptionList.OptionSelected) -> None:
        if self.guide is not None and event.option.id is not None:
            with self._lock:
                self.guide.select(int(event.option.id))
            self.post_message(GuideEvent("changed"))

    def action_abort(self) -> None:
        if self.guide is not None:
            with self._lock:
                self.guide.abort()
                n = self.guide.n_captured
        else:
            n = 0
        self.workers.cancel_group(self, "stream")
        self.app.session.guide = None
        if n:
            said = f"{n} position{'s' if n != 1 else ''} captured: Resume (F6) continues it"
        else:
            said = "no position captured"
        self.app.notify(f"P1 aborted with {said}", timeout=6)
        self.app.pop_screen()

    def action_sim_place(self) -> None:
        """The simulated device: turn the unit to the asked position (the hand's placement
        error and the rocking as it is set down come with it)."""
        g = self.guide
        if g is None or g.step is None or g.phase in ("done", "aborted"):
            return
        with self._lock:
            name = g.step.name
            st = g.status()
        if st.in_position and st.phase in ("settle", "average"):
            # turning it again would restart the average (a first `p` on x_up, where the unit
            # starts, threw the running average away)
            self.notify(f"The unit is on {name} already: the average goes on", timeout=3)
            return
        self._sim_place(name, f"Simulated unit turned to {name}")

    def action_finish(self) -> None:
        """Fit with the positions captured so far (at least 9 make sense for P1)."""
        if self.guide is not None and self.guide.n_captured >= 9:
            self.fit()
        else:
            self.notify("P1 needs at least 9 captured positions to fit", severity="warning")

    # ------------------------------------------------------------ the fit

    @work(thread=True, exclusive=True, group="fit", exit_on_error=False, description="fit P1")
    def fit(self) -> None:
        self._fit(None)  # the previous calibration rides on the guide (it also checks the steps)

    def on_calibration_ready(self, message: CalibrationReady) -> None:
        self._show_results(message, getattr(self.guide, "previous_calibration", None))
