"""`station devices add|list|show`: the devices the station knows."""

from __future__ import annotations

import argparse
import math
import sys

from station.commands._dbutil import add_db_option, fmt_num, open_store, print_json, require_device
from station.errors import InputError
from station.procedures import registry
from station.textsafe import safe


def register(subparsers) -> None:
    p = subparsers.add_parser("devices", help="add, list and show devices")
    sub = p.add_subparsers(dest="devices_command", metavar="ACTION", required=True)

    add = sub.add_parser("add", help="add a device, or update the fields given of an existing one")
    add.add_argument("id", metavar="ID", help="device id (serial number), stored verbatim")
    add.add_argument("--model", help="device model")
    add.add_argument("--interval-days", type=float, help="recalibration interval in days")
    add.add_argument("--notes", help="free text")
    add.add_argument(
        "--kind",
        action="append",
        dest="kinds",
        metavar="KIND",
        choices=registry.sensor_kinds(),
        help=f"sensor kind ({', '.join(registry.sensor_kinds())}); repeatable",
    )
    add.add_argument(
        "--tolerance",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="largest acceptable change of a parameter (B[0]) or block (B) from its calibrated value; repeatable",
    )
    add.add_argument(
        "--limit",
        action="append",
        default=[],
        metavar="NAME=LOW:HIGH",
        help="absolute limits of a parameter (M[0][0]=0.98:1.02) or block (B=-0.5:0.5), in its units; "
        "leave one end empty for none (S=0.9:); NAME= removes one; repeatable",
    )
    add.set_defaults(func=_add)

    ls = sub.add_parser("list", help="every device")
    ls.add_argument("--json", action="store_true", help="a JSON list")
    ls.set_defaults(func=_list)

    show = sub.add_parser("show", help="one device and its latest calibrations")
    show.add_argument("id", metavar="ID")
    show.add_argument("--json", action="store_true", help="a JSON object")
    show.set_defaults(func=_show)
    for parser in (add, ls, show):
        add_db_option(parser)


def _tolerances(items: list[str]) -> dict | None:
    if not items:
        return None
    out = {}
    for item in items:
        name, sep, value = item.rpartition("=")
        try:
            number = float(value)
        except ValueError:
            number = None
        if not sep or not name or number is None or not number > 0:
            raise InputError(None, None, f"--tolerance {item!r}: expected NAME=VALUE with a positive number")
        out[name] = number
    return out


def parse_limit(item: str) -> tuple[str, list | None]:
    """``NAME=LOW:HIGH`` (either end may be empty, not both) → (name, [low, high]);
    ``NAME=`` → (name, None): remove that limit. ValueError says what is wrong. The CLI's
    ``--limit`` and the TUI's limits editor read the same syntax."""
    name, sep, span = item.strip().partition("=")
    name = name.strip()
    if sep and name and not span.strip():
        return name, None
    low, colon, high = span.partition(":")
    try:
        pair = [float(low) if low.strip() else None, float(high) if high.strip() else None]
    except ValueError:
        pair = None
    if (
        not sep
        or not colon
        or not name
        or pair is None
        or pair == [None, None]
        or any(x is not None and not math.isfinite(x) for x in pair)
        or (None not in pair and pair[0] > pair[1])
    ):
        raise ValueError(
            f"{item!r}: expected NAME=LOW:HIGH with LOW <= HIGH (one end may be empty), or NAME= to remove"
        )
    return name, pair


def _limits(items: list[str]) -> dict | None:
    if not items:
        return None
    out = {}
    for item in items:
        try:
            name, pair = parse_limit(item)
        except ValueError as exc:
            raise InputError(None, None, f"--limit {exc}") from None
        out[name] = pair
    return out


def _add(args: argparse.Namespace) -> int:
    if args.interval_days is not None and not args.interval_days > 0:
        raise InputError(None, None, f"--interval-days must be positive, got {args.interval_days:g}")
    with open_store(args, create=True) as store:  # adding a device is how a database is made
        existed = store.get_device(args.id) is not None
        device = store.add_device(
            args.id,
            model=args.model,
            notes=args.notes,
            interval_days=args.interval_days,
            sensor_kinds=args.kinds,
            tolerances=_tolerances(args.tolerance),
            limits=_limits(args.limit),
        )
    sys.stdout.write(f"{'updated' if existed else 'added'} device {safe(device['id'])}\n")
    return 0


def _list(args: argparse.Namespace) -> int:
    with open_store(args) as store:
        devices = store.list_devices()
    if args.json:
        print_json(devices)
        return 0
    if not devices:
        sys.stdout.write("no devices\n")
        return 0
    rows = [("ID", "MODEL", "KINDS", "INTERVAL_D", "CALIBRATIONS", "LAST_CALIBRATED", "NOTES")]
    for d in devices:
        rows.append(
            (
                safe(d["id"]),
                safe(d["model"] or "-"),
                safe(",".join(d["sensor_kinds"]) or "-"),
                fmt_num(d["interval_days"]),
                str(d["n_calibrations"]),
                safe(d["last_calibrated"] or "-"),
                safe(d["notes"] or ""),
            )
        )
    widths = [max(len(r[i]) for r in rows) if i < 6 else 0 for i in range(7)]
    for r in rows:
        sys.stdout.write("  ".join(c.ljust(w) if w else c for c, w in zip(r, widths)).rstrip(" ") + "\n")
    return 0


def _with_units(name: str, values: list, contexts: list[dict], fmt) -> str:
    """``NAME=LOW:HIGH`` (or ``NAME=VALUE``) as ``--limit``/``--tolerance`` take it, in the
    stored unit, said, and in the unit the screens show when that is another one: e.g.
    ``drift=-0.001:0.001 rad/s (-206.265:206.265 °/h)``."""
    from station.procedures.review import display_unit, param_unit, shown_value, unit_context

    ctx = unit_context(name, contexts)
    stored = safe(f"{name}=" + ":".join(fmt(v) for v in values))
    unit = param_unit(ctx, name) if ctx else ""
    if unit and unit != "1":
        stored += f" {safe(unit)}"
    disp = display_unit(ctx, name) if ctx else None
    if disp is None:
        return stored
    shown = ":".join(fmt(None if v is None else shown_value(ctx, name, v)) for v in values)
    return f"{stored} ({safe(shown)} {safe(disp[1])})"


def _show(args: argparse.Namespace) -> int:
    from station.procedures.review import record_result

    with open_store(args) as store:
        device = require_device(store, args.id)
        history = store.history(args.id)
    latest = {}
    for h in history:
        if h["accepted"]:
            latest[h["procedure"]] = h
    if args.json:
        device = dict(device)
        device["n_calibrations"] = len(history)
        device["latest"] = {p: {"id": h["id"], "time": h["time"]} for p, h in latest.items()}
        print_json(device)
        return 0
    contexts = [record_result(h) for h in [*latest.values(), *reversed(history)]]
    out = [
        f"device: {safe(device['id'])}",
        f"model: {safe(device['model'] or '-')}",
        f"sensor kinds: {safe(', '.join(device['sensor_kinds']) or '-')}",
        f"interval: {fmt_num(device['interval_days'])} days" if device["interval_days"] else "interval: -",
        "tolerances: "
        + (", ".join(_with_units(k, [v], contexts, fmt_num) for k, v in device["tolerances"].items()) or "-"),
        "limits: "
        + (
            ", ".join(
                _with_units(k, pair, contexts, lambda x: "" if x is None else format(x, "g"))
                for k, pair in device.get("limits", {}).items()
            )
            or "-"
        ),
        f"created: {safe(device['created'])}",
        f"calibrations: {len(history)}",
    ]
    for procedure, h in sorted(latest.items()):
        out.append(f"latest {safe(procedure)}: #{h['id']} {safe(h['time'])}")
    out.append(f"notes: {safe(device['notes']) if device['notes'] is not None else '-'}")
    sys.stdout.write("\n".join(out) + "\n")
    return 0
