"""Where a guided run's resume file lives (kept free of numpy so the TUI starts fast)."""

from __future__ import annotations

import os

from station.procedures import registry


def default_state_path(device_id: str, procedure: str = registry.DEFAULT, base: str | None = None) -> str:
    """``<base>/resume-<procedure>-<device>.json`` (device id made file-name safe)."""
    return os.path.join(base or ".", f"resume-{procedure}-{file_name_part(device_id)}.json")


def file_name_part(device_id: str | None) -> str:
    """``device_id`` as part of a file name: letters, digits, - _ . kept, anything else (a /
    that would name a folder, a control character) as _."""
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in device_id or "") or "device"
