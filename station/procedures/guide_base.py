"""What the guides (``station/procedures/<stem>_guide.py``) do alike: the queue of events
the screen takes, abort, the end of a recording, the time it started, the place in the
capture's metadata, and the rest detector of those that wait for the unit to be still."""

from __future__ import annotations

import datetime as _dt

from solvers.stillness import StillnessTracker


def started_utc() -> str:
    """Now, as a guide's ``started``: UTC to the second, ``YYYY-MM-DDTHH:MM:SSZ``."""
    return _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


SITE_KEYS = ("latitude_deg", "longitude_deg", "altitude_m")


def site_meta(site: dict) -> dict[str, str]:
    """A guide's capture metadata for the bench's place: those of ``SITE_KEYS`` the site gives, as numbers."""
    return {key: repr(float(site[key])) for key in SITE_KEYS if key in site}


def stillness_tracker(config, sample_rate_hz: float) -> StillnessTracker:
    """The rest detector of a guide whose ``config`` has ``init_rest_s`` and ``window_s`` [s]:
    its initial rest at least one window of samples (made odd) and 2 more."""
    c = config
    init = max(c.init_rest_s, (2 * int(round(c.window_s * sample_rate_hz / 2)) + 3) / sample_rate_hz)
    return StillnessTracker(
        sample_rate_hz,
        init_rest_s=init,
        window_s=c.window_s,
        min_duration_s=0.0,
        margin_s=0.0,
        nan_policy="omit",
    )


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
