"""Centrifuge (P2): the guided step list "mount in orientation k, spin at ω rad/s", with a
drawing of mounting k (its axes from above and from the side of the arm, and their
direction cosines), the radius and local g as the operator enters them (stored in the
capture), and the table rate the gyro measures against the asked speed. The station
averages the accelerometer once its output is steady and the rate is at the asked speed
(the stability bar and countdown are the P1 widgets); or the operator types the averages
and the measured speed (``m``, then Enter). Rows that disagree are named at once. At the
end, or ``f`` with at least 10 rows, the table of averages is fitted and the Results
screen shows it. On the simulated centrifuge ``p`` mounts and spins it as asked.

Same pattern as the P1 screen: a thread worker drains the source and feeds the guide
(``station.procedures.centrifuge_guide``), posting replaceable LiveUpdates and GuideEvents.
"""

from __future__ import annotations

from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import Screen
from textual.widgets import Input, Label, OptionList, Static
from textual.worker import get_current_worker

from station.formatting import num
from station.messages import CalibrationReady, GuideEvent, LiveUpdate, SourceFailed
from station.screens._common import GuidedScreenMixin, source_rate_hz
from station.widgets.field import Field
from station.widgets.live import CountdownBar, SteadyBar
from station.widgets.notices import NoticesMixin
from station.widgets.steps import StepList
from station.widgets.title import TitleBar, footer

FIELDS = ("ax", "ay", "az", "speed")


class CentrifugeScreen(NoticesMixin, GuidedScreenMixin, Screen):
    CSS = """
    CentrifugeScreen #steps { width: 22; height: 1fr; border: round $primary; }
    CentrifugeScreen #right { width: 1fr; height: 1fr; padding: 0 1; }
    CentrifugeScreen #prompt { height: 2; }
    CentrifugeScreen #drawing { height: 5; color: $text-muted; }
    CentrifugeScreen #bench { height: 1; }
    CentrifugeScreen #bench Label { width: auto; }
    CentrifugeScreen #bench Input { width: 10; margin-right: 1; }
    CentrifugeScreen #indicators { height: 2; }
    CentrifugeScreen #indicators Static { height: 1; }
    CentrifugeScreen #readouts { height: 2; }
    CentrifugeScreen #manual { height: 1; }
    CentrifugeScreen #manual Label { width: auto; color: $text-muted; }
    CentrifugeScreen #manual Input { width: 1fr; margin-right: 1; }
    CentrifugeScreen #entry-error { height: 1; color: $error; }
    /* the rows it needs (a disagreeing row's reason and the next step ran past two rows) */
    CentrifugeScreen #message { height: auto; min-height: 2; text-style: bold; }
    CentrifugeScreen #progress { height: 1; color: $text-muted; }
    /* notices in the free rows under the progress, not toasts over the entry and the prompt */
    CentrifugeScreen ToastHolder { display: none; }
    CentrifugeScreen #notices { height: auto; max-height: 4; }
    """

    BINDINGS = [
        Binding("m", "manual", "Type row"),
        Binding("s", "skip", "Skip"),
        Binding("r", "redo", "Redo"),
        Binding("a", "ask_abort", "Abort"),
        Binding("f", "finish", "Fit now"),
        Binding("p", "sim_place", "Spin (sim)"),
        Binding("escape", "leave_entry", "Back", show=False),
    ]

    def __init__(self) -> None:
        super().__init__()
        self._shown: dict[str, object] = {}

    def compose(self) -> ComposeResult:
        yield TitleBar("P2 accelerometer, centrifuge")
        with Horizontal():
            yield StepList(id="steps")
            with Vertical(id="right"):
                yield Static("", id="prompt")
                yield Static("", id="drawing")
                with Horizontal(id="bench"):
                    yield Label("Radius ")
                    yield Field(value=f"{self._bench('radius_m', 1.0):g}", id="radius", compact=True)
                    yield Label("m  local g ")
                    yield Field(value=f"{self._bench('g_mps2', 9.8):g}", id="gravity", compact=True)
                    yield Label("m/s^2")
                with Vertical(id="indicators"):
                    yield SteadyBar(id="stability")
                    yield CountdownBar(id="countdown")
                yield Static("", id="readouts")
                with Horizontal(id="manual"):
                    yield Label("m types ")
                    for name in FIELDS:
                        yield Field(placeholder=name, id=f"in-{name}", compact=True)
                yield Static("", id="entry-error")
                yield Static("", id="message")
                yield Static("", id="progress")
                yield Static("", id="notices")
        yield footer()

    def _bench(self, key: str, default: float) -> float:
        """The session's (or the simulated centrifuge's) radius / local g, else ``default``."""
        s = self.app.session
        if key in s.extra:
            return float(s.extra[key])
        src = s.source
        v = getattr(getattr(src, "imu", None), key, None) if getattr(src, "kind", "") == "sim" else None
        return float(v) if isinstance(v, (int, float)) else default

    def on_mount(self) -> None:
        self.query_one("#steps").border_title = "Orientation @ ω"
        self.query_one("#steps").focus()
        self.stream()

    # ------------------------------------------------------------ the worker

    def _make_guide(self, src):
        from station.procedures.centrifuge_guide import CentrifugeConfig, CentrifugeGuide

        s = self.app.session
        kw = {k: s.extra[k] for k in ("speeds_rad_s", "n_orientations") if k in s.extra}
        cfg = CentrifugeConfig(
            average_s=s.average_s,
            settle_s=s.settle_s,
            radius_m=self._bench("radius_m", 1.0),
            g_mps2=self._bench("g_mps2", 9.8),
            **kw,
        )
        return CentrifugeGuide(
            sample_rate_hz=source_rate_hz(src), units=src.units, device_id=s.device_id or src.device_id, config=cfg
        )

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

    def _put(self, selector: str, text, layout: bool = False) -> None:
        """Update a Static only when its text changed (each update costs a repaint); ``layout``
        for one whose height follows its text (the message)."""
        if self._shown.get(selector) != text:
            self._shown[selector] = text
            self.query_one(selector, Static).update(text, layout=layout)  # fixed heights: no re-layout

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
            prompt = f"[b]{step.prompt}[/b]\nRemount or change the speed, then hold it steady"
        self._put("#prompt", prompt)
        from station.procedures.centrifuge_guide import mounting_drawing

        k = step.orientation if step is not None else None
        if k is not None and self._shown.get("_k") != k:
            self._shown["_k"] = k
            self._put("#drawing", "\n".join(mounting_drawing(k, g.config.n_orientations)))
        self.query_one(SteadyBar).show(st)
        self.query_one(CountdownBar).show(st, g.config.average_s)
        r, stats = st.raw, message.stats
        au = self.app.session.source.units.get("accel_unit") or "raw"
        if step is None or not (st.table_rate_rad_s == st.table_rate_rad_s):
            # one row of the 56 beside the steps: "  (no rate measured: asked 12.57)" ran past it
            speed = "" if step is None else f" (not measured, asked {step.speed_rad_s:.2f})"
        else:
            speed = f" of {step.speed_rad_s:.2f} " + ("[green]AT SPEED[/]" if st.at_speed else "[b red]NOT AT SPEED[/]")
        self._put(
            "#readouts",
            f"accel {num(r[0], '8.4f')} {num(r[1], '8.4f')} {num(r[2], '8.4f')} {au}  "
            f"{num(stats.rate_hz, '.0f')} Hz err {stats.parse_errors} drop {stats.dropped}"
            + ("" if stats.connected else " DISCONNECTED")
            + "\n"
            f"table rate (gyro) {num(st.table_rate_rad_s, '.3f')} rad/s{speed}",
        )
        self._put("#message", st.message, layout=True)
        self._put(
            "#progress", f"{st.n_captured}/{len(g.steps)} captured, {st.n_skipped} skipped · t={num(st.t_s, '.0f')} s"
        )

    def on_guide_event(self, message: GuideEvent) -> None:
        g = self.guide
        if g is None:
            return
        with self._lock:
            self.query_one(StepList).show(g.steps, g.index if g.index is not None else -1, set(g.disagreeing))
        if message.kind == "captured":
            self.notify(f"{message.detail.strip()} captured", timeout=2)
        elif message.kind == "disagree":
            self.notify(f"Row {message.detail} (r redoes it)", title="Row disagrees", severity="error", timeout=8)
        elif message.kind == "restarted":
            self.notify(f"{message.detail.strip()}: output changed, averaging restarted", severity="warning", timeout=3)
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

    def action_sim_place(self) -> None:
        """The simulated centrifuge: mount orientation k and spin to the asked speed."""
        g = self.guide
        if g is None or g.step is None:
            return
        with self._lock:
            k, w = g.step.orientation, g.step.speed_rad_s
        self._sim_place(f"{k}@{w!r}", f"Simulated centrifuge: orientation {k}, spinning up to {w:.2f} rad/s")

    @on(Input.Submitted, "#radius, #gravity")
    @on(Input.Blurred, "#radius, #gravity")
    def _bench_entered(self, event) -> None:
        """Radius and local g as entered: positive numbers, into the run's configuration
        (and the capture's metadata); a bad one is one line and changes nothing."""
        from station.procedures.centrifuge_guide import parse_positive

        name, key = ("radius", "radius_m") if event.input.id == "radius" else ("local g", "g_mps2")
        try:
            v = parse_positive(event.input.value, name)
        except ValueError as exc:
            self.query_one("#entry-error", Static).update(str(exc))
            return
        self.query_one("#entry-error", Static).update("")
        self.app.session.extra[key] = v
        if self.guide is not None:
            with self._lock:
                setattr(self.guide.config, key, v)
        if isinstance(event, Input.Submitted):
            self.query_one("#steps").focus()

    @on(Input.Submitted, "#manual Input")
    def _entered(self, event: Input.Submitted) -> None:
        from station.procedures.centrifuge_guide import ManualEntryError

        if self.guide is None:
            return
        ids = [f"#in-{n}" for n in FIELDS]
        k = ids.index(f"#{event.input.id}")
        values = [self.query_one(i, Input).value for i in ids]
        if k < 3 and not all(v.strip() for v in values[k + 1 :]):
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
