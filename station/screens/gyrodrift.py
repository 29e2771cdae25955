"""Gyro drift (P4, static base): place the unit level at a known heading and keep it
still while the station records (P4 asks for at least 3 minutes). The stability bar and
countdown are the P1 widgets; moving restarts the recording.

Same pattern as the P1 screen: a thread worker drains the source and feeds the guide."""
from __future__ import annotations

import math
import threading

from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import Screen
from textual.widgets import Footer, Static
from textual.worker import get_current_worker

from station.messages import CalibrationReady, GuideEvent, LiveUpdate, SourceFailed
from station.screens._common import GuidedScreenMixin, _n, source_rate_hz
from station.widgets.live import CountdownBar, StabilityBar
from station.widgets.title import TitleBar

SIM_FRAME = "x forward, y left, z up"  # the simulated unit lies level with z up


class HoldScreen(GuidedScreenMixin, Screen):
    CSS = """
    HoldScreen #body { padding: 0 1; }
    HoldScreen #instruction { height: 4; }
    HoldScreen #indicators { height: 2; margin-top: 1; }
    HoldScreen #readouts { height: 3; margin-top: 1; }
    HoldScreen #message { height: 1; text-style: bold; margin-top: 1; }
    """
    BINDINGS = [Binding("r", "restart", "Restart"), Binding("a", "abort", "Abort")]

    def __init__(self) -> None:
        super().__init__()
        self._lock = threading.Lock()
        self.guide = None
        self.last_status = None
        self.updates = 0
        self._fitting = False

    SUBJECT = "P4 gyro drift, static base"
    INSTRUCTION = ("Put the unit on a level, steady surface, forward (x) axis pointing north\n"
                   "(heading 0°), and do not touch it: the station records the gyro at rest\n"
                   "and removes the Earth's rotation. Walking on a wooden floor shows here.")
    NAME = "P4"

    def compose(self) -> ComposeResult:
        yield TitleBar(self.SUBJECT)
        with Vertical(id="body"):
            yield Static(self.INSTRUCTION, id="instruction")
            with Vertical(id="indicators"):
                yield StabilityBar(id="stability")
                yield CountdownBar(id="countdown")
            yield Static("", id="readouts")
            yield Static("", id="message")
        yield Footer()

    def on_mount(self) -> None:
        self.stream()

    @work(thread=True, exclusive=True, group="stream", exit_on_error=False, description="read the device")
    def stream(self) -> None:
        from station.procedures.gyrodrift_guide import HoldConfig, HoldGuide

        s = self.app.session
        worker = get_current_worker()
        src = s.source

        def make_guide():
            frame = s.extra.get("frame") or (SIM_FRAME if src.kind == "sim" else "")
            cfg = HoldConfig(duration_s=s.average_s, settle_s=s.settle_s, frame=frame)
            return HoldGuide(sample_rate_hz=source_rate_hz(src), units=src.units,
                             device_id=s.device_id or src.device_id, site=getattr(src, "site", None), config=cfg)

        if not self._start_guide(src, make_guide):
            return
        guide = self.guide
        self._pump(worker, src, lambda b: guide.update(b.t_s, b.accel, b.gyro, b.temp_c), guide.status)

    def on_live_update(self, message: LiveUpdate) -> None:
        st = message.status
        self.last_status = st
        self.updates += 1
        g = self.guide
        self.query_one(StabilityBar).show(st)
        self.query_one(CountdownBar).show(st, g.config.duration_s if g else math.nan)
        m, stats = st.gyro_mean, message.stats
        unit = self.app.session.source.units.get("gyro_unit") or "raw"
        self.query_one("#readouts", Static).update(
            f"mean rate so far  {_n(m[0], '10.6f')} {_n(m[1], '10.6f')} {_n(m[2], '10.6f')} {unit}\n"
            f"{st.n_samples} samples   temp {_n(st.temp_c, '.1f')} °C\n"
            f"{_n(stats.rate_hz, '.0f')} Hz   errors {stats.parse_errors}   dropped {stats.dropped}"
            + ("" if stats.connected else "   DISCONNECTED"))
        self.query_one("#message", Static).update(st.message)

    def on_guide_event(self, message: GuideEvent) -> None:
        if message.kind == "done":
            self.fit()
        elif message.kind == "restarted":
            self.notify("The unit moved: recording restarted", severity="warning", timeout=3)

    def on_source_failed(self, message: SourceFailed) -> None:
        self.query_one("#message", Static).update(f"[b red]device: {message.error}[/]")

    def action_restart(self) -> None:
        if self.guide is not None:
            with self._lock:
                self.guide.restart()

    def action_abort(self) -> None:
        self._abort(f"{self.NAME} aborted: nothing saved")

    @work(thread=True, exclusive=True, group="fit", exit_on_error=False, description="fit P4")
    def fit(self) -> None:
        self._fit("gyro-drift")

    def _capture_meta(self) -> dict:
        extra = {"operator_tool": "station tui"}
        nominal = getattr(self.app.session.source, "nominal", None)
        if nominal is not None and self.guide.units.get("accel_unit") in ("V", "mV"):
            # the analogue triad's zero-g output, so P4 can take pitch and roll from it
            extra["accel_offset"] = ", ".join([repr(float(nominal[0]))] * 3)
        return extra

    def on_calibration_ready(self, message: CalibrationReady) -> None:
        self._show_results(message, message.previous)
