"""The application's door to the database: save a calibrate result with its capture."""

from __future__ import annotations

import getpass
import socket

from station import __version__
from station.procedures import registry


def open_store(path: str):
    from db.store import Store

    return Store(path)


NOT_JUDGED = object()  # save_result without a judgement to keep current (imports, tools)


def save_result(
    path: str,
    capture,
    result: dict,
    *,
    device_id: str | None = None,
    operator: str | None = None,
    accepted: bool = True,
    review: dict | None = None,
    time=None,
    judged_reference=NOT_JUDGED,
) -> int:
    """Store ``capture`` and ``result`` in one transaction; returns the calibration id.

    ``review`` is ``station.procedures.review.review_record(...)`` (how the result was
    judged and decided). A capture already stored raises ``db.store.DuplicateCapture``.
    ``judged_reference``: the previous calibration ``judge`` compared the result with (its
    dict, or None for none); when another became the reference since, nothing is saved and
    ``db.store.ReferenceChanged`` says so (the check and the save are one transaction).
    """
    store = open_store(path)
    operator = operator or str(capture.meta.get("operator") or "") or None  # who recorded it, as the report says
    try:
        operator = operator or getpass.getuser()
    except Exception:
        operator = operator or None
    entry = registry.get(result.get("procedure") or capture.meta.get("procedure"))
    try:
        return store.save_calibration(
            result,
            meta=capture.meta,
            columns=capture.columns,
            device_id=device_id,
            operator=operator,
            accepted=accepted,
            software_version=__version__,
            host=socket.gethostname(),
            review=review,
            time=time,
            sensor_kind=entry.sensor_kind if entry else None,
            **(
                {}
                # judge() reads the reference of result["procedure"]: without one, nothing to keep current
                if judged_reference is NOT_JUDGED or not result.get("procedure")
                else {"judged_reference": judged_reference["id"] if judged_reference else None}
            ),
        )
    finally:
        store.close()


def save_time(capture, time=None) -> str:
    """The time a save of ``capture`` stores (``Store.save_calibration``): ``time``, else the
    capture's ``date`` (``db.params.capture_time``: a date alone is read at now, so one dated
    today is now and an earlier one its date's 23:59:59), else now; UTC text. ValueError for a
    date that is not ISO 8601."""
    from db import params as P

    return P.normalize_time(time) if time is not None else (P.capture_time(capture.meta) or P.iso(P.now_utc()))


def run_start(capture, started) -> str | None:
    """``started`` (a guided run's start, with its time of day) when it is this capture's run
    (on the capture's date), else None (an imported file): the time the TUI saves with."""
    if isinstance(started, str) and started[:10] == str(capture.meta.get("date", ""))[:10]:
        return started
    return None


def previous_at(store, device_id: str, procedure: str, capture, started=None) -> dict | None:
    """The calibration a TUI result of ``capture`` is judged against: the device's accepted one
    of ``procedure`` in use at the time its save stores (`save_time`, `run_start`)."""
    try:
        at = save_time(capture, run_start(capture, started))
    except ValueError:
        at = None  # the save refuses the date; nothing better to compare with than the latest
    return store.reference(device_id, procedure, before=at)


def judge(path: str | None, result: dict, device_id: str | None = None, at=None):
    """(Assessment, device dict or None, previous accepted calibration or None) of ``result``
    against the device in the database at ``path`` (nothing to compare without one).

    The previous calibration is the one in use at the result's own time ``at`` (`save_time`;
    None: now): a capture dated before the device's latest calibration (an older log imported,
    a file calibrated late) is judged against the calibration current at its date, the one its
    save supersedes (``Store.save_calibration``), not against a later one."""
    import os

    from db import params as P
    from station.procedures.review import assess

    device = device_id or result.get("device")
    dev = previous = None
    if path and device and os.path.exists(path):
        store = open_store(path)
        try:
            dev = store.get_device(device)
            before = at if at is not None else P.now_utc()
            previous = store.reference(device, result.get("procedure") or "", before=before)
        finally:
            store.close()
    return assess(result, previous, dev), dev, previous


def later_line(path: str, calibration_id: int) -> str | None:
    """One line for a calibration saved with a date before the device's latest of its procedure
    (a back-dated capture), naming the next one and what it stays judged against; None when it
    is the latest. The later records are not rewritten: each is hashed into the device's chain
    with the judgement made when it was saved (README, "Tamper evidence")."""
    store = open_store(path)
    try:
        saved = store.calibration(calibration_id)
        later = store.later(calibration_id) if saved["accepted"] else []
    finally:
        store.close()
    if not later:
        return None
    nxt = later[0]
    judged = (nxt.get("review") or {}).get("previous_calibration_id", nxt["supersedes"])
    was = f"judged when saved against #{judged}" if judged is not None else "saved with no previous calibration"
    more = f" and {len(later) - 1} more" if len(later) > 1 else ""
    return (
        f"calibration {calibration_id} is dated {saved['time'][:10]}, before #{nxt['id']} of "
        f"{nxt['time'][:10]}{more}: it takes its place in the history at its date, superseded by #{nxt['id']}, "
        f"which stays as saved ({was}, not judged again)"
    )


def back_dated_line(record: dict, before: list[dict], judged: bool = True) -> str | None:
    """One short line for a calibration (``record``: a `history` or `calibration` dict) before
    which back-dated captures were saved later (``before``: `Store.back_dated_before`, nearest
    first; None when empty): which one, its date, when it was saved, and that ``record`` keeps
    the judgement made when it was saved (``judged=False``: not that, for the History screen's
    narrow column at 80x24). The `history`, `devices show`, report and History screen say it
    alike; `later_line` is the same event told when the back-dated one is saved."""
    if not before:
        return None
    b = before[0]
    # its time of day where the two share a date (a date alone sorts at its day's end)
    dated = b["time"][:10] if b["time"][:10] != record["time"][:10] else b["time"][:16].replace("T", " ")
    saved = str(b.get("saved_at") or "?")[:16].replace("T", " ")
    more = f" (and {len(before) - 1} more)" if len(before) > 1 else ""
    x = record["id"]
    line = f"#{b['id']} dated {dated}, saved {saved} UTC after #{x}, now precedes it{more}"
    if not judged:
        return line
    from db.store import compared_with

    ref = compared_with(record)
    return (
        line + f"; #{x} stays as " + (f"judged against #{ref}" if ref is not None else "with no previous calibration")
    )


def kind_added(device: dict | None, result: dict) -> str | None:
    """The sensor kind a save adds to an existing device registered for other kinds (a compass
    result saved to a unit registered as an accelerometer); None when it has that kind, has
    none registered (the TUI registers devices without), or is new. The store adds the kind:
    a device may carry several sensors (an IMU's gyro, a compass module's magnetometer); the
    warning (calibrate --save, the Results screen) catches a device id that names another unit."""
    entry = registry.get(result.get("procedure"))
    kinds = (device or {}).get("sensor_kinds") or []
    if entry is None or not kinds or entry.sensor_kind in kinds:
        return None
    return entry.sensor_kind
