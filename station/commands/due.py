"""`station due [--within DAYS] [--json]`: devices due for recalibration; exit 1 when any is.

For cron and systemd timers: exit status 0 = nothing due, 1 = something due or
overdue (listed on stdout), 2 = bad input.
"""

from __future__ import annotations

import argparse
import sys

from station.commands._dbutil import fit_line, open_store, print_json, terminal_width
from station.errors import InputError
from station.formatting import due_when
from station.textsafe import safe

MAX_WITHIN_DAYS = 36525.0  # the longest recalibration interval a device may have (db.store.MAX_INTERVAL_DAYS)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "due",
        help="devices due for recalibration (exit 1 when any is)",
        description="Devices due or overdue for recalibration: by their interval since the last accepted "
        "calibration, and earlier when a coefficient's drift trend leaves its tolerance first. "
        "Exit status 1 when anything is due, 0 when nothing is.",
    )
    p.add_argument("--within", type=float, default=0.0, metavar="DAYS", help="also list what falls due within DAYS")
    p.add_argument("--now", help=argparse.SUPPRESS)  # ISO date-time, for reproducible runs
    p.add_argument("--json", action="store_true", help="a JSON list, one object per device")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.within < 0:
        raise InputError(None, None, f"--within must not be negative, got {args.within:g}")
    if not args.within <= MAX_WITHIN_DAYS:  # NaN and inf too: they failed deep in the date arithmetic
        raise InputError(
            None, None, f"--within must be at most {MAX_WITHIN_DAYS:g} days (100 years), got {args.within:g}"
        )
    with open_store(args) as store:
        items = store.due(within_days=args.within, now=args.now)
        # calibrated but without an interval: never due, which "nothing due" alone hides (the
        # TUI registers a device with none); said on stderr, stdout stays what cron reads
        never = [d["id"] for d in store.list_devices() if d.get("last_calibrated") and not d.get("interval_days")]
    if never and not args.json:
        shown = ", ".join(safe(d) for d in never[:3]) + (f" and {len(never) - 3} more" if len(never) > 3 else "")
        sys.stderr.write(
            f"station: {len(never)} calibrated device{'s' if len(never) > 1 else ''} without a recalibration "
            f"interval, never due: {shown} (set one: station devices add ID --interval-days N)\n"
        )
    if args.json:
        print_json(items)
    elif not items:
        horizon = f" within {args.within:g} days" if args.within else ""
        sys.stdout.write(f"nothing due{horizon}\n")
    else:
        width = terminal_width()
        for e in items:
            when = due_when(e)
            sys.stdout.write(fit_line(f"{safe(e['device_id'])}: {when}", "", width) + "\n")
            for r in e["reasons"]:  # on a terminal, wrapped at its width (a drift reason: 150 columns)
                sys.stdout.write(fit_line(safe(r["text"]), "    ", width) + "\n")
    return 1 if items else 0
