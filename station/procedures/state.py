"""Where a guided run's resume file lives (kept free of numpy so the TUI starts fast)."""

from __future__ import annotations

import os

from station.procedures import registry


def default_state_path(device_id: str, procedure: str = registry.DEFAULT, base: str | None = None) -> str:
    """``<base>/resume-<procedure>-<device>.json`` (device id made file-name safe)."""
    safe = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in device_id) or "device"
    return os.path.join(base or ".", f"resume-{procedure}-{safe}.json")
