"""Serial ports on this machine, through serial.tools.list_ports."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PortInfo:
    device: str
    description: str
    hwid: str


def list_ports(include_links: bool = False) -> list[PortInfo]:
    """Ports sorted by device path; `description`/`hwid` as pyserial reports them ('n/a' if unknown)."""
    from serial.tools import list_ports as lp

    found = lp.comports(include_links=include_links)
    return sorted(
        (PortInfo(p.device, p.description or "n/a", p.hwid or "n/a") for p in found),
        key=lambda p: p.device,
    )
