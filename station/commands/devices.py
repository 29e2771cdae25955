"""`station devices add|list|show` (alone: list): the devices the station knows."""

from __future__ import annotations

import argparse
import math
import sys

from station.commands._dbutil import add_db_option, fmt_num, open_store, print_json, require_device
from station.errors import InputError
from station.procedures import registry
from station.textsafe import safe

# the unit --tolerance and --limit take, as devices show, history and the screens print it
_UNITS_HELP = (
    "in the unit the station prints it in (P4 drift and earth_rate_body in °/h, the compass's "
    "soft_iron as a ratio, e.g. uT/uT; others as stored: devices show says each)"
)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "devices",
        help="add, list and show devices",
        description="Add, list and show devices; with no ACTION, list them.",
    )
    sub = p.add_subparsers(dest="devices_command", metavar="ACTION")
    p.set_defaults(func=_list, json=False)  # `station devices` alone: the list

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
        help="largest acceptable change of a parameter (B[0]) or block (B) from its calibrated value, "
        f"{_UNITS_HELP}; residual_rms: the fit's residual, in its procedure's unit (P4 °/h); repeatable",
    )
    add.add_argument(
        "--limit",
        action="append",
        default=[],
        metavar="NAME=LOW:HIGH",
        help="absolute limits of a parameter (M[0][0]=0.98:1.02) or block (B=-0.5:0.5), "
        f"{_UNITS_HELP}; leave one end empty for none (S=0.9:); NAME= removes one; repeatable",
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


def _typed_unit(item: str, name: str, contexts: list[dict]) -> tuple[dict, str]:
    """review.typed_context of ``name`` typed in ``item``; its ValueError names the item."""
    from station.procedures.review import typed_context

    try:
        return typed_context(name, contexts)
    except ValueError as exc:
        raise ValueError(f"{item!r}: {exc}") from None


def _typed(option: str, item: str, name: str, contexts: list[dict]) -> tuple[dict, str]:
    """:func:`_typed_unit` for ``option``: a name whose unit cannot be known is refused in one line."""
    try:
        return _typed_unit(item, name, contexts)
    except ValueError as exc:
        raise InputError(None, None, f"{option} {exc}") from None


def _in_unit(name: str, unit: str) -> str:
    """'; drift is in °/h' for an error message ('' when the unit is none or unknown)."""
    return f"; {name} is in {unit}" if unit and unit != "1" else ""


def _tolerances(items: list[str], contexts: list[dict]) -> dict | None:
    """``NAME=VALUE`` typed in the unit the station shows ``NAME`` in → {name: stored value}."""
    from station.procedures.review import stored_value

    if not items:
        return None
    out = {}
    for item in items:
        name, sep, value = item.rpartition("=")
        name = name.strip()
        if sep and name:
            try:  # a typo (dirft) was stored and never checked, as a limit's was
                _check_limit_name(item, name, contexts)
            except ValueError as exc:
                raise InputError(None, None, f"--tolerance {exc}") from None
        ctx, unit = _typed("--tolerance", item, name, contexts) if sep and name else ({}, "")
        try:
            number = float(value)
        except ValueError:
            number = None
        if not sep or not name or number is None or not (number > 0 and math.isfinite(number)):
            raise InputError(
                None, None, f"--tolerance {item!r}: expected NAME=VALUE with a positive number{_in_unit(name, unit)}"
            )
        if name in out:
            raise InputError(None, None, f"--tolerance: {name} given twice")
        out[name] = stored_value(ctx, name, number)
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


def typed_limit(item: str, contexts: list[dict]) -> tuple[str, list | None, str]:
    """``NAME=LOW:HIGH`` typed in the unit the station shows ``NAME`` in (:func:`parse_limit`)
    → (name, [low, high] in the stored unit, the typed unit); ``NAME=`` → (name, None, ''):
    remove it, whatever unit it was in. ``contexts``: the results that tell the units, the
    device's calibrations (:func:`unit_contexts`). ValueError, one line: a bad entry (with
    the unit ``NAME`` is typed in), or a unit they cannot tell yet (review.typed_context).
    The CLI's ``--limit`` and the TUI's limits editor convert and refuse through this."""
    from station.procedures import review

    name = item.strip().partition("=")[0].strip()
    try:
        name, pair = parse_limit(item)
    except ValueError as exc:
        unit = _limit_unit_typed(item, name, contexts)[1] if name and "=" in item else ""
        raise ValueError(f"{exc}{_in_unit(name, unit)}") from None
    if pair is None:
        return name, None, ""
    _check_limit_name(item, name, contexts)
    ctx, unit = _limit_unit_typed(item, name, contexts)
    if ctx is None:  # typed as a ratio before the device's first compass calibration: kept so, said so
        return name, [*pair, review.RATIO], unit
    stored = [None if x is None else review.stored_value(ctx, name, x) for x in pair]
    stored_unit = review.limit_unit(ctx, name, typed_as_shown=False)
    return name, stored + ([stored_unit] if stored_unit else []), unit


def _limit_unit_typed(item: str, name: str, contexts: list[dict]) -> tuple[dict | None, str]:
    """:func:`_typed_unit` for a limit: where no calibration tells the capture's unit but the
    screens show ``name`` alike for every capture (the soft iron's ratio), (None, that unit):
    the limit is stored in it, with its unit (review.limit_unit), and read in each result's."""
    from station.procedures.review import RATIO, limit_unit, ratio_unit, unit_context

    try:
        return _typed_unit(item, name, contexts)
    except ValueError:
        ctx = unit_context(name, contexts)
        if limit_unit(ctx, name, typed_as_shown=True) != RATIO:
            raise
        return None, ratio_unit(ctx, name)


def _check_limit_name(item: str, name: str, contexts: list[dict]) -> None:
    """ValueError when the device's calibrations show ``name`` limits nothing: an element
    beyond its block (``B[9]``), or a name no calibrated procedure has and no other
    procedure's parameter list claims (a typo: ``dirft``). A limit was stored and never
    checked. Without a calibration, the names every procedure's result can hold
    (``PARAM_SHAPES``) are those known: a typo was stored there too, for the first
    calibration to ignore."""
    from station.procedures.review import block_of, flatten, unit_context

    names: dict[str, set[str]] = {}  # block -> its scalar names, over the device's calibrations
    procedures = set()
    for ctx in contexts:
        params = (ctx or {}).get("params")
        if not params:
            continue
        procedures.add(ctx.get("procedure"))
        for key in flatten(params):
            names.setdefault(block_of(key), set()).add(key)
    if not names:  # no calibration yet: any procedure's parameters
        names, procedures = _every_procedures_names(), None
    if name == "residual_rms" or name in names or any(name in keys for keys in names.values()):
        return
    block = block_of(name)
    if block in names:
        keys = sorted(names[block])
        span = keys[0] if len(keys) == 1 else f"{keys[0]} … {keys[-1]}"
        owner = "of this device " if procedures is not None else ""
        raise ValueError(f"{item!r}: {block} {owner}is {span}: no {name}")
    owner = unit_context(name, []).get("procedure")
    if procedures is not None and owner is not None and owner not in procedures:
        return  # another procedure's parameter: a limit for its first calibration
    shown = ", ".join(sorted({n.split(".")[0] + (".…" if "." in n else "") for n in names}))
    where = "this device's calibrations" if procedures is not None else "any procedure's results"
    raise ValueError(f"{item!r}: no parameter {name!r} in {where} ({shown})")


def _every_procedures_names() -> dict[str, set[str]]:
    """Block -> its scalar names, over every procedure's ``PARAM_SHAPES``."""
    import numpy as np

    from station.procedures import registry
    from station.procedures.review import block_of

    names: dict[str, set[str]] = {}
    for entry in registry.PROCEDURES:
        for block, shape in getattr(entry.load(), "PARAM_SHAPES", {}).items():
            for index in np.ndindex(*shape):
                key = block + "".join(f"[{i}]" for i in index)
                names.setdefault(block_of(key), set()).add(key)
    return names


def _limits(items: list[str], contexts: list[dict]) -> dict | None:
    """``NAME=LOW:HIGH`` typed in the unit the station shows ``NAME`` in → {name: stored pair}."""
    if not items:
        return None
    out = {}
    for item in items:
        try:
            name, pair, _ = typed_limit(item, contexts)
        except ValueError as exc:
            raise InputError(None, None, f"--limit {exc}") from None
        if name in out:
            raise InputError(None, None, f"--limit: {name} given twice")
        out[name] = pair
    return out


def unit_contexts(history: list[dict]) -> list[dict]:
    """A device's calibrations (``Store.history``, oldest first) as the results that tell its
    parameters' units (review.unit_context): the accepted one of each procedure first, then
    newest first."""
    from station.procedures.review import record_result

    latest = {h["procedure"]: h for h in history if h["accepted"]}  # oldest first: the newest wins
    return [record_result(h) for h in [*latest.values(), *reversed(history)]]


def _device_contexts(args: argparse.Namespace) -> list[dict]:
    """:func:`unit_contexts` of the device being added, read without making a database ([] when
    there is none yet, or no such device)."""
    from station.cli import db_path
    from station.commands._dbutil import require_existing

    try:
        require_existing(db_path(args))
    except InputError:
        return []  # no database yet: adding the device makes it
    with open_store(args) as store:
        if store.get_device(args.id) is None:
            return []
        return unit_contexts(store.history(args.id))


def _add(args: argparse.Namespace) -> int:
    from db.store import MAX_INTERVAL_DAYS

    if args.interval_days is not None and not 0 < args.interval_days <= MAX_INTERVAL_DAYS:
        raise InputError(
            None,
            None,
            f"--interval-days must be positive, at most {MAX_INTERVAL_DAYS:g} (100 years), got {args.interval_days:g}",
        )
    # typed in the units the station shows, stored in the parameters' own: read and converted
    # before anything is written (a refusal leaves no database and no change behind)
    contexts = _device_contexts(args) if args.tolerance or args.limit else []
    tolerances = _tolerances(args.tolerance, contexts)
    limits = _limits(args.limit, contexts)
    with open_store(args, create=True) as store:  # adding a device is how a database is made
        before = store.get_device(args.id)
        existed = before is not None
        device = store.add_device(
            args.id,
            model=args.model,
            notes=args.notes,
            interval_days=args.interval_days,
            sensor_kinds=args.kinds,
            tolerances=tolerances,
            limits=limits,
        )
    sys.stdout.write(f"{'updated' if existed else 'added'} device {safe(device['id'])}\n")
    gone = [k for k in ((before or {}).get("sensor_kinds") or []) if k not in device["sensor_kinds"]]
    if gone:  # --kind gives the whole list: `--kind mag` on an accelerometer replaced accel without a word
        keep = " ".join(f"--kind {k}" for k in device["sensor_kinds"] + gone)
        sys.stderr.write(
            safe(
                f"station: warning: device {device['id']}'s sensor kinds are now {', '.join(device['sensor_kinds'])}, "
                f"no longer {', '.join(gone)} (--kind gives the whole list: {keep} keeps every one)"
            )
            + "\n"
        )
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
    """``NAME=LOW:HIGH`` (or ``NAME=VALUE``) as ``--limit``/``--tolerance`` take it: in the
    unit the screens show, said, and the stored value when that is in another unit: e.g.
    ``drift=-206.265:206.265 °/h (stored -0.001:0.001 rad/s)``."""
    from station.procedures.review import display_unit, param_unit, result_unit, shown_value, typed_context

    try:
        ctx, unit = typed_context(name, contexts)
    except ValueError:  # unit unknown: as stored, no unit said
        ctx, unit = {}, ""
    disp = display_unit(ctx, name) if ctx else None
    shown = values if disp is None else [None if v is None else shown_value(ctx, name, v) for v in values]
    text = safe(f"{name}=" + ":".join(fmt(v) for v in shown))
    if unit and unit != "1":
        text += f" {safe(unit)}"
    if disp is None:
        return text
    stored_unit = result_unit(ctx) if name == "residual_rms" else param_unit(ctx, name)
    stored = ":".join(fmt(v) for v in values)
    return f"{text} (stored {safe(stored)}" + (f" {safe(stored_unit)})" if stored_unit else ")")


def _limit_text(name: str, lim, contexts: list[dict]) -> str:
    """A stored limit as ``--limit`` takes it (:func:`_with_units`); one stored with its unit
    (review.limit_parts) is shown in the unit the device's calibrations show ``name`` in where
    it converts, its stored values and unit said."""
    from station.procedures.review import limit_parts, shown_limit, unit_context

    def fmt(x):
        return "" if x is None else format(x, "g")

    low, high, unit = limit_parts(lim)
    if unit is None:
        return _with_units(name, [low, high], contexts, fmt)
    shown_low, shown_high, shown_unit = shown_limit(unit_context(name, contexts), name, lim)
    text = safe(f"{name}={fmt(shown_low)}:{fmt(shown_high)}") + (f" {safe(shown_unit)}" if shown_unit else "")
    stored = safe(f"{fmt(low)}:{fmt(high)} {unit}")
    return text if (shown_low, shown_high, shown_unit) == (low, high, unit) else f"{text} (stored {stored})"


def _show(args: argparse.Namespace) -> int:
    from db.store import MAX_INTERVAL_DAYS
    from station.formatting import due_when

    with open_store(args) as store:
        device = require_device(store, args.id)
        history = store.history(args.id)
        # every date ahead: the device's next due date, which `due` lists only within its window
        due = [d for d in store.due(within_days=2 * MAX_INTERVAL_DAYS) if d["device_id"] == args.id]
    latest = {}
    for h in history:
        if h["accepted"]:
            latest[h["procedure"]] = h
    if args.json:
        device = dict(device)
        device["n_calibrations"] = len(history)
        device["latest"] = {
            p: {"id": h["id"], "time": h["time"], "back_dated_before": h["back_dated_before"]}
            for p, h in latest.items()
        }
        print_json(device)
        return 0
    contexts = unit_contexts(history)
    out = [
        f"device: {safe(device['id'])}",
        f"model: {safe(device['model'] or '-')}",
        f"sensor kinds: {safe(', '.join(device['sensor_kinds']) or '-')}",
        f"interval: {fmt_num(device['interval_days'])} days" if device["interval_days"] else "interval: -",
        "due: "
        + (
            due_when(due[0]).removeprefix("due ")
            if due
            else "never (no recalibration interval: station devices add ID --interval-days N)"
            if device["interval_days"] is None
            else "-"
        ),
        "tolerances: "
        + (", ".join(_with_units(k, [v], contexts, fmt_num) for k, v in device["tolerances"].items()) or "-"),
        "limits: " + (", ".join(_limit_text(k, lim, contexts) for k, lim in device.get("limits", {}).items()) or "-"),
        f"created: {safe(device['created'])}",
        f"calibrations: {len(history)}",
    ]
    by_id = {h["id"]: h for h in history}
    for procedure, h in sorted(latest.items()):
        out.append(f"latest {safe(procedure)}: #{h['id']} {safe(h['time'])}")
        if h["back_dated_before"]:  # a back-dated capture saved after it now comes before it
            from station.store import back_dated_line

            note = back_dated_line(h, [by_id[i] for i in h["back_dated_before"]])
            out.append(f"  note: {safe(note)}")
    out.append(f"notes: {safe(device['notes']) if device['notes'] is not None else '-'}")
    sys.stdout.write("\n".join(out) + "\n")
    return 0
