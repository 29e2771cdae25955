"""`station ports`: the serial ports this machine has (serial.tools.list_ports)."""

from __future__ import annotations

import argparse
import json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "ports",
        help="list serial ports",
        description="List serial ports (USB-UART adapters, flight controllers, built-in UARTs). "
        "Pseudo-terminals (station sim-device) are not listed: use the path sim-device prints.",
    )
    p.add_argument("--links", action="store_true", help="also list symlinks such as /dev/serial/by-id/*")
    p.add_argument(
        "--json",
        action="store_true",
        help="a JSON list of {device, description, hwid} (an empty list when there is none)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from station.device.ports import list_ports

    ports = list_ports(include_links=args.links)
    if args.json:
        print(
            json.dumps(
                [{"device": p.device, "description": p.description, "hwid": p.hwid} for p in ports],
                indent=2,
                ensure_ascii=False,
            )
        )
        return 0
    if not ports:
        print("no ports")
        return 0
    width = max(len(p.device) for p in ports)
    for p in ports:
        print(f"{p.device:<{width}}  {p.description}  [{p.hwid}]")
    return 0
