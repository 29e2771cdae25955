"""The operator TUI: a thin Textual App and the ``make_app`` factory that the commands,
tests, snapshots and benchmarks use.

Screens (one file each in ``station/screens/``): Connect → Procedure → Results, History,
Help. Device I/O and database reads run in thread workers that post the typed messages
of ``station/messages.py``; the procedure logic is ``station.procedures.tabletop_guide``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

from textual import events, work
from textual.app import App
from textual.binding import Binding
from textual.notifications import Notify

from station.messages import StoreLoaded
from station.procedures import registry
from station.textsafe import tui_markup


@dataclass
class Session:
    """What the screens share: where the database is, the source, the device, the run."""

    db_path: str | None = None
    source: object | None = None  # a station.sources source, started on connect
    device_id: str = ""
    model: str = ""
    procedure: str = registry.DEFAULT
    average_s: float = registry.DEFAULT_AVERAGE_S
    # no averaging time was given: the Connect screen offers the procedure's default for the
    # source chosen (registry.default_average_s: shorter on the simulated device)
    average_default: bool = False
    settle_s: float = 2.0
    scripted: bool = False  # the demo's scripted operator follows the prompts
    autosave: bool = False  # save the result without asking (the demo)
    state_dir: str | None = None  # where resume files live (default: next to the database)
    resume: bool = False
    guide: object | None = None
    refresh_hz: float = 15.0
    exit_when_saved: bool = False
    extra: dict = field(default_factory=dict)

    def resume_dir(self) -> str | None:
        """Where resume files live: --state-dir, else next to the database, else nowhere."""
        if self.state_dir:
            return self.state_dir
        if self.db_path:
            return os.path.dirname(os.path.abspath(self.db_path)) or "."
        return None

    def open_store(self):
        """The database (one Store per session: it is thread-safe), or None when there is
        none yet (never created just by looking)."""
        if not self.db_path or not os.path.exists(self.db_path):
            return None
        store = self.extra.get("_store")
        if store is None:
            from db.store import Store

            store = self.extra["_store"] = Store(self.db_path)
        return store


class StationApp(App):
    """Thin: holds the session, shows the first screen, reminds of due devices."""

    TITLE = "Calibration station"
    SUB_TITLE = "operator console"
    BINDINGS = [
        Binding("f1", "help", "Help"),
        # the key a newcomer guesses first (less, man, vim, htop); a field being typed in keeps it
        Binding("question_mark", "help", "Help", show=False),
        Binding("f2", "history", "History", show=False),
        Binding("ctrl+q", "quit", "Quit", priority=True),
    ]

    def __init__(self, session: Session, *, start: str = "connect") -> None:
        super().__init__()
        self.session = session
        self.start = start
        self.due: list = []  # the due/overdue list read at start-up
        self.notices: list = []  # every notification (textual.notifications.Notification), in order
        self._keys_held: list[events.Key] = []  # typed ahead while an earlier key is still handled
        self._key_in_flight: events.Key | None = None

    # ------------------------------------------------------------------ one key at a time
    # Textual sends each key the terminal gives to the widget focused when it is read, and runs a
    # binding that is not a priority one (F7 Import, l Limits, s Save, ...) only when the key has
    # bubbled back up to the App. Keys that come in one burst (a paste without bracketed paste,
    # `tmux send-keys F7 'path' Enter`, a fast typist) were all sent to the old screen's focus
    # before F7 opened Import; they bubbled up after it, unbound there, and were dropped, or met a
    # binding of the screen then on top. So a key goes to the widgets only when the one before it
    # has been through every widget it was sent to, the App included, and a screen it opened has
    # mounted and focused its field: keys typed ahead land where they would have, typed slowly.

    async def on_event(self, event: events.Event) -> None:
        if isinstance(event, events.Key) and not event.is_forwarded:
            if self._key_in_flight is not None:
                self._keys_held.append(event)
                return
            await self._route_key(event)
            return
        await super().on_event(event)

    async def _route_key(self, event: events.Key) -> None:
        self._key_in_flight = event
        target = self.focused or self.screen  # where App.on_event sends it
        path = list(target.ancestors_with_self)  # the widgets it bubbles through, the App last
        # a safety net, run by the App as the path is: a widget removed before its turn never runs it
        self.set_timer(1.0, lambda: self.call_later(self._key_done, event))
        try:
            await super().on_event(event)
        finally:
            self._follow(path, 0, event)

    def _follow(self, path: list, k: int, event: events.Key) -> None:
        """Once ``path[k]`` has handled what it was sent before now (the key, or its bubble from
        ``path[k - 1]``), the same for ``path[k + 1]``; after the App, the screen now on top."""
        while k < len(path):
            if path[k].call_later(self._follow, path, k + 1, event):
                return
            k += 1  # closed (a widget removed): nothing more comes through it
        screen = self.screen
        if screen.is_mounted:  # its on_mount has asked the App for its focus: after that
            self.call_later(self._key_done, event)
        elif not screen.call_later(self.call_later, self._key_done, event):
            self.call_later(self._key_done, event)

    async def _key_done(self, event: events.Key) -> None:
        if self._key_in_flight is not event:
            return  # done already (the safety net, or the path, came second)
        self._key_in_flight = None
        if self._keys_held:
            await self._route_key(self._keys_held.pop(0))

    def on_mount(self) -> None:
        from station.screens.connect import ConnectScreen

        self.push_screen(ConnectScreen())
        if self.start == "procedure":
            self.push_screen(registry.screen_for(self.session.procedure))
        elif self.start == "history":
            from station.screens.history import HistoryScreen

            self.push_screen(HistoryScreen())
        self.call_after_refresh(self.load_due)  # after the first paint: start-up stays fast

    def on_notify(self, message: Notify) -> None:
        """Keep the notice for the screens that show notices in their own place (lines under
        Connect's buttons, Results' tables, ...: ``station.widgets.notices``); Textual shows the
        toast on the others."""
        self.notices = [n for n in self.notices if not n.has_expired] + [message.notification]
        self._show_notices()

    def clear_notifications(self) -> None:
        """Every notice goes, the lines that screens show them in too."""
        super().clear_notifications()
        self.notices = []
        self._show_notices()

    def _show_notices(self) -> None:
        for screen in self.screen_stack:
            if hasattr(screen, "show_notices"):
                screen.show_notices()

    @work(thread=True, exclusive=True, group="due", exit_on_error=False, description="read due devices")
    def load_due(self) -> None:
        try:
            store = self.session.open_store()
            due = store.due(within_days=7) if store is not None else []
            self.post_message(StoreLoaded("due", due))
        except Exception as exc:  # noqa: BLE001 - a broken database must not stop the console
            self.post_message(StoreLoaded("due", [], error=str(exc)))

    def on_store_loaded(self, message: StoreLoaded) -> None:
        if message.what != "due":
            return
        if message.error:
            self.notify(f"database: {tui_markup(message.error)}", severity="error", timeout=8)
            return
        overdue = [d for d in message.data if d["status"] == "overdue"]
        soon = [d for d in message.data if d["status"] == "due"]
        # as `station due`, which exits 1 for them: a device registered but never calibrated
        never = [d for d in message.data if d["status"] == "never calibrated"]
        if overdue or soon or never:
            parts = []
            if overdue:
                parts.append("overdue: " + ", ".join(tui_markup(d["device_id"]) for d in overdue[:4]))
            if soon:
                parts.append("due within 7 days: " + ", ".join(tui_markup(d["device_id"]) for d in soon[:4]))
            if never:
                parts.append("never calibrated: " + ", ".join(tui_markup(d["device_id"]) for d in never[:4]))
            self.notify("; ".join(parts) + "  (F2 history)", title="Recalibration", severity="warning", timeout=10)
        self.due = message.data
        for screen in self.screen_stack:
            if hasattr(screen, "show_due"):
                screen.show_due(message.data)

    def unsaved_work(self, kept: int | None = None) -> str | None:
        """What quitting now would lose, or None (``kept``: ``kept_for_resume()``, if known)."""
        kept = self.kept_for_resume() if kept is None else kept
        for screen in self.screen_stack:
            guide = getattr(screen, "guide", None)
            if guide is not None and getattr(guide, "phase", "") not in ("done", "fitted", "aborted"):
                if kept:
                    return "the position being averaged"
                return "the run in progress"
            if (
                type(screen).__name__ == "ResultsScreen"
                and getattr(screen, "result", None) is not None
                and getattr(screen, "calibration_id", None) is None
                and not getattr(screen, "discarded", False)
            ):
                return "the unsaved result"
        return None

    def kept_for_resume(self) -> int:
        """How many captured positions the running guide has saved for Resume (P1 writes its
        resume file at each capture), 0 when none or the guide keeps none."""
        for screen in self.screen_stack:
            guide = getattr(screen, "guide", None)
            path = getattr(guide, "state_path", None)
            if guide is not None and path and os.path.exists(path):
                return int(getattr(guide, "n_captured", 0) or 0)
        return 0

    async def action_quit(self) -> None:
        """ctrl+q: quit, after a confirmation when a run or an unsaved result would be lost."""
        from station.screens.decide import ConfirmScreen

        kept = self.kept_for_resume()
        lost = self.unsaved_work(kept)
        if lost is None or self.session.scripted:
            self.exit()
            return
        if isinstance(self.screen, ConfirmScreen):
            return

        def question(lost: str = lost, kept: int = kept) -> str:
            # the run goes on behind the question: said again as positions are captured
            text = f"Quit? {lost[0].upper() + lost[1:]} is lost."
            if kept:
                text += (
                    f" The {kept} captured position{'s are' if kept > 1 else ' is'} kept: F6 on the Connect screen"
                    " resumes."
                )
            return text

        def now() -> str:
            kept = self.kept_for_resume()
            lost = self.unsaved_work(kept)
            return question(lost, kept) if lost else question()

        self.push_screen(ConfirmScreen(question(), update=now), lambda yes: self.exit() if yes else None)

    def action_history(self) -> None:
        from station.screens.history import HistoryScreen

        if not isinstance(self.screen, HistoryScreen):
            self.push_screen(HistoryScreen())

    def action_help(self) -> None:
        from station.screens.help import HelpScreen

        if not isinstance(self.screen, HelpScreen):
            self.push_screen(HelpScreen())


def make_app(
    db_path: str | None = None,
    device=None,
    *,
    demo: bool = False,
    average_s: float | None = None,
    settle_s: float | None = None,
    device_id: str | None = None,
    model: str = "",
    state_dir: str | None = None,
    start: str | None = None,
    resume: bool = False,
    exit_when_saved: bool = False,
) -> StationApp:
    """The station app.

    db_path: the station database (None: nothing is saved or looked up).
    device: a started-or-not source (``station.sources.SimSource`` / ``SerialSource``);
        with it the Connect screen is pre-filled (and skipped for the demo).
    demo: the scripted operator follows the prompts and the result is saved unasked.
    average_s: averaging time per position (default 180 s, the source's 3–5 minutes, which
        the Connect screen shortens on the simulated device; the demo uses 3 s).
    """
    session = Session(
        db_path=db_path,
        source=device,
        scripted=demo,
        autosave=demo,
        state_dir=state_dir,
        resume=resume,
        exit_when_saved=exit_when_saved,
        model=model,
    )
    session.average_s = float(average_s if average_s is not None else (3.0 if demo else registry.DEFAULT_AVERAGE_S))
    session.average_default = average_s is None and not demo
    session.settle_s = float(settle_s if settle_s is not None else (1.0 if demo else 2.0))
    if device is not None:
        session.device_id = device_id or getattr(device, "device_id", "") or ""
        session.procedure = getattr(device, "procedure", None) or session.procedure
    elif device_id:
        session.device_id = device_id
    if start is None:
        start = "procedure" if (demo and device is not None) else "connect"
    return StationApp(session, start=start)
