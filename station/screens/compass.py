"""Compass (P3): the guided sweep. The operator turns the unit through every orientation;
the screen shows a live sphere-coverage map (the compass calibration's own measure,
solvers.compass.coverage: the sphere within 30° of a visited field direction), the
recorded time, the field readouts and the turn rate. The recording ends by itself at the target coverage (f finishes early), then the fit runs.

Same pattern as the P1 screen: a thread worker drains the source and feeds the guide,
posting replaceable LiveUpdates (~15 Hz) and GuideEvents.
"""

from __future__ import annotations

from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import Screen
from textual.widgets import Static
from textual.worker import get_current_worker

from station.formatting import num
from station.messages import CalibrationReady, GuideEvent, LiveUpdate, SourceFailed
from station.screens._common import GuidedScreenMixin, source_rate_hz
from station.textsafe import tui_markup
from station.widgets.live import bar
from station.widgets.title import TitleBar, footer


class CompassScreen(GuidedScreenMixin, Screen):
    CSS = """
    CompassScreen #map { width: 30; height: 10; border: round $primary; padding: 0 1; }
    CompassScreen #right { width: 1fr; padding: 0 1; }
    CompassScreen #instruction { height: 3; }
    CompassScreen #progress { height: 2; }
    CompassScreen #readouts { height: 6; margin-top: 1; }
    /* the rows it needs beside the map (48 columns): one cut "(all faces up, all headings)" off */
    CompassScreen #message { height: auto; text-style: bold; }
    """
    BINDINGS = [
        Binding("f", "finish", "Finish now"),
        Binding("r", "restart", "Restart"),
        Binding("a", "ask_abort", "Abort"),
        Binding("p", "sim_sweep", "Sweep (sim)"),
        Binding("l", "sim_level", "Level (sim)"),
    ]

    def compose(self) -> ComposeResult:
        yield TitleBar("P3 compass sweep")
        with Horizontal():
            yield Static("", id="map")
            with Vertical(id="right"):
                yield Static(
                    "Turn the unit slowly through every orientation:\n"
                    "each face up in turn, a full turn about the\nvertical at each. Keep metal away.",
                    id="instruction",
                )
                yield Static("", id="progress")
                yield Static("", id="readouts")
                yield Static("", id="message")
        yield footer()

    def on_mount(self) -> None:
        self.query_one("#map").border_title = "Sphere coverage"
        site = getattr(self.app.session.source, "site", None) or {}
        if "latitude_deg" not in site:
            self.notify(
                "No site: the field will not be IGRF-anchored. Start with --site LAT,LON[,ALT_M] to set it.",
                severity="warning",
                timeout=8,
            )
        self.stream()

    @work(thread=True, exclusive=True, group="stream", exit_on_error=False, description="read the device")
    def stream(self) -> None:
        from station.procedures.compass_guide import CompassConfig, CompassGuide, SweepOperator, sweep_positions

        s = self.app.session
        worker = get_current_worker()
        src = s.source

        def make_guide():
            from station.procedures.accel_frontend import for_device

            cfg = CompassConfig(min_s=s.extra.get("compass_min_s", 60.0))
            device_id = s.device_id or src.device_id
            # the unit's own P1 (zero and scale) and compass calibrations, when it has them
            p1, mag = [], None
            store = s.open_store()
            if store is not None:
                p1 = store.history(device_id)  # for_device takes the A = B + M V ones
                mag = next((c for c in reversed(store.history(device_id, "compass")) if c["accepted"]), None)
            return CompassGuide(
                sample_rate_hz=source_rate_hz(src),
                units=src.units,
                device_id=device_id,
                site=getattr(src, "site", None),
                config=cfg,
                accel_frontend=for_device(p1, src.units.get("accel_unit"), getattr(src, "nominal", None)),
                mag_calibration=mag,
            )

        if not self._start_guide(src, make_guide):
            return
        operator = None
        if s.scripted and getattr(src, "positions", None):
            operator = SweepOperator(src.place, sweep_positions(src.positions), hold_s=1.0)
        guide = self.guide
        self._pump(
            worker,
            src,
            lambda b: guide.update(b.t_s, b.accel, b.gyro, b.mag, b.temp_c),
            lambda: (guide.status(), guide.coverage_map()),
            operator,
            accept=lambda b: b.mag is not None,
        )

    def on_live_update(self, message: LiveUpdate) -> None:
        st, cov_map = message.status
        self.last_status = st
        self.updates += 1
        units = self.app.session.source.units
        self.query_one("#map", Static).update("+z\n" + "\n".join(cov_map) + "\n-z")
        t = Text("Coverage ")
        # 48 columns beside the map at 80: a longer line wrapped and pushed 'Recorded' out of sight
        t.append(
            bar(st.coverage / st.target if st.target else 0, 12), style="green" if st.coverage >= st.target else "cyan"
        )
        t.append(
            f" {100 * st.coverage:3.0f} % of {100 * st.target:.0f} %"
            + ("" if st.enough else " (fit ≥ 40 %)")
            + f"\nRecorded {st.recorded_s:5.0f} s, "
            f"{st.n_samples} samples"
        )
        self.query_one("#progress", Static).update(t)
        m = st.field_raw
        stats = message.stats
        if st.tilt_from:
            attitude = (
                f"pitch {num(st.pitch_deg, '+6.1f')}°  roll {num(st.roll_deg, '+6.1f')}°  "
                f"heading {num(st.heading_deg, '5.1f')}° mag\n"
                f"tilt: {tui_markup(st.tilt_from)}\nheading: {tui_markup(st.heading_from)}\n"
            )
        else:
            unit = units.get("accel_unit") or "no unit"
            attitude = (
                f"no tilt, no heading: accelerometer in {tui_markup(unit)}\nwith no P1 calibration or zero/scale\n\n"
            )
        self.query_one("#readouts", Static).update(
            f"mag  {num(m[0], '8.2f')} {num(m[1], '8.2f')} {num(m[2], '8.2f')} {units.get('mag_unit') or 'raw'}"
            f"  |m| {num(st.field_norm_raw, '.2f')}\n"
            f"turn {num(st.turn_rate, '.3f')} {units.get('gyro_unit') or 'raw'}\n"
            + attitude
            + f"{num(stats.rate_hz, '.0f')} Hz   errors {stats.parse_errors}   dropped {stats.dropped}"
            + ("" if stats.connected else "   DISCONNECTED")
        )
        self.query_one("#message", Static).update(st.message)

    def on_guide_event(self, message: GuideEvent) -> None:
        if message.kind == "done":
            self.fit()
        elif message.kind == "restarted":
            self.notify("Recording restarted", timeout=2)

    def on_source_failed(self, message: SourceFailed) -> None:
        self.query_one("#message", Static).update(f"[b red]device: {message.error}[/]")

    def action_finish(self) -> None:
        self._finish_guide()

    def action_restart(self) -> None:
        self._restart_guide()

    def action_abort(self) -> None:
        self._abort("P3 aborted: nothing saved")

    def action_sim_level(self) -> None:
        """The simulated unit: set it down level (z down: pitch and roll 0°) at some heading."""
        self._sim_place("z_down", "Simulated unit: set down level")

    def action_sim_sweep(self) -> None:
        """The simulated unit: start turning it through every orientation, or stop."""
        src = self.app.session.source
        sweeping = getattr(src, "bench", lambda _: None)("driving") == "sweep"
        self._sim_place(
            "still" if sweeping else "sweep",
            "Simulated unit: sweep stopped" if sweeping else "Simulated unit: turning through every orientation",
        )

    @work(thread=True, exclusive=True, group="fit", exit_on_error=False, description="fit P3")
    def fit(self) -> None:
        self._fit("compass")

    def on_calibration_ready(self, message: CalibrationReady) -> None:
        self._show_results(message, message.previous)
