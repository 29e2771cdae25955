"""`station simulate --procedure NAME --out FILE [--seed N] [--date YYYY-MM-DD] [--effect NAME=VALUE ...]
[--truth FILE.json]`."""

from __future__ import annotations

import argparse
import json

from station.errors import InputError
from station.fileio import atomic_open, cannot_write, check_output, same_file
from station.procedures import registry
from station.textsafe import safe


def parse_assignments(items: list[str] | None, what: str) -> dict[str, float | str]:
    out: dict[str, float | str] = {}
    for item in items or []:
        if "=" not in item:
            raise InputError(None, None, f"{what} {item!r}: expected NAME=VALUE")
        name, value = item.split("=", 1)
        if name.strip() in out:  # the last one would win without a word (import's --map refuses it too)
            raise InputError(None, None, f"{what}: {name.strip()} given twice")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            out[name.strip()] = value.strip()
    return out


def seed_arg(text: str) -> int:
    """argparse type: a seed is a whole number >= 0 (numpy's generators refuse negatives)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value} is negative; seeds are whole numbers >= 0")
    return value


def date_arg(text: str) -> str:
    """argparse type: a calendar date, YYYY-MM-DD (what the capture's ``date`` holds)."""
    import datetime as _dt
    import re

    try:
        if not re.fullmatch(r"\d{4}-\d{2}-\d{2}", text.strip()):
            raise ValueError
        return _dt.date.fromisoformat(text.strip()).isoformat()
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a date (YYYY-MM-DD, e.g. 2026-11-29)") from None


def today_utc() -> str:
    """Today's date in UTC, YYYY-MM-DD: the date a capture simulated now carries."""
    import datetime as _dt

    return _dt.datetime.now(_dt.UTC).date().isoformat()


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help="write a realistic simulated capture and its truth",
        description="Simulate a capture of any procedure with the station's forward models.",
    )
    p.add_argument(
        "--procedure", required=True, choices=registry.names(), metavar="P", help=registry.one_of(registry.names())
    )
    p.add_argument("--out", required=True, help="capture file to write")
    p.add_argument("--seed", type=seed_arg, default=0)
    p.add_argument(
        "--date",
        type=date_arg,
        metavar="YYYY-MM-DD",
        help="the day the capture says it was measured (its 'date'; the compass field is IGRF's of that "
        "day); default: today (UTC), so a calibration saved from it is filed now, not on an old date",
    )
    p.add_argument(
        "--effect",
        action="append",
        metavar="NAME=VALUE",
        help="switch on an effect of diagnose.md with a size (units: see docs/models.md)",
    )
    p.add_argument("--truth", help="also write the truth (parameters, effects) as JSON here")
    p.add_argument(
        "--option",
        action="append",
        metavar="NAME=VALUE",
        help="simulator option, e.g. hold_s=5, averages=1, mode=reference, maneuver=straight",
    )
    p.set_defaults(func=run)


# What the command line can set, checked here so a bad value gets one line, not a traceback.
_FLAGS = {"averages", "label_positions"}
_COUNTS = {"extra_positions": 0, "n_orientations": 1}  # integer, at least this
# ... and at most this: P1 draws its extra positions one by one (1e308 never returned)
_COUNT_MAX = {"extra_positions": 1000}
_CHOICES = {"mode": ("static", "reference"), "maneuver": ("varied", "straight"), "reference": ("body", "nav")}
_POSITIVE = {"rate_hz", "hold_s", "duration_s", "radius_m", "g_mps2"}  # > 0; other numbers >= 0 unless angles
_SIGNED = {"latitude_deg", "pitch_deg", "roll_deg", "table_tilt_deg"}  # any finite value
_NOT_SETTABLE = {"seed", "effects", "site", "positions", "speeds_rad_s", "headings_deg", "truth_params"}


def settable_options(procedure: str) -> list[str]:
    """The ``--option`` names the procedure's simulator takes (its keyword-only parameters,
    less those the command line cannot set)."""
    import inspect

    import solvers.simulate

    function = getattr(solvers.simulate, registry.get(procedure).simulator)
    kinds = (inspect.Parameter.KEYWORD_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)
    return [
        name
        for name, p in inspect.signature(function).parameters.items()
        if p.kind in kinds and name not in _NOT_SETTABLE
    ]


def _option_value(name: str, value):
    import math

    if name in _NOT_SETTABLE:
        raise InputError(None, None, f"--option {name}: not settable from the command line")
    if name in _FLAGS:
        text = str(value).strip().lower()
        flags = {
            "1": True,
            "1.0": True,
            "true": True,
            "yes": True,
            "0": False,
            "0.0": False,
            "false": False,
            "no": False,
        }
        if text not in flags:
            raise InputError(None, None, f"--option {name}={value}: expected 0 or 1")
        return flags[text]
    if name in _CHOICES:
        if value not in _CHOICES[name]:
            raise InputError(None, None, f"--option {name}={value}: choose {' or '.join(_CHOICES[name])}")
        return value
    if isinstance(value, str):
        if value.lower() in {"true", "false", "yes", "no"}:
            return value.lower() in {"true", "yes"}
        raise InputError(None, None, f"--option {name}={value!r}: not a number")
    if not math.isfinite(value):
        raise InputError(None, None, f"--option {name}={value}: must be a finite number")
    if name in _COUNTS:
        if value != int(value) or value < _COUNTS[name]:
            raise InputError(None, None, f"--option {name}={value:g}: must be a whole number >= {_COUNTS[name]}")
        if value > _COUNT_MAX.get(name, math.inf):
            raise InputError(None, None, f"--option {name}={value:g}: at most {_COUNT_MAX[name]}")
        return int(value)
    if name in _POSITIVE and value <= 0:
        raise InputError(None, None, f"--option {name}={value:g}: must be positive")
    if name not in _SIGNED and not name.endswith("_deg") and value < 0:
        raise InputError(None, None, f"--option {name}={value:g}: must not be negative")
    return value


def _refuse_implausible(sim) -> None:
    """Options that make numbers no instrument reports (``mag_noise_uT=1e300``) would write a
    capture the station's own reader refuses: refused here, nothing written."""
    import numpy as np

    from station.capture import column_limit

    for name, values in sim.columns.items():
        values = np.asarray(values)
        if values.dtype.kind != "f" or not values.size:
            continue
        largest = float(np.nanmax(np.abs(values))) if not np.all(np.isnan(values)) else 0.0
        bound, reason = column_limit(name, sim.meta)
        if largest > bound:
            raise InputError(
                None, None, f"simulate: these options make column '{name}' reach {largest:.3g}, beyond {reason}"
            )


def run(args: argparse.Namespace) -> int:
    import math

    from solvers.simulate import SimulationError, simulate
    from station.capture import Capture, write_capture

    check_output(args.out)  # found out before the simulation, and before the capture is written beside a truth
    if args.truth:
        check_output(args.truth)
    if args.truth and same_file(args.truth, args.out):  # the truth would replace the capture
        raise InputError(args.truth, None, "--truth is the --out file: give the truth its own name")
    effects = parse_assignments(args.effect, "--effect")
    for name, size in effects.items():
        if isinstance(size, str):
            raise InputError(None, None, f"--effect {name}: {size!r} is not a number")
        if not math.isfinite(size):
            raise InputError(None, None, f"--effect {name}: {size} is not a finite number")
    options = parse_assignments(args.option, "--option")
    allowed = settable_options(args.procedure)
    for name in options:  # a mistyped name: which there are, not Python's "unexpected keyword argument"
        if name not in allowed and name not in _NOT_SETTABLE:
            raise InputError(
                None, None, f"--option {name}: not an option of {args.procedure} (its options: {', '.join(allowed)})"
            )
    options = {k: _option_value(k, v) for k, v in options.items()}
    if options.get("averages") and options.get("label_positions") is False:
        raise InputError(
            None,
            None,
            "--option label_positions=0 applies to time series: a table of averages "
            "(averages=1) always names its positions",
        )
    day = args.date or today_utc()  # the clock is read here: solvers/ stays pure
    takes_site = registry.get(args.procedure).takes_site
    if takes_site:
        options["site"] = {"date": day}
    try:
        sim = simulate(args.procedure, seed=args.seed, effects=effects, **options)
    except (SimulationError, TypeError) as exc:
        raise InputError(None, None, f"simulate: {exc}") from None
    except (MemoryError, OverflowError):  # OverflowError: a length beyond any integer (hold_s=1e308)
        raise InputError(None, None, "simulate: the options ask for more samples than fit in memory") from None
    except ValueError as exc:  # a day the site's model cannot give (P3: IGRF's field of --date), or an option
        if args.date and args.date in str(exc):
            raise InputError(None, None, f"--date {args.date}: {exc}") from None
        raise InputError(None, None, f"simulate: these options cannot be simulated ({exc})") from None
    except (IndexError, ZeroDivisionError) as exc:  # an option the simulator cannot honour
        raise InputError(None, None, f"simulate: these options cannot be simulated ({exc})") from None
    _refuse_implausible(sim)
    if not takes_site and args.date:  # a table without a site (P2): the date given is still its date
        sim.meta["date"] = day
    capture = Capture(meta=sim.meta, columns=sim.columns, path=args.out)
    if args.truth:  # both or neither: the truth's temporary is made first, renamed after the capture
        text = json.dumps(sim.truth, indent=2)
        with cannot_write(args.truth), atomic_open(args.truth) as f:
            f.write(text)
            write_capture(args.out, capture)
    else:
        write_capture(args.out, capture)
    n = len(next(iter(sim.columns.values())))
    print(
        f"wrote {safe(args.out)}: {args.procedure}, {n} rows, device {sim.meta.get('device')}"
        + (f", effects {effects}" if effects else "")
    )
    return 0
