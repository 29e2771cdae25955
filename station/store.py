"""The application's door to the database: save a calibrate result with its capture."""
from __future__ import annotations

import getpass
import socket

from station import __version__
from station.procedures import registry


def open_store(path: str):
    from db.store import Store

    return Store(path)


def save_result(path: str, capture, result: dict, *, device_id: str | None = None,
                operator: str | None = None, accepted: bool = True) -> int:
    """Store ``capture`` and ``result`` in one transaction; returns the calibration id."""
    store = open_store(path)
    try:
        operator = operator or getpass.getuser()
    except Exception:
        operator = operator or None
    entry = registry.get(result.get("procedure") or capture.meta.get("procedure"))
    return store.save_calibration(result, meta=capture.meta, columns=capture.columns, device_id=device_id,
                                  operator=operator, accepted=accepted, software_version=__version__,
                                  host=socket.gethostname(), sensor_kind=entry.sensor_kind if entry else None)
