"""Compass (P3): the guided sweep. The operator turns the unit through every orientation;
the screen shows a live sphere-coverage map (the compass calibration's own measure,
solvers.compass.coverage: the sphere within 30° of a visited field direction), the
recorded time, the field readouts and the turn rate. The recording ends by itself at the target coverage (f finishes early), then the fit runs.

Same pattern as the P1 screen: a thread worker drains the source and feeds the guide,
posting replaceable LiveUpdates (~15 Hz) and GuideEvents.
"""
from __future__ import annotations

import math
import threading
import time

from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.screen import Screen
from textual.widgets import Footer, Static
from textual.worker import get_current_worker

from station.messages import CalibrationReady, GuideEvent, LiveUpdate, SourceFailed
from station.widgets.live import bar
from station.widgets.title import TitleBar


def sweep_positions(positions: list[str]) -> list[str]:
    """The demo operator's tour: the simulator's sphere positions, then the P1 faces."""
    from solvers.positions import P1_POSITIONS

    return list(positions) + [p for p in P1_POSITIONS if p not in positions]


def _n(x, fmt):
    return format(x, fmt) if isinstance(x, (int, float)) and math.isfinite(x) else "—"


class CompassScreen(Screen):
    CSS = """
    CompassScreen #map { width: 30; height: 10; border: round $primary; padding: 0 1; }
    CompassScreen #right { width: 1fr; padding: 0 1; }
    CompassScreen #instruction { height: 3; }
    CompassScreen #progress { height: 2; }
    CompassScreen #readouts { height: 4; margin-top: 1; }
    CompassScreen #message { height: 1; text-style: bold; }
    """
    BINDINGS = [
        Binding("f", "finish", "Finish now"),
        Binding("r", "restart", "Restart"),
        Binding("a", "abort", "Abort"),
    ]

    def __init__(self) -> None:
        super().__init__()
        self._lock = threading.Lock()
        self.guide = None
        self.last_status = None
        self.updates = 0
        self._fitting = False

    def compose(self) -> ComposeResult:
        yield TitleBar("P3 compass sweep")
        with Horizontal():
            yield Static("", id="map")
            with Vertical(id="right"):
                yield Static("Turn the unit slowly through every orientation:\n"
                             "each face up in turn, a full turn about the\nvertical at each. Keep metal away.",
                             id="instruction")
                yield Static("", id="progress")
                yield Static("", id="readouts")
                yield Static("", id="message")
        yield Footer()

    def on_mount(self) -> None:
        self.query_one("#map").border_title = "Sphere coverage"
        self.stream()

    @work(thread=True, exclusive=True, group="stream", exit_on_error=False, description="read the device")
    def stream(self) -> None:
        from station.procedures.guide_compass import CompassGuide, CompassConfig, SweepOperator

        s = self.app.session
        worker = get_current_worker()
        src = s.source
        try:
            if src.kind == "sim" and getattr(src, "_t0", None) is None:
                src.start()
            elif src.kind == "serial" and not src.reader.running:
                src.start()
            rate = float(getattr(src, "rate_hz", math.nan))
            cfg = CompassConfig(min_s=s.extra.get("compass_min_s", 60.0))
            with self._lock:
                self.guide = CompassGuide(sample_rate_hz=rate if math.isfinite(rate) and rate > 0 else 100.0,
                                          units=src.units, device_id=s.device_id or src.device_id,
                                          site=getattr(src, "site", None), config=cfg)
                s.guide = self.guide
        except Exception as exc:  # noqa: BLE001 - one line on screen
            self.post_message(SourceFailed(str(exc)))
            return
        operator = None
        if s.scripted and getattr(src, "positions", None):
            operator = SweepOperator(src.place, sweep_positions(src.positions), hold_s=1.0)
        period = 1.0 / s.refresh_hz
        next_post = 0.0
        while not worker.is_cancelled:
            b = src.drain()
            if b is not None and len(b) and b.mag is not None:
                with self._lock:
                    st = self.guide.update(b.t_s, b.accel, b.gyro, b.mag, b.temp_c)
                    events = self.guide.take_events()
                    if operator is not None:
                        operator.step(self.guide, st.t_s)
                for kind, detail in events:
                    self.post_message(GuideEvent(kind, detail))
            now = time.monotonic()
            if now >= next_post:
                with self._lock:
                    st = self.guide.status()
                    st_map = self.guide.coverage_map()
                self.post_message(LiveUpdate((st, st_map), src.stats()))
                next_post = max(next_post + period, now - period)  # 15 Hz on average
            time.sleep(0.02)  # 50 batches a second: ~20 samples each at 1 kHz

    def on_live_update(self, message: LiveUpdate) -> None:
        st, cov_map = message.status
        self.last_status = st
        self.updates += 1
        units = self.app.session.source.units
        self.query_one("#map", Static).update("+z\n" + "\n".join(cov_map) + "\n-z")
        t = Text("Coverage ")
        t.append(bar(st.coverage / st.target if st.target else 0, 16), style="green" if st.coverage >= st.target else "cyan")
        t.append(f" {100 * st.coverage:3.0f} % of {100 * st.target:.0f} %"
                 + ("" if st.enough else " (fit needs 40 %)") + f"\nRecorded {st.recorded_s:5.0f} s, "
                 f"{st.n_samples} samples")
        self.query_one("#progress", Static).update(t)
        m = st.field_raw
        stats = message.stats
        self.query_one("#readouts", Static).update(
            f"mag  {_n(m[0], '8.2f')} {_n(m[1], '8.2f')} {_n(m[2], '8.2f')} {units.get('mag_unit') or 'raw'}"
            f"  |m| {_n(st.field_norm_raw, '.2f')}\n"
            f"turn {_n(st.turn_rate, '.3f')} {units.get('gyro_unit') or 'raw'}\n"
            f"{_n(stats.rate_hz, '.0f')} Hz   errors {stats.parse_errors}   dropped {stats.dropped}"
            + ("" if stats.connected else "   DISCONNECTED"))
        self.query_one("#message", Static).update(st.message)

    def on_guide_event(self, message: GuideEvent) -> None:
        if message.kind == "done":
            self.fit()
        elif message.kind == "restarted":
            self.notify("Recording restarted", timeout=2)

    def on_source_failed(self, message: SourceFailed) -> None:
        self.query_one("#message", Static).update(f"[b red]device: {message.error}[/]")

    def action_finish(self) -> None:
        if self.guide is not None:
            with self._lock:
                self.guide.finish()
                events = self.guide.take_events()
            for kind, detail in events:
                self.post_message(GuideEvent(kind, detail))

    def action_restart(self) -> None:
        if self.guide is not None:
            with self._lock:
                self.guide.restart()
                self.guide.take_events()
            self.notify("Recording restarted", timeout=2)

    def action_abort(self) -> None:
        if self.guide is not None:
            with self._lock:
                self.guide.abort()
        self.workers.cancel_group(self, "stream")
        self.app.session.guide = None
        self.app.notify("P3 aborted: nothing saved", timeout=4)
        self.app.pop_screen()

    @work(thread=True, exclusive=True, group="fit", exit_on_error=False, description="fit P3")
    def fit(self) -> None:
        if self._fitting:
            return
        self._fitting = True
        with self._lock:
            capture = self.guide.capture(extra_meta={"operator_tool": "station tui"})
        previous = None
        try:
            store = self.app.session.open_store()
            if store is not None:
                hist = [c for c in store.history(self.app.session.device_id, "compass") if c["accepted"]]
                previous = hist[-1] if hist else None
        except Exception:  # noqa: BLE001 - no comparison then
            previous = None
        try:
            from station.calibrate import calibrate_capture

            self.post_message(CalibrationReady(capture, calibrate_capture(capture), previous=previous))
        except Exception as exc:  # noqa: BLE001 - one line on the results screen
            self.post_message(CalibrationReady(capture, None, error=str(exc), previous=previous))

    def on_calibration_ready(self, message: CalibrationReady) -> None:
        from station.screens.results import ResultsScreen

        self.workers.cancel_group(self, "stream")
        self.app.switch_screen(ResultsScreen(message.capture, message.result, message.error, message.previous))
