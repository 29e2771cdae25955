"""What the guided procedure screens (P1–P4) share.

``GuidedScreenMixin`` holds the thread-worker bodies: starting the source, the loop that
drains it into the guide (posting GuideEvents and a replaceable LiveUpdate ~15 Hz), and the
fit (capture, the device's previous accepted calibration, calibrate_capture, a
CalibrationReady). Each screen keeps its own ``@work`` methods and message handlers and
passes what differs. No message handlers live here: Textual calls the handlers of every
class in the MRO.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from collections.abc import Callable

from station.messages import CalibrationReady, GuideEvent, LiveUpdate, SourceFailed
from station.procedures import registry


def start_source(src) -> bool:
    """Start a simulated or serial source that is not running yet; True if it was started."""
    if src.kind == "sim" and getattr(src, "_t0", None) is None:
        src.start()
        return True
    if src.kind == "serial" and not src.reader.running:
        src.start()
        return True
    return False


def source_rate_hz(src) -> float:
    """The source's sample rate, 100 Hz when it reports none."""
    rate = float(getattr(src, "rate_hz", math.nan))
    return rate if math.isfinite(rate) and rate > 0 else 100.0


def is_simulated(src) -> bool:
    """True for the built-in simulated device and `station sim-device` on a port: the bench
    whose unit the station can turn (``place``) for the operator."""
    if src is None:
        return False
    return getattr(src, "kind", "") == "sim" or str(getattr(src, "device_id", "")).startswith("SIM-")


NO_DATA_S = 5.0  # a procedure screen says a device silent this long, and again every as long


def no_data_text(src, silent_s: float, since_data: bool = False) -> str:
    """What the operator is told while a started device sends no sample (wrong port, baud rate or
    protocol, unpowered), or has stopped sending (unplugged mid-run): the screen's dashes and
    "t=— s", or a prompt and a countdown that stand still, alone say nothing is wrong."""
    where = getattr(src, "label", "") or "the device"
    since = " since its last sample" if since_data else ""
    return (
        f"no data from {where} for {silent_s:.0f} s{since}: check the cable, the port, the baud rate and the "
        "protocol (a abort, then Connect)"
    )


class GuidedScreenMixin:
    """For a guided Screen (listed before ``Screen`` in its bases): ``__init__`` gives it its
    ``_lock``, ``guide``, ``last_status``, ``updates`` and ``_fitting``.

    Actions named ``sim_*`` move the simulated bench (the operator's hand on the built-in
    device); their keys show only when the source is simulated."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._lock = threading.Lock()  # held by the stream worker and the UI around the guide
        self.guide = None  # the procedure's guide, once the source has started
        self.last_status = None  # the status of the newest LiveUpdate drawn
        self.updates = 0  # LiveUpdates drawn (the benchmark's refresh count)
        self._fitting = False  # the fit runs once per screen

    def check_action(self, action: str, parameters) -> bool | None:
        if action.startswith("sim_"):
            return is_simulated(self.app.session.source)
        return True

    def _sim_place(self, name: str, said: str) -> None:
        """Ask the simulated bench for ``name`` (a position, ``k@ω``, ``sweep`` ...)."""
        src = self.app.session.source
        if not is_simulated(src):
            return
        try:
            src.place(name)
        except Exception as exc:  # noqa: BLE001 - one line, the run goes on
            self.notify(f"simulated bench: {exc}", severity="error", timeout=5)
            return
        self.notify(said, timeout=2)

    def action_ask_abort(self) -> None:
        """`a`: abort only once the operator confirms (y / Enter; n / Esc keeps the run)."""
        from station.screens.decide import ConfirmScreen

        entry = registry.get(self.app.session.procedure)
        keep = (
            " (captured positions are kept: Resume continues)"
            if entry is not None and getattr(entry.guide(), "RESUMABLE", False)
            else " (nothing of this run is saved)"
        )
        self.app.push_screen(ConfirmScreen("Abort this run?" + keep), lambda yes: self.action_abort() if yes else None)

    def _finish_guide(self) -> None:
        """End the recording now (the guide's ``finish``) and post its events (``done`` fits)."""
        if self.guide is not None:
            with self._lock:
                self.guide.finish()
                events = self.guide.take_events()
            for kind, detail in events:
                self.post_message(GuideEvent(kind, detail))

    def _restart_guide(self) -> None:
        """Start the recording again (the guide's ``restart``), said here, not by its event."""
        if self.guide is not None:
            with self._lock:
                self.guide.restart()
                self.guide.take_events()
            self.notify("Recording restarted", timeout=2)

    def _start_guide(self, src, make_guide: Callable) -> bool:
        """Start ``src`` and set ``self.guide`` (and the session's) to ``make_guide()``;
        False, with a SourceFailed posted, when either fails."""
        try:
            start_source(src)
            with self._lock:
                self.guide = make_guide()
                self.app.session.guide = self.guide
        except Exception as exc:  # noqa: BLE001 - one line on screen
            self.post_message(SourceFailed(str(exc)))
            return False
        return True

    def _pump(
        self,
        worker,
        src,
        update: Callable,
        status: Callable,
        operator=None,
        accept: Callable | None = None,
        with_hz: bool = False,
    ) -> None:
        """Drain ``src`` into the guide until ``worker`` is cancelled.

        ``update(batch)`` feeds the guide and returns its status (under the lock);
        ``status()`` is the LiveUpdate payload (under the lock); ``accept(batch)`` skips
        batches the guide cannot use; ``with_hz`` adds the measured post rate."""
        # The counters count this procedure only. A source left running while nobody read it
        # (the Connect screen, a previous run) counts the samples it could not keep as dropped
        # when it is next read: read it once first, then take the base.
        pending = src.drain()
        base = src.stats()

        def counted():
            st = src.stats()
            return dataclasses.replace(
                st,
                samples=st.samples - base.samples,
                dropped=st.dropped - base.dropped,
                parse_errors=st.parse_errors - base.parse_errors,
            )

        period = 1.0 / self.app.session.refresh_hz
        next_post = 0.0
        posts = 0
        t_posts = time.monotonic()
        # a device on a port that sends nothing, from the start or since some time (unplugged), is
        # said every NO_DATA_S (the built-in one never is silent; a test's bench clock may hold it still)
        watched = getattr(src, "kind", "") == "serial"
        got_data, last_data, said_silent = False, t_posts, t_posts
        while not worker.is_cancelled:
            b, pending = (pending if pending is not None else src.drain()), None
            if b is not None and len(b) > 0:
                got_data, last_data = True, time.monotonic()
            silent = time.monotonic() - last_data
            if watched and silent >= NO_DATA_S and time.monotonic() - said_silent >= NO_DATA_S:
                said_silent = time.monotonic()
                self.app.call_from_thread(
                    self.notify, no_data_text(src, silent, since_data=got_data), severity="warning", timeout=NO_DATA_S
                )
            if b is not None and len(b) and (accept is None or accept(b)):
                with self._lock:
                    st = update(b)
                    events = self.guide.take_events()
                    if operator is not None:
                        operator.step(self.guide, st.t_s)
                for kind, detail in events:
                    self.post_message(GuideEvent(kind, detail))
            now = time.monotonic()
            if now >= next_post:
                with self._lock:
                    payload = status()
                if with_hz:
                    posts += 1
                    hz = posts / (now - t_posts) if now > t_posts else math.nan
                    self.post_message(LiveUpdate(payload, counted(), hz))
                else:
                    self.post_message(LiveUpdate(payload, counted()))
                next_post = max(next_post + period, now - period)  # 15 Hz on average
            time.sleep(0.02)  # 50 batches a second: ~20 samples each at 1 kHz

    def _capture_meta(self) -> dict:
        """Extra metadata of the fitted capture (called under the lock)."""
        return {"operator_tool": "station tui"}

    def _fit(self, history_procedure: str | None) -> None:
        """Capture the guide, calibrate it and post CalibrationReady (once per screen).

        With ``history_procedure`` the device's accepted calibration of that procedure in use
        at the capture's time (``station.store.previous_at``) rides along as ``previous``."""
        if self._fitting:
            return
        self._fitting = True
        with self._lock:
            capture = self.guide.capture(extra_meta=self._capture_meta())
        previous = None
        if history_procedure is not None:
            try:
                store = self.app.session.open_store()
                if store is not None:
                    from station.store import previous_at

                    started = getattr(self.guide, "started", None)
                    previous = previous_at(store, self.app.session.device_id, history_procedure, capture, started)
            except Exception:  # noqa: BLE001 - no comparison then
                previous = None
        try:
            from station.calibrate import calibrate_capture

            self.post_message(CalibrationReady(capture, calibrate_capture(capture), previous=previous))
        except Exception as exc:  # noqa: BLE001 - one line on the results screen
            self.post_message(CalibrationReady(capture, None, error=str(exc), previous=previous))

    def _show_results(self, message: CalibrationReady, previous) -> None:
        from station.screens.results import ResultsScreen

        self.workers.cancel_group(self, "stream")
        self.app.switch_screen(ResultsScreen(message.capture, message.result, message.error, previous))

    def _abort(self, text: str) -> None:
        """Abort the guide, stop the stream worker and go back (nothing saved)."""
        if self.guide is not None:
            with self._lock:
                self.guide.abort()
        self.workers.cancel_group(self, "stream")
        self.app.session.guide = None
        self.app.notify(text, timeout=4)
        self.app.pop_screen()
