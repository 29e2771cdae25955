"""`station simulate --procedure NAME --out FILE [--seed N] [--effect NAME=VALUE ...] [--truth FILE.json]`."""
from __future__ import annotations

import argparse
import json
import os
import tempfile

from station.errors import InputError

PROCEDURES = ("accel-tabletop", "accel-centrifuge", "compass", "gyro-drift", "ldv")


def parse_assignments(items: list[str] | None, what: str) -> dict[str, float | str]:
    out: dict[str, float | str] = {}
    for item in items or []:
        if "=" not in item:
            raise InputError(None, None, f"{what} {item!r}: expected NAME=VALUE")
        name, value = item.split("=", 1)
        try:
            out[name.strip()] = float(value)
        except ValueError:
            out[name.strip()] = value.strip()
    return out


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="write a realistic simulated capture and its truth",
                       description="Simulate a capture of any procedure with the station's forward models.")
    p.add_argument("--procedure", required=True, choices=PROCEDURES)
    p.add_argument("--out", required=True, help="capture file to write")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--effect", action="append", metavar="NAME=VALUE",
                   help="switch on an effect of diagnose.md with a size (units: see docs/models.md)")
    p.add_argument("--truth", help="also write the truth (parameters, effects) as JSON here")
    p.add_argument("--option", action="append", metavar="NAME=VALUE",
                   help="simulator option, e.g. hold_s=5, averages=1, mode=reference, maneuver=straight")
    p.set_defaults(func=run)


def _option_value(name: str, value):
    if isinstance(value, float) and name in {"averages", "label_positions"}:
        return bool(value)
    if isinstance(value, float) and name in {"extra_positions", "n_orientations"}:
        return int(value)
    if isinstance(value, str) and value.lower() in {"true", "false", "yes", "no"}:
        return value.lower() in {"true", "yes"}
    return value


def run(args: argparse.Namespace) -> int:
    from solvers.simulate import SimulationError, simulate
    from station.capture import Capture, write_capture

    effects = parse_assignments(args.effect, "--effect")
    for name, size in effects.items():
        if isinstance(size, str):
            raise InputError(None, None, f"--effect {name}: {size!r} is not a number")
    options = {k: _option_value(k, v) for k, v in parse_assignments(args.option, "--option").items()}
    try:
        sim = simulate(args.procedure, seed=args.seed, effects=effects, **options)
    except (SimulationError, TypeError) as exc:
        raise InputError(None, None, f"simulate: {exc}") from None
    write_capture(args.out, Capture(meta=sim.meta, columns=sim.columns, path=args.out))
    if args.truth:
        folder = os.path.dirname(os.path.abspath(args.truth))
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=".truth-", suffix=".json")
        with os.fdopen(fd, "w") as fh:
            json.dump(sim.truth, fh, indent=2)
        os.replace(tmp, args.truth)
    n = len(next(iter(sim.columns.values())))
    print(f"wrote {args.out}: {args.procedure}, {n} rows, device {sim.meta.get('device')}"
          + (f", effects {effects}" if effects else ""))
    return 0
