"""What the guides (``station/procedures/<stem>_guide.py``) do alike: the queue of events
the screen takes, abort, the end of a recording, the time it started, the place in the
capture's metadata, the recording's columns, and the rest detector of those that wait for the unit to be still."""

from __future__ import annotations

import datetime as _dt

import numpy as np

from solvers.stillness import StillnessTracker


def started_utc() -> str:
    """Now, as a guide's ``started``: UTC to the second, ``YYYY-MM-DDTHH:MM:SSZ``."""
    return _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


SITE_KEYS = ("latitude_deg", "longitude_deg", "altitude_m")


def site_meta(site: dict) -> dict[str, str]:
    """A guide's capture metadata for the bench's place: those of ``SITE_KEYS`` the site gives, as numbers."""
    return {key: repr(float(site[key])) for key in SITE_KEYS if key in site}


def recorded_columns(chunks: list[dict], blocks, optional: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """A recording's capture columns from its chunks (dicts holding ``t`` and ``temp`` (n,) and the
    (n, 3) arrays named in ``blocks``, ``((key, (x, y, z column names)), ...)``): ``t``, each block's
    three columns in order (a block named in ``optional`` is left out when it holds no number),
    and ``temp_c`` when a temperature was read."""

    def joined(key: str, empty: np.ndarray) -> np.ndarray:
        return np.concatenate([c[key] for c in chunks]) if chunks else empty

    cols = {"t": joined("t", np.zeros(0))}
    for key, names in blocks:
        arr = joined(key, np.zeros((0, 3)))
        if key in optional and not np.isfinite(arr).any():
            continue
        for i, name in enumerate(names):
            cols[name] = arr[:, i]
    temp = joined("temp", np.zeros(0))
    if np.isfinite(temp).any():
        cols["temp_c"] = temp
    return cols


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
