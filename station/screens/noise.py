"""Gyro noise (Allan) run: a guided still hold (the P4 hold screen and ``HoldGuide``) whose
result screen draws the Allan deviation per axis (log-log, textual-plotext) and gives the
angle random walk, the bias instability and how long a P4 run must be for the accuracy
typed in (``station.procedures.noise``, numerics in ``solvers.allan``)."""

from __future__ import annotations

from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.screen import Screen
from textual.widgets import Input, Label, Static
from textual_plotext import PlotextPlot

from station.messages import Exported
from station.procedures.noise import AXES, format_duration, p4_record_verdict
from station.screens.export import export_files, exported_text
from station.screens.gyrodrift import HoldScreen
from station.widgets.field import Field
from station.widgets.notices import NoticesMixin
from station.widgets.title import TitleBar, footer


class NoiseReady(Message):
    """The Allan analysis of the still record: ``report`` or a one-line ``error``."""

    def __init__(self, capture, report, error: str | None = None) -> None:
        super().__init__()
        self.capture = capture
        self.report = report
        self.error = error


class NoiseHoldScreen(HoldScreen):
    """The still recording of the noise run (HoldScreen with its own words and ending)."""

    # the hold screen's layout under this screen's own name: a screen's CSS is loaded with its
    # class, so the inherited rules applied only once a P4 hold screen had been shown
    CSS = HoldScreen.CSS.replace("HoldScreen ", "NoiseHoldScreen ")
    SUBJECT = "gyro noise (Allan) run"
    INSTRUCTION = (
        "Put the unit on a steady surface away from fans and footsteps and do not\n"
        "touch it: the station records the gyro at rest for the set time and\n"
        "computes its Allan deviation (longer records reach longer τ)."
    )
    NAME = "Noise run"

    @work(thread=True, exclusive=True, group="fit", exit_on_error=False, description="Allan analysis")
    def fit(self) -> None:
        if self._fitting:
            return
        self._fitting = True
        from station.procedures.noise import noise_report

        with self._lock:
            capture = self.guide.capture(extra_meta={"operator_tool": "station tui", "run": "gyro-noise"})
            rate = self.guide.sample_rate_hz
        g = [capture.columns[c] for c in ("gx", "gy", "gz")]
        try:
            import numpy as np

            report = noise_report(np.column_stack(g), rate, capture.meta.get("gyro_unit"))
            self.post_message(NoiseReady(capture, report))
        except Exception as exc:  # noqa: BLE001 - one line on screen
            self.post_message(NoiseReady(capture, None, error=str(exc)))

    def on_noise_ready(self, message: NoiseReady) -> None:
        self.workers.cancel_group(self, "stream")
        self.app.switch_screen(AllanScreen(message.capture, message.report, message.error))


class AllanPlot(PlotextPlot):
    """A log-log plotext figure drawn again before each build: plotext takes the log of a
    log-scale figure's data in place when it builds, so a second build (the terminal resized,
    the plot given rows) took the log of the logs, a math domain error for τ < 1 s that stopped
    the TUI. ``draw(plt)`` sets the figure up."""

    def __init__(self, draw, **kwargs) -> None:
        super().__init__(**kwargs)
        self._draw = draw

    def render(self):
        self._draw(self.plt)
        return super().render()


class AllanScreen(NoticesMixin, Screen):
    # nothing focused, so the footer's keys work: Textual's default ("*") gave the accuracy field
    # the focus each time the screen came back (after Help, after a question), and t, e, n
    # were typed into it
    AUTO_FOCUS = ""
    CSS = """
    AllanScreen #plot { height: 1fr; min-height: 8; max-height: 12; }
    AllanScreen #table { height: 5; padding: 0 1; }
    AllanScreen #ask { height: 1; padding: 0 1; }
    AllanScreen #ask Label { width: 26; }
    AllanScreen #accuracy { width: 12; }
    /* the verdict takes the rows it needs (three at 80 columns when one axis never gets there
       and the others are named): two cut "...; x alone needs 3 min, z" off; the plot gives them */
    AllanScreen #status { height: auto; min-height: 2; padding: 0 1; }
    /* notices under the answer (the plot gives them rows if needed), not a toast over the table */
    AllanScreen ToastHolder { display: none; }
    AllanScreen #notices { height: auto; max-height: 4; padding: 0 1; }
    """
    BINDINGS = [
        Binding("t", "accuracy", "Accuracy"),
        Binding("e", "export", "Export"),
        Binding("n", "new", "New run"),
        Binding("escape", "leave_entry", "Back", show=False),
    ]

    def __init__(self, capture, report, error: str | None = None) -> None:
        super().__init__()
        self.capture = capture
        self.report = report
        self.error = error
        self.accuracy_deg_h: float | None = None
        self.exported: list[str] = []

    def compose(self) -> ComposeResult:
        yield TitleBar("gyro noise (Allan) result")
        with Vertical():
            yield AllanPlot(self._draw, id="plot")
            yield Static("", id="table")
            with Horizontal(id="ask"):
                yield Label("P4 accuracy asked (°/h):")
                yield Field(value=f"{self.app.session.extra.get('accuracy_deg_h', 1.0):g}", id="accuracy", compact=True)
                yield Label("  (t, type, Enter)")
            yield Static("", id="status")
            yield Static("", id="notices")
        yield footer()

    def on_mount(self) -> None:
        self.plot()
        if self.report is None:
            self.query_one("#table", Static).update(f"[b red]Allan analysis failed: {self.error}[/]")
            return
        self._answer(self.query_one("#accuracy", Input).value)

    def plot(self) -> None:
        self.query_one("#plot", PlotextPlot).refresh()

    def _draw(self, plt) -> None:
        """The figure, set up again before each build (``AllanPlot``)."""
        plt.clear_data()
        plt.clear_figure()
        r = self.report
        if r is None:
            plt.title("no Allan deviation")
            return
        plt.xscale("log")
        plt.yscale("log")
        for k, (ax, color) in enumerate(zip(AXES, ("red", "green", "blue"))):
            plt.plot(r.taus_s.tolist(), r.adev_deg_h[:, k].tolist(), label=ax, color=color, marker="dot")
        plt.title(f"Allan deviation (°/h) vs τ (s), {r.duration_s:.0f} s record")

    def _table(self, need=None) -> str:
        r = self.report
        lines = [
            "axis  ARW °/√h   bias inst. °/h (τ s)   mean °/h ± 1σ" + ("     P4 needs" if need is not None else "")
        ]
        for k, ax in enumerate(AXES):
            line = (
                f"{ax:>4}  {r.arw_deg_rt_h[k]:8.4f}   {r.bias_instability_deg_h[k]:9.3f} ({r.bias_instability_tau_s[k]:5.0f})"
                f"   {r.mean_deg_h[k]:8.2f} ± {r.sigma_mean_deg_h[k]:.2f}"
            )
            if need is not None:
                line += f"   {format_duration(need[k]):>9}"
            lines.append(line)
        lines.append("axes as the device reports them (P4's result: x forward, y up, z right)")
        return "\n".join(lines)

    def _answer(self, text: str) -> None:
        try:
            acc = float(text)
            need = self.report.time_needed_s(acc)
        except ValueError:
            self.query_one("#status", Static).update("[b red]Type the accuracy as a positive number of °/h[/]")
            self.query_one("#table", Static).update(self._table())
            return
        self.accuracy_deg_h = acc
        self.app.session.extra["accuracy_deg_h"] = acc
        self.query_one("#table", Static).update(self._table(need))
        self.query_one("#status", Static).update(p4_record_verdict(need, acc))

    @on(Input.Submitted, "#accuracy")
    def _accuracy(self, event: Input.Submitted) -> None:
        if self.report is not None:
            self._answer(event.value)
        self.set_focus(None)

    def action_accuracy(self) -> None:
        self.query_one("#accuracy", Input).focus()

    def action_leave_entry(self) -> None:
        self.set_focus(None)

    def action_new(self) -> None:
        """A new run; asked first when the record is not exported (nothing else keeps it: a
        noise run of hours went on one key)."""
        from station.screens.decide import new_run

        kept = self.exported or self.capture is None
        new_run(self, None if kept else "This record is not exported and is lost (e exports it).")

    def action_export(self) -> None:
        self.export()

    @work(thread=True, exclusive=True, group="export", exit_on_error=False, description="export")
    def export(self) -> None:
        export_files(
            self,
            self.capture,
            "gyro-noise",
            lambda: None if self.report is None else self.report.to_json(self.accuracy_deg_h),
        )

    def on_exported(self, message: Exported) -> None:
        if message.error:
            self.notify(f"Export failed: {message.error}", severity="error")
        else:
            self.exported = message.paths
            self.notify(exported_text(message.paths), timeout=8)
