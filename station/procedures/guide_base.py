"""What the guides (``station/procedures/<stem>_guide.py``) do alike: the queue of events
the screen takes, abort, and the end of a recording."""

from __future__ import annotations


class GuideBase:
    """A guide's event queue and ends. The guide sets ``self._events`` (a list), ``self.phase``
    and ``self._message`` in its ``__init__``; events are ``(kind, detail)`` pairs."""

    _events: list[tuple[str, str]]
    phase: str
    _message: str

    def take_events(self) -> list[tuple[str, str]]:
        """The events since the last call (the screen posts them), oldest first."""
        ev, self._events = self._events, []
        return ev

    def abort(self) -> None:
        """The operator aborts: nothing of the run is kept."""
        self.phase = "aborted"
        self._message = "Aborted"
        self._events.append(("aborted", ""))

    def _finish(self, why: str) -> None:
        self.phase = "done"
        self._message = f"Done: {why}"
        self._events.append(("done", why))
