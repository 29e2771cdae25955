"""LDV (P5): the vehicle drives while the station records the three beams and the INS/DGPS
velocity, and shows the procedure's own check as the set builds: the conditioning of the
body velocity set, κ = cond(HᵀH) (refused above 1e4, warned above 1e3), how many moving
epochs are in, and the per-beam estimate (δK, α, β, γ) once κ allows one. The recording
ends by itself when the set is enough (``f`` ends it earlier), then the P5 fit runs and
Results show it. On the simulated vehicle ``d`` drives or stops, ``t`` turns and climbs
or drives straight.

Same pattern as the other guided screens: a thread worker drains the source and feeds the
guide (``station.procedures.ldv_guide``), posting replaceable LiveUpdates and GuideEvents.
"""

from __future__ import annotations

import math

import numpy as np
from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Vertical
from textual.screen import Screen
from textual.widgets import Static
from textual.worker import get_current_worker

from solvers.ldv import KAPPA_REFUSE, KAPPA_WARN
from station.formatting import num
from station.messages import CalibrationReady, GuideEvent, LiveUpdate, SourceFailed
from station.screens._common import GuidedScreenMixin, source_rate_hz
from station.widgets.live import bar
from station.widgets.title import TitleBar, footer


def kappa_bar(kappa: float, width: int = 16) -> float:
    """Fill of the conditioning bar: log10 κ from 6 (empty) down to 2 (full)."""
    if not math.isfinite(kappa) or kappa <= 0:
        return 0.0
    return max(0.0, min(1.0, (6.0 - math.log10(kappa)) / 4.0))


class LdvScreen(GuidedScreenMixin, Screen):
    CSS = """
    LdvScreen #body { padding: 0 1; }
    LdvScreen #instruction { height: 2; }
    LdvScreen #condition { height: 2; margin-top: 1; }
    LdvScreen #readouts { height: 3; margin-top: 1; }
    LdvScreen #estimate { height: 4; margin-top: 1; }
    LdvScreen #message { height: 2; text-style: bold; }
    """
    BINDINGS = [
        Binding("f", "finish", "Finish now"),
        Binding("r", "restart", "Restart"),
        Binding("a", "ask_abort", "Abort"),
        Binding("d", "sim_drive", "Drive/stop (sim)"),
        Binding("t", "sim_turns", "Turns (sim)"),
    ]

    def compose(self) -> ComposeResult:
        yield TitleBar("P5 laser velocimeter on a vehicle")
        with Vertical(id="body"):
            yield Static(
                "Drive with the INS/DGPS running: turns, slopes and braking. Straight driving\n"
                "leaves the beam angles unidentifiable (the conditioning below says when).",
                id="instruction",
            )
            yield Static("", id="condition")
            yield Static("", id="readouts")
            yield Static("", id="estimate")
            yield Static("", id="message")
        yield footer()

    def on_mount(self) -> None:
        self.stream()

    @work(thread=True, exclusive=True, group="stream", exit_on_error=False, description="read the device")
    def stream(self) -> None:
        from station.procedures.ldv_guide import Driver, LdvConfig, LdvGuide

        s = self.app.session
        worker = get_current_worker()
        src = s.source

        def make_guide():
            cfg = LdvConfig(min_s=float(s.extra.get("ldv_min_s", 120.0)))
            return LdvGuide(
                sample_rate_hz=source_rate_hz(src),
                device_id=s.device_id or src.device_id,
                site=getattr(src, "site", None),
                config=cfg,
            )

        if not self._start_guide(src, make_guide):
            return
        guide = self.guide
        operator = Driver(src.place) if s.scripted else None

        def update(b):
            e = b.extra or {}
            nan = np.full((len(b), 3), np.nan)

            def trio(names):
                return np.column_stack([e[k] for k in names]) if names[0] in e else nan

            return guide.update(b.t_s, trio(("vl1", "vl2", "vl3")), trio(("vx", "vy", "vz")), b.gyro, b.temp_c)

        self._pump(worker, src, update, guide.status, operator)

    def on_live_update(self, message: LiveUpdate) -> None:
        st = message.status
        self.last_status = st
        self.updates += 1
        t = Text("Conditioning ")
        style = {"good": "green", "poor": "yellow"}.get(st.verdict, "red")
        t.append(bar(kappa_bar(st.kappa), 16), style=style)
        word = {"none": "no data yet", "refused": "ILL-CONDITIONED (refused)", "poor": "poor (warned)", "good": "good"}[
            st.verdict
        ]
        t.append(f" κ {num(st.kappa, '.3g')}  {word}\n", style=style)
        t.append(
            f"needs κ ≤ {KAPPA_WARN:.0e} (refused above {KAPPA_REFUSE:.0e}); {st.n_epochs} moving epochs, "
            f"recorded {st.recorded_s:.0f} s" + ("  ENOUGH" if st.enough else "")
        )
        self.query_one("#condition", Static).update(t)
        v, b, stats = st.v_ref, st.beams, message.stats
        src = self.app.session.source
        bench = getattr(src, "bench", lambda _: None)
        car = ""
        if bench("driving") is not None:
            car = (
                "   vehicle "
                + ("driving" if bench("driving") else "parked")
                + (", turns and hills" if bench("turning") else ", straight" if bench("driving") else "")
            )
        self.query_one("#readouts", Static).update(
            f"reference {num(v[0], '7.2f')} {num(v[1], '7.2f')} {num(v[2], '7.2f')} m/s (body)  "
            f"|v| {num(st.speed_mps, '.2f')}\n"
            f"beams     {num(b[0], '7.2f')} {num(b[1], '7.2f')} {num(b[2], '7.2f')} m/s{car}\n"
            f"{num(stats.rate_hz, '.0f')} Hz   errors {stats.parse_errors}   dropped {stats.dropped}"
            + ("" if stats.connected else "   DISCONNECTED")
        )
        if st.estimate is None:
            est = "estimate: when κ allows one"
        else:
            est = "estimate  " + "\n          ".join(
                f"beam{j + 1} δK {e[0]:+.4f}  α {e[1]:6.2f}°  β {e[2]:6.2f}°  γ {e[3]:6.2f}°"
                for j, e in enumerate(st.estimate)
            )
        self.query_one("#estimate", Static).update(est)
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
        self._abort("P5 aborted: nothing saved")

    def action_sim_drive(self) -> None:
        on = getattr(self.app.session.source, "bench", lambda _: None)("driving")
        self._sim_place("stop" if on else "drive", "Simulated vehicle: braking" if on else "Simulated vehicle: driving")

    def action_sim_turns(self) -> None:
        on = getattr(self.app.session.source, "bench", lambda _: None)("turning")
        self._sim_place(
            "straight" if on else "turns",
            "Simulated vehicle: straight road" if on else "Simulated vehicle: turns and hills",
        )

    @work(thread=True, exclusive=True, group="fit", exit_on_error=False, description="fit P5")
    def fit(self) -> None:
        self._fit("ldv")

    def on_calibration_ready(self, message: CalibrationReady) -> None:
        self._show_results(message, message.previous)
