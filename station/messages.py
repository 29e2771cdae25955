"""Every message the TUI's workers post to its screens, in one module.

Workers run in threads; ``post_message`` is thread-safe. ``LiveUpdate`` is replaceable:
when the screen falls behind, only the newest is drawn (the guide itself sees every
sample on the worker thread, so nothing is lost for the averages).
"""

from __future__ import annotations

from textual.message import Message


class LiveUpdate(Message):
    """The newest guide status and source statistics (~15 per second)."""

    def __init__(self, status, stats, refresh_hz: float = float("nan")) -> None:
        super().__init__()
        self.status = status
        self.stats = stats
        self.refresh_hz = refresh_hz

    def can_replace(self, message: Message) -> bool:
        return isinstance(message, LiveUpdate)


class GuideEvent(Message):
    """Something the operator should see in the log: captured, skipped, restarted, done, aborted."""

    def __init__(self, kind: str, detail: str = "") -> None:
        super().__init__()
        self.kind = kind
        self.detail = detail


class SourceFailed(Message):
    """The source could not be opened or stopped delivering (one line)."""

    def __init__(self, error: str) -> None:
        super().__init__()
        self.error = error


class CalibrationReady(Message):
    """The fit of the captured positions: ``result`` (calibrate.md dict) or ``error``."""

    def __init__(
        self,
        capture,
        result: dict | None,
        error: str | None = None,
        previous: dict | None = None,
        alternative: str | None = None,
    ) -> None:
        super().__init__()
        self.capture = capture
        self.result = result
        self.error = error
        self.previous = previous  # the device's last accepted calibration of the procedure
        self.alternative = alternative  # with an error: a method the capture allows (UnsupportedError)


class Saved(Message):
    """A calibration was stored (``calibration_id``) or could not be (``error``); ``note``: one
    line to tell the operator beside it (a back-dated result's place in the history)."""

    def __init__(self, calibration_id: int | None, error: str | None = None, note: str | None = None) -> None:
        super().__init__()
        self.calibration_id = calibration_id
        self.error = error
        self.note = note


class Exported(Message):
    def __init__(self, paths: list[str], error: str | None = None) -> None:
        super().__init__()
        self.paths = paths
        self.error = error


class StoreLoaded(Message):
    """Database contents for a screen (devices, due list, history...), read off the UI thread."""

    def __init__(self, what: str, data, error: str | None = None) -> None:
        super().__init__()
        self.what = what
        self.data = data
        self.error = error


class Connected(Message):
    """The source is open: its device id and units are known."""

    def __init__(self, source, device_id: str, devices: list | None = None) -> None:
        super().__init__()
        self.source = source
        self.device_id = device_id
        self.devices = devices or []


class DiagnoseStep(Message):
    """The step a running diagnosis has begun, in words (station.diagnose_process)."""

    def __init__(self, step: str) -> None:
        super().__init__()
        self.step = step
