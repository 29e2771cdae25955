"""`station drift ID [--param NAME] [--json]`: each coefficient's trend over time."""

from __future__ import annotations

import argparse
import os
import sys

from db.params import DRIFT_MIN_CALIBRATIONS, DRIFT_SIGNIFICANCE
from station.commands._dbutil import aligned, fit_line, fmt_num, open_store, print_json, require_device, terminal_width
from station.errors import InputError
from station.procedures import registry
from station.textsafe import safe

MAX_PLOTS = 4


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "drift",
        help="trend of each calibration coefficient, rate per year ± sigma",
        description="Each coefficient's trend over the device's accepted calibrations: rate per year ± sigma "
        f"(weighted least squares), its significance, and when a significant trend (≥ {DRIFT_SIGNIFICANCE:g}σ over "
        f"≥ {DRIFT_MIN_CALIBRATIONS} calibrations) leaves the coefficient's tolerance.",
    )
    p.add_argument("id", metavar="ID", help="device id")
    p.add_argument("--param", help="one coefficient (B[0], beam1.dK) or a block (B = all of B)")
    p.add_argument(
        "--procedure",
        choices=registry.names(),
        metavar="P",
        help=f"only this procedure ({registry.one_of(registry.names())})",
    )
    p.add_argument("--json", action="store_true", help="a JSON list, one object per coefficient")
    p.add_argument("--no-plot", action="store_true", help="the table without the terminal plot")
    p.set_defaults(func=run)


_SCALED = ("value_in_use", "rate_per_year", "rate_sigma_per_year", "trend_value_at_last", "tolerance")


def _shown(store, device_id: str, trends: list[dict]) -> list[dict]:
    """``trends`` in the units the screens show (P4's drift in °/h, the compass's soft iron
    as a ratio), each with its ``unit``; the unit is read from the calibration in use of
    its procedure (``--json`` keeps the stored units)."""
    from station.procedures.review import record_result, shown_unit, shown_value

    contexts: dict[str, dict] = {}
    out = []
    for t in trends:
        proc, name = t["procedure"], t["param"]
        if proc not in contexts:
            ref = store.reference(device_id, proc)
            contexts[proc] = record_result(ref) if ref else {"procedure": proc}
        ctx = contexts[proc]

        def f(x, name=name, ctx=ctx):
            return None if x is None else shown_value(ctx, name, x)

        shown = {k: f(t[k]) for k in _SCALED}
        shown.update(values=[f(v) for v in t["values"]], sigmas=[f(v) for v in t["sigmas"]])
        out.append(dict(t, **shown, unit=shown_unit(ctx, name)))
    return out


def _significance(t: dict) -> float:
    if t["rate_per_year"] is None:
        return -1.0
    if not t["rate_sigma_per_year"]:
        return 0.0
    return abs(t["rate_per_year"]) / t["rate_sigma_per_year"]


_HEADER = (
    "PROCEDURE",
    "PARAM",
    "UNIT",
    "N",
    "IN_USE",
    "RATE/YEAR",
    "±SIGMA",
    "SIGNIF",
    "TOLERANCE",
    "LEAVES_TOLERANCE",
)
_LEGEND = (
    f"SIGNIF: |rate| / its sigma; * = significant (≥ {DRIFT_SIGNIFICANCE:g}σ over ≥ {DRIFT_MIN_CALIBRATIONS} "
    "calibrations)"
)


def _cells(t: dict) -> tuple[str, ...]:
    """One trend as the cells of ``_HEADER``."""
    signif = "-" if t["significance_sigmas"] is None else f"{t['significance_sigmas']:.1f}σ"
    if t["significant"]:
        signif += " *"
    return (
        safe(t["procedure"]),
        safe(t["param"]),
        safe(t["unit"] or "-"),
        str(t["n"]),
        fmt_num(t["value_in_use"]),
        fmt_num(t["rate_per_year"], 3),
        fmt_num(t["rate_sigma_per_year"], 2),
        signif,
        fmt_num(t["tolerance"]),
        safe((t["leaves_tolerance"] or "-")[:10]),
    )


def _fit_row(line: str, cells: tuple[str, ...], indent: str, width: int) -> list[str]:
    """A table row wider than ``width``: broken between its cells (never inside one), the
    continuation indented."""
    if len(line) <= width:
        return [line]
    out, cur = [], indent + cells[0]
    for c in cells[1:]:
        if len(cur) + 2 + len(c) > width:
            out.append(cur)
            cur = indent + "    " + c
        else:
            cur += "  " + c
    return out + [cur]


def _grouped(rows: list[tuple[str, ...]], width: int) -> list[str]:
    """The table for a terminal too narrow for one line per coefficient with its procedure
    and unit: one small table per procedure and unit, under a heading that names both
    (``accel-tabletop [m/s^2]``); TOLERANCE and LEAVES (the date a significant trend leaves
    its tolerance) only where a tolerance is set. A group still too wide (long names such as
    ``reference.declination_deg``) gives each name its own line, its figures on the next."""
    groups: dict[tuple[str, str], list[tuple[str, ...]]] = {}
    for r in rows:
        groups.setdefault((r[0], r[2]), []).append(r)
    out = []
    for (proc, unit), members in groups.items():
        with_tolerance = any(r[8] != "-" for r in members)
        unit_text = "no unit" if unit == "-" else unit
        out.append(fit_line(f"{proc} [{unit_text}]" + ("" if with_tolerance else ", no tolerances set"), "", width))
        figures = [
            ("N", "IN_USE", "RATE/YEAR", "±SIGMA", "SIGNIF") + (("TOLERANCE", "LEAVES") if with_tolerance else ())
        ]
        figures += [r[3:8] + (r[8:10] if with_tolerance else ()) for r in members]
        names = ["PARAM"] + [r[1] for r in members]
        lines = aligned([(n, *f) for n, f in zip(names, figures)], "  ")
        if max(map(len, lines)) <= width:
            out += lines
            continue
        for name, line, cells in zip(names, aligned(figures, "      "), figures):
            out.append(fit_line(name, "  ", width))
            out += _fit_row(line, cells, "      ", width)
    legend = (
        _LEGEND + ": only those get a LEAVES date (when the trend leaves its TOLERANCE) and can bring the "
        "due date forward"
    )
    return out + [fit_line(legend, "", width)]


def _plot(trends: list[dict]) -> str:
    import plotext as plt

    from station.term import color_enabled
    from station.timeaxis import time_axis

    tty = sys.stdout.isatty()
    color = color_enabled(sys.stdout)
    try:
        width = min((os.get_terminal_size(sys.stdout.fileno()).columns if tty else 0) or 100, 120)  # 0: size unknown
    except OSError:
        width = 100
    figures = []
    for t in trends:
        plt.clear_figure()
        if not color:
            plt.theme("clear")
        plt.plotsize(width, 15)
        axis = time_axis(t["times"])
        xs = axis["x"]
        ys = t["values"]
        if all(s is not None for s in t["sigmas"]):
            plt.error(xs, ys, yerr=t["sigmas"])
        plt.scatter(xs, ys, marker="dot", label=t["param"])
        if t["rate_per_year"] is not None and t["trend_value_at_last"] is not None:
            y_last = t["trend_value_at_last"]
            ends = [xs[0], xs[-1]]
            per_day = t["rate_per_year"] / 365.25  # x is in days
            plt.plot(ends, [y_last + per_day * (x - xs[-1]) for x in ends], label="trend")
        rate = (
            ""
            if t["rate_per_year"] is None
            else (
                f"  {fmt_num(t['rate_per_year'], 3)} ± {fmt_num(t['rate_sigma_per_year'], 2)} "
                f"{t.get('unit') or ''}/year".replace(" /year", "/year")
            )
        )
        plt.title(safe(f"{t['procedure']} {t['param']}{rate}"))
        plt.xlim(*axis["xlim"])
        plt.xticks(axis["ticks"], axis["labels"])
        plt.xlabel(axis["label"])
        text = plt.build()
        figures.append(text if color else plt.uncolorize(text))
    return "\n".join(figures)


def run(args: argparse.Namespace) -> int:
    with open_store(args) as store:
        require_device(store, args.id)
        trends = store.drift(args.id, procedure=args.procedure, param=args.param)
        if not args.json:
            trends = _shown(store, args.id, trends)
    of = f" {args.procedure}" if args.procedure else ""  # the procedure asked for, when one is
    if args.param is not None and not trends:
        raise InputError(None, None, f"no coefficient named {args.param!r} in this device's accepted{of} calibrations")
    if args.json:
        print_json(trends)
        return 0
    if not trends:
        sys.stdout.write(f"device {safe(args.id)}: no accepted{of} calibrations yet\n")
        return 0
    width = terminal_width()
    title = f"device {safe(args.id)}: drift per year over its accepted calibrations (weighted linear fit)"
    rows = [_cells(t) for t in trends]
    wide = aligned([_HEADER] + rows)
    out = [fit_line(title, "", width)]
    if width and max(map(len, wide)) > width:  # a terminal too narrow for the table: grouped, units in headings
        out += _grouped(rows, width)
    else:  # into a pipe (or wide enough): one line per coefficient with its procedure and unit
        out += wide + [_LEGEND + ":", "only those get a LEAVES_TOLERANCE date and can bring the due date forward"]
    sys.stdout.write("\n".join(out) + "\n")
    if not args.no_plot:
        plottable = [t for t in trends if t["n"] >= 2 and len(set(t["values"])) > 1]
        if args.param:
            chosen = plottable[:MAX_PLOTS]
        else:
            chosen = sorted(plottable, key=_significance, reverse=True)[:MAX_PLOTS]
        if chosen:
            note = (
                "" if args.param else f" (the {len(chosen)} steepest relative to their sigma; --param NAME for others)"
            )
            # the plot's own colour codes (a terminal only) pass; its titles were made safe above
            write = getattr(sys.stdout, "write_trusted", sys.stdout.write)
            write("\n" + fit_line(f"plot{note}:", "", width) + "\n" + _plot(chosen) + "\n")
    return 0
