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


def judge(path: str | None, result: dict, device_id: str | None = None):
    """(Assessment, device dict or None, previous accepted calibration or None) of ``result``
    against the device in the database at ``path`` (nothing to compare without one)."""
    import os

    from station.procedures.review import assess

    device = device_id or result.get("device")
    dev = previous = None
    if path and device and os.path.exists(path):
        store = open_store(path)
        try:
            dev = store.get_device(device)
            previous = store.reference(device, result.get("procedure") or "")
        finally:
            store.close()
    return assess(result, previous, dev), dev, previous


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
