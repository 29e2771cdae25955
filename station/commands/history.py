"""`station history ID [--procedure P] [--json]`: a device's calibrations, oldest first."""

from __future__ import annotations

import argparse
import sys

from station.commands._dbutil import fit_line, fmt_num, open_store, print_json, require_device, terminal_width
from station.formatting import sigma
from station.procedures import registry
from station.textsafe import safe


def register(subparsers) -> None:
    p = subparsers.add_parser("history", help="a device's calibrations, oldest first")
    p.add_argument("id", metavar="ID", help="device id")
    p.add_argument(
        "--procedure",
        choices=registry.names(),
        metavar="P",
        help=f"only this procedure ({registry.one_of(registry.names())})",
    )
    p.add_argument("--json", action="store_true", help="a JSON list of calibration records")
    p.set_defaults(func=run)


def _param_lines(record: dict) -> list[str]:
    """One line per top-level parameter: `B [m/s^2]: 0.1±0.001  0.2±0.001  ...`, in the units
    the screens show (P4's drift in °/h, the compass's soft iron as a ratio; ``--json``
    keeps the stored units)."""
    from db.params import flatten
    from station.procedures.review import record_result, shown_unit, shown_value

    result = record_result(record)
    params, uncertainty = record["params"], record["uncertainty"]
    lines = []
    for key, value in params.items():
        if isinstance(value, str):
            lines.append(f"{safe(key)}: {safe(value)}")
            continue
        vals = flatten({key: value})
        sig = flatten({key: (uncertainty or {}).get(key)})
        parts = []
        for name, v in vals.items():
            label = name[len(key) :]
            s = sig.get(name)
            text = fmt_num(shown_value(result, name, v)) + (
                f"±{sigma(shown_value(result, name, s), '.2g')}" if s is not None else ""
            )
            parts.append(f"{safe(label)}={text}" if label.startswith(".") else text)
        unit = shown_unit(result, key) if not isinstance(value, dict) else ""
        lines.append(f"{safe(key)}{f' [{safe(unit)}]' if unit and unit != '1' else ''}: " + "  ".join(parts))
    return lines


def run(args: argparse.Namespace) -> int:
    with open_store(args) as store:
        require_device(store, args.id)
        records = store.history(args.id, args.procedure)
    if args.json:
        print_json(records)
        return 0
    from station.procedures.review import record_result, residual_of, shown_residual

    # on a terminal, the parameter lines (a P1 M is nine value±σ pairs, 175 columns) wrap at its
    # width between pairs, indented; into a pipe or a file they stay one line each
    width = terminal_width()
    what = f" of {args.procedure}" if args.procedure else ""
    out = [f"device {safe(args.id)}: {len(records)} calibration{'s' if len(records) != 1 else ''}{what}, oldest first"]
    by_id = {r["id"]: r for r in records}
    for r in records:
        status = "accepted" if r["accepted"] else "rejected"
        if r["superseded_by"] is not None:
            status += f", superseded by #{r['superseded_by']}"
        res, unit = shown_residual(record_result(r))
        of = residual_of(record_result(r))  # what the RMS is over, as calibrate says it (P4: per sample)
        out.append(
            fit_line(
                f"#{r['id']}  {safe(r['time'])}  {safe(r['procedure'])}  {status}  residual_rms "
                f"{fmt_num(res, 4)}{f' {safe(unit)}' if unit else ''}{f' {of}' if of else ''}  "
                f"software {safe(r['software_version'] or '-')}",
                "",
                width,
            )
        )
        if r["back_dated_before"]:  # a back-dated capture saved after it now comes before it
            from station.store import back_dated_line

            before = [by_id[i] for i in r["back_dated_before"]]
            out.append(fit_line(f"note: {safe(back_dated_line(r, before))}", "    ", width))
        out.extend(fit_line(line, "    ", width) for line in _param_lines(r))
        out.extend(fit_line(f"warning: {safe(w)}", "    ", width) for w in r["warnings"])
    sys.stdout.write("\n".join(out) + "\n")
    return 0
