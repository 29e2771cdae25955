"""Gyro drift (P4). Static base (mode B, ``HoldScreen``): place the unit level at a known
heading and keep it still while the station records (P4 asks for at least 3 minutes). The
stability bar and countdown are the P1 widgets; moving restarts the recording. Reference
IMU (mode A, ``ReferenceScreen``): both units on a rate table, recorded side by side.

Same pattern as the P1 screen: a thread worker drains the source and feeds the guide."""

from __future__ import annotations

import math

import numpy as np
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import Screen
from textual.widgets import Static
from textual.worker import get_current_worker

from solvers.units import si_factor
from station.formatting import num
from station.messages import CalibrationReady, GuideEvent, LiveUpdate, SourceFailed
from station.screens._common import GuidedScreenMixin, is_simulated, source_rate_hz
from station.widgets.live import CountdownBar, StabilityBar
from station.widgets.title import TitleBar, footer

SIM_FRAME = "x forward, y left, z up"  # the simulated unit lies level with z up


def _deg_h(unit: str) -> float:
    """Factor from the gyro ``unit`` to °/h (the unit P4's screens show rates in); NaN for a
    unit without a physical factor."""
    return 3600.0 / math.radians(1.0) * (si_factor("gyro", unit) or math.nan)


class HoldScreen(GuidedScreenMixin, Screen):
    CSS = """
    HoldScreen #body { padding: 0 1; }
    HoldScreen #instruction { height: 4; }
    HoldScreen #indicators { height: 2; margin-top: 1; }
    HoldScreen #readouts { height: 4; margin-top: 1; }
    HoldScreen #message { height: 1; text-style: bold; margin-top: 1; }
    """
    BINDINGS = [Binding("r", "restart", "Restart"), Binding("a", "ask_abort", "Abort")]

    SUBJECT = "P4 gyro drift, static base"
    INSTRUCTION = (
        "Put the unit on a level, steady surface, forward (x) axis pointing north\n"
        "(heading 0°), and do not touch it: the station records the gyro at rest\n"
        "and removes the Earth's rotation. Walking on a wooden floor shows here."
    )
    NAME = "P4"

    def compose(self) -> ComposeResult:
        yield TitleBar(self.SUBJECT)
        with Vertical(id="body"):
            yield Static(self.INSTRUCTION, id="instruction")
            with Vertical(id="indicators"):
                yield StabilityBar(id="stability")
                yield CountdownBar(id="countdown", label="Record")
            yield Static("", id="readouts")
            yield Static("", id="message")
        yield footer()

    def on_mount(self) -> None:
        self.stream()

    @work(thread=True, exclusive=True, group="stream", exit_on_error=False, description="read the device")
    def stream(self) -> None:
        from station.procedures.gyrodrift_guide import HoldConfig, HoldGuide

        s = self.app.session
        worker = get_current_worker()
        src = s.source

        def make_guide():
            frame = s.extra.get("frame") or (SIM_FRAME if is_simulated(src) else "")
            cfg = HoldConfig(duration_s=s.average_s, settle_s=s.settle_s, frame=frame)
            return HoldGuide(
                sample_rate_hz=source_rate_hz(src),
                units=src.units,
                device_id=s.device_id or src.device_id,
                site=getattr(src, "site", None),
                config=cfg,
            )

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
        m, stats = st.gyro_mean_body, message.stats  # in the axes of the result's drift
        unit = self.app.session.source.units.get("gyro_unit") or "raw"
        k, fmt = _deg_h(unit), "+.1f"  # °/h, as the Results screen shows the drift
        if math.isfinite(k):
            unit = "°/h"
        else:  # a raw unit (counts without a scale): as it comes
            k, fmt = 1.0, "+.6f"
        self.query_one("#readouts", Static).update(
            f"mean so far, Earth rate included; {st.axes}\n"
            + "   ".join(f"{ax} {num(m[i] * k, fmt):>10}" for i, ax in enumerate("xyz"))
            + f" {unit}\n"
            f"{st.n_samples} samples   temp {num(st.temp_c, '.1f')} °C\n"
            f"{num(stats.rate_hz, '.0f')} Hz   errors {stats.parse_errors}   dropped {stats.dropped}"
            + ("" if stats.connected else "   DISCONNECTED")
        )
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


class ReferenceScreen(GuidedScreenMixin, Screen):
    """P4 mode A: the unit and a reference IMU rigidly mounted together on a rate table;
    the station records both for the set time and shows, live, the running drift (unit
    minus reference) ± its standard error, how much the reference moved, and the
    mounting check (does the difference grow with the rate?). On the simulated device
    ``p`` runs or stops the rate table."""

    CSS = """
    ReferenceScreen #body { padding: 0 1; }
    ReferenceScreen #instruction { height: 2; }
    ReferenceScreen #indicators { height: 1; margin-top: 1; }
    ReferenceScreen #readouts { height: 6; margin-top: 1; }
    ReferenceScreen #message { height: 2; text-style: bold; margin-top: 1; }
    """
    BINDINGS = [
        Binding("r", "restart", "Restart"),
        Binding("a", "ask_abort", "Abort"),
        Binding("p", "sim_table", "Rate table (sim)"),
    ]
    SUBJECT = "P4 gyro drift, reference IMU"

    def compose(self) -> ComposeResult:
        yield TitleBar(self.SUBJECT)
        with Vertical(id="body"):
            yield Static(
                "Mount the unit rigidly on the reference IMU, axes aligned, and run the rate\n"
                "table (any motion: both see it). The drift is the unit minus the reference.",
                id="instruction",
            )
            with Vertical(id="indicators"):
                yield CountdownBar(id="countdown", label="Record")
            yield Static("", id="readouts")
            yield Static("", id="message")
        yield footer()

    def on_mount(self) -> None:
        self.stream()

    @work(thread=True, exclusive=True, group="stream", exit_on_error=False, description="read the device")
    def stream(self) -> None:
        from station.procedures.gyrodrift_guide import ReferenceConfig, ReferenceGuide

        s = self.app.session
        worker = get_current_worker()
        src = s.source

        def make_guide():
            frame = s.extra.get("frame") or (SIM_FRAME if is_simulated(src) else "")
            cfg = ReferenceConfig(
                duration_s=s.average_s,
                frame=frame,
                reference_drift_deg_h=float(s.extra.get("reference_drift_deg_h", 1.0)),
            )
            return ReferenceGuide(
                sample_rate_hz=source_rate_hz(src),
                units=src.units,
                device_id=s.device_id or src.device_id,
                site=getattr(src, "site", None),
                config=cfg,
            )

        if not self._start_guide(src, make_guide):
            return
        guide = self.guide
        if s.scripted:
            src.place("table")

        def update(b):
            e = b.extra or {}
            ref = np.column_stack([e[k] for k in ("ref_gx", "ref_gy", "ref_gz")]) if "ref_gx" in e else None
            return guide.update(b.t_s, b.accel, b.gyro, ref, b.temp_c)

        self._pump(worker, src, update, guide.status)

    def on_live_update(self, message: LiveUpdate) -> None:
        st = message.status
        self.last_status = st
        self.updates += 1
        g = self.guide
        self.query_one(CountdownBar).show(st, g.config.duration_s if g else math.nan)
        unit = self.app.session.source.units.get("gyro_unit") or "raw"
        stats = message.stats
        k = _deg_h(unit)
        e, se = st.drift_body, st.drift_se_body  # in the axes of the result's drift
        mount = (
            "—"
            if not math.isfinite(st.coupling_max)
            else f"|M| {st.coupling_max:.2g} rad/rad, bias {st.coupling_bias * k:.2g} °/h "
            + ("[green]OK[/]" if st.mounting_ok else "[b red]CHECK THE MOUNTING[/]")
        )
        self.query_one("#readouts", Static).update(
            f"drift (unit − reference) °/h ± 1σ, {st.axes}\n"
            + "   ".join(f"{ax} {num(e[i] * k, '+9.1f')} ± {num(se[i] * k, '.1f')}" for i, ax in enumerate("xyz"))
            + "\n"
            f"reference motion {num(st.motion, '.3f')} {unit} RMS"
            + (
                "   rate table ON"
                if getattr(self.app.session.source, "bench", lambda _: None)("driving") == "table"
                else ""
            )
            + "\n"
            f"mounting check: {mount}\n"
            f"{st.n_samples} samples   {num(stats.rate_hz, '.0f')} Hz   errors {stats.parse_errors}   "
            f"dropped {stats.dropped}" + ("" if stats.connected else "   DISCONNECTED")
        )
        self.query_one("#message", Static).update(st.message)

    def on_guide_event(self, message: GuideEvent) -> None:
        if message.kind == "done":
            self.fit()

    def on_source_failed(self, message: SourceFailed) -> None:
        self.query_one("#message", Static).update(f"[b red]device: {message.error}[/]")

    def action_restart(self) -> None:
        if self.guide is not None:
            with self._lock:
                self.guide.restart()

    def action_abort(self) -> None:
        self._abort("P4 aborted: nothing saved")

    def action_sim_table(self) -> None:
        src = self.app.session.source
        on = getattr(src, "bench", lambda _: None)("driving") == "table"
        self._sim_place("still" if on else "table", "Rate table stopped" if on else "Rate table running")

    @work(thread=True, exclusive=True, group="fit", exit_on_error=False, description="fit P4")
    def fit(self) -> None:
        self._fit("gyro-drift")

    def on_calibration_ready(self, message: CalibrationReady) -> None:
        self._show_results(message, message.previous)
