"""The Results and noise screens' export action: the capture and its result as files."""

from __future__ import annotations

import datetime as _dt
import os
from collections.abc import Callable

from station.fileio import atomic_write_json
from station.messages import Exported
from station.procedures.state import file_name_part
from station.textsafe import tui_markup


def export_files(screen, capture, what: str, payload: Callable) -> None:
    """Write ``capture`` (CSV) and ``payload()`` (JSON, unless None) to the export folder
    as ``<device>-<what>-<stamp>.*``, atomically; post Exported to ``screen``. The stamp is
    UTC, ``YYYYMMDD-HHMMSSZ``, as every time the station writes (the database, captures,
    reports, ``station export``); it was the computer's local time."""
    s = screen.app.session
    folder = s.extra.get("export_dir") or os.getcwd()
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y%m%d-%H%M%SZ")
    base = os.path.join(folder, f"{file_name_part(s.device_id)}-{what}-{stamp}")  # 'lab/unit7': no folder
    try:
        from station.capture import write_capture

        paths = [base + ".csv"]
        write_capture(paths[0], capture)
        data = payload()
        if data is not None:
            paths.append(base + ".json")
            atomic_write_json(paths[1], data, indent=2)
        screen.post_message(Exported(paths))
    except Exception as exc:  # noqa: BLE001
        screen.post_message(Exported([], error=str(exc)))


def exported_text(paths) -> str:
    """'Exported a.csv, a.json in FOLDER' (markup-safe): the operator is told where they are."""
    folders = {os.path.dirname(os.path.abspath(p)) for p in paths}
    where = f" in {folders.pop()}" if len(folders) == 1 else ""
    return tui_markup("Exported " + ", ".join(os.path.basename(p) for p in paths) + where)
