"""Small inline SVG figures for the calibration report: no external assets, no scripts.

Each function returns one ``<svg>`` element as text, sized in CSS pixels, with its axes,
tick labels and units drawn in the SVG itself, so the page prints and archives as it is.

- ``xy_plot``: lines and/or points with optional 1-σ error bars; linear or log axes; a
  time axis (x in POSIX seconds, UTC) labelled with dates, and times of day when the
  span is short.
- ``bar_plot``: one bar per label about zero (residual per position).
- ``sphere_plot``: directions on the unit sphere, the upper and lower hemispheres as two
  discs seen from +z and from −z (orthographic), e.g. the compass's field coverage.
"""

from __future__ import annotations

import math
from datetime import UTC, datetime
from html import escape

PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf")
_FONT = 'font-family="sans-serif" font-size="11"'


def _nice_step(span: float, n: int = 5) -> float:
    raw = span / max(n, 1)
    mag = 10 ** math.floor(math.log10(raw))
    for m in (1, 2, 2.5, 5, 10):
        if m * mag >= raw:
            return m * mag
    return 10 * mag


def _ticks(lo: float, hi: float, n: int = 5) -> list[float]:
    if hi <= lo:
        return [lo]
    step = _nice_step(hi - lo, n)
    start = math.ceil(lo / step - 1e-9) * step
    out, k = [], 0
    while start + k * step <= hi + 1e-9 * step and k < 50:
        out.append(start + k * step)
        k += 1
    return out


def _fmt_tick(v: float, step: float) -> str:
    if v == 0:
        return "0"
    if abs(v) >= 1e5 or abs(v) < 1e-3:
        return f"{v:.2g}"
    decimals = max(0, -int(math.floor(math.log10(step))) if step > 0 else 0)
    return f"{v:.{min(decimals, 6)}f}"


def _time_ticks(lo: float, hi: float) -> tuple[list[float], str]:
    """Tick positions (POSIX s) and a strftime format for a time axis."""
    span = hi - lo
    day = 86400.0
    if span <= 0:
        return [lo], "%Y-%m-%d %H:%M"
    for step, fmt in (  # noqa: B007
        (60, "%H:%M"),
        (600, "%H:%M"),
        (3600, "%m-%d %H:%M"),
        (6 * 3600, "%m-%d %H:%M"),
        (day, "%Y-%m-%d"),
        (7 * day, "%Y-%m-%d"),
        (30 * day, "%Y-%m-%d"),
        (91 * day, "%Y-%m-%d"),
        (365.25 * day, "%Y-%m"),
        (5 * 365.25 * day, "%Y"),
    ):
        if span / step <= 6:
            break
    start = math.ceil(lo / step) * step
    ticks = [start + k * step for k in range(int((hi - start) / step) + 1)]
    return (ticks or [lo]), fmt


class _Axes:
    def __init__(self, width, height, xlim, ylim, log_x=False, log_y=False, left=64, right=12, top=12, bottom=40):
        self.w, self.h = width, height
        self.x0, self.x1 = left, width - right
        self.y0, self.y1 = height - bottom, top  # y0 is the bottom edge
        self.log_x, self.log_y = log_x, log_y
        self.xlim = tuple(math.log10(v) for v in xlim) if log_x else xlim
        self.ylim = tuple(math.log10(v) for v in ylim) if log_y else ylim

    def X(self, x):
        v = math.log10(x) if self.log_x else x
        a, b = self.xlim
        return self.x0 + (v - a) / (b - a or 1.0) * (self.x1 - self.x0)

    def Y(self, y):
        v = math.log10(y) if self.log_y else y
        a, b = self.ylim
        return self.y0 - (v - a) / (b - a or 1.0) * (self.y0 - self.y1)


def _axis_ticks(lim, axis_lim, log: bool) -> tuple[list[float], list[str]]:
    """Ticks along one axis and their labels: on a log axis the decades (``1eN``) within
    ``axis_lim`` (its limits as ``_Axes`` keeps them, log10), else round steps within ``lim``."""
    if log:
        ticks = [10.0**k for k in range(int(round(axis_lim[0])), int(round(axis_lim[1])) + 1)]
        return ticks, [f"1e{int(round(math.log10(v)))}" for v in ticks]
    ticks = _ticks(*lim)
    step = ticks[1] - ticks[0] if len(ticks) > 1 else 1.0
    return ticks, [_fmt_tick(v, step) for v in ticks]


def _figure_start(ax: _Axes, label: str) -> list[str]:
    """The opening ``<svg>`` of a figure of ``ax``'s size, named ``label``, and its plot area."""
    return [
        f'<svg xmlns="http://www.w3.org/2000/svg" class="figure" role="img" width="{ax.w}" height="{ax.h}" '
        f'viewBox="0 0 {ax.w} {ax.h}" aria-label="{escape(label)}">',
        f'<rect x="{ax.x0}" y="{ax.y1}" width="{ax.x1 - ax.x0}" height="{ax.y0 - ax.y1}" fill="#fff" stroke="#888"/>',
    ]


def _limits(values, log: bool, pad: float = 0.05):
    vals = [v for v in values if v is not None and math.isfinite(v) and (v > 0 or not log)]
    if not vals:
        return (1.0, 10.0) if log else (0.0, 1.0)
    lo, hi = min(vals), max(vals)
    if log:
        lo, hi = 10 ** math.floor(math.log10(lo)), 10 ** math.ceil(math.log10(hi))
        return (lo, hi if hi > lo else lo * 10)
    if hi == lo:
        d = abs(lo) * 0.1 or 1.0
        return lo - d, hi + d
    d = (hi - lo) * pad
    return lo - d, hi + d


def xy_plot(
    series: list[dict],
    *,
    x_label: str,
    y_label: str,
    title: str = "",
    log_x: bool = False,
    log_y: bool = False,
    time_x: bool = False,
    width: int = 640,
    height: int = 260,
    hline: float | None = None,
) -> str:
    """series: [{x: [...], y: [...], err: [...] or None, label, mode: line|points|both}]."""
    xs = [x for s in series for x in s["x"]]
    ys = []
    for s in series:
        errs = s.get("err") or [None] * len(s["y"])
        for y, e in zip(s["y"], errs):
            if y is None:
                continue
            ys.append(y)
            if e is not None and math.isfinite(e) and not log_y:
                ys += [y - e, y + e]
    if hline is not None:
        ys.append(hline)
    xlim = _limits(xs, log_x, pad=0.03)
    ylim = _limits(ys, log_y)
    ax = _Axes(width, height, xlim, ylim, log_x, log_y)
    out = _figure_start(ax, title or y_label)
    yt, ylab = _axis_ticks(ylim, ax.ylim, log_y)
    for v, lab in zip(yt, ylab):
        y = ax.Y(v)
        out.append(f'<line x1="{ax.x0}" x2="{ax.x1}" y1="{y:.1f}" y2="{y:.1f}" stroke="#e5e5e5"/>')
        out.append(f'<text x="{ax.x0 - 4}" y="{y + 4:.1f}" text-anchor="end" {_FONT}>{lab}</text>')
    # x ticks
    if time_x:
        xt, fmt = _time_ticks(*xlim)
        xlab = [datetime.fromtimestamp(v, UTC).strftime(fmt) for v in xt]
    else:
        xt, xlab = _axis_ticks(xlim, ax.xlim, log_x)
    for v, lab in zip(xt, xlab):
        x = ax.X(v)
        out.append(f'<line x1="{x:.1f}" x2="{x:.1f}" y1="{ax.y1}" y2="{ax.y0}" stroke="#e5e5e5"/>')
        out.append(f'<text x="{x:.1f}" y="{ax.y0 + 14}" text-anchor="middle" {_FONT}>{escape(lab)}</text>')
    if hline is not None:
        y = ax.Y(hline)
        out.append(f'<line x1="{ax.x0}" x2="{ax.x1}" y1="{y:.1f}" y2="{y:.1f}" stroke="#555" stroke-dasharray="4 3"/>')
    for i, s in enumerate(series):
        color = s.get("color") or PALETTE[i % len(PALETTE)]
        pts = [
            (ax.X(x), ax.Y(y))
            for x, y in zip(s["x"], s["y"])
            if y is not None and math.isfinite(y) and (y > 0 or not log_y) and (x > 0 or not log_x)
        ]
        mode = s.get("mode", "line")
        errs = s.get("err")
        if errs and not log_y:
            for x, y, e in zip(s["x"], s["y"], errs):
                if y is None or e is None or not math.isfinite(e):
                    continue
                X = ax.X(x)
                out.append(
                    f'<line x1="{X:.1f}" x2="{X:.1f}" y1="{ax.Y(y - e):.1f}" y2="{ax.Y(y + e):.1f}" stroke="{color}"/>'
                )
        if mode in ("line", "both") and len(pts) > 1:
            d = " ".join(f"{x:.1f},{y:.1f}" for x, y in pts)
            out.append(f'<polyline points="{d}" fill="none" stroke="{color}" stroke-width="1.5"/>')
        if mode in ("points", "both"):
            out += [f'<circle cx="{x:.1f}" cy="{y:.1f}" r="3" fill="{color}"/>' for x, y in pts]
        if s.get("label"):
            lx = ax.x0 + 8 + 120 * i
            out.append(
                f'<rect x="{lx}" y="{ax.y1 + 6}" width="10" height="3" fill="{color}"/>'
                f'<text x="{lx + 14}" y="{ax.y1 + 11}" {_FONT}>{escape(s["label"])}</text>'
            )
    out.append(
        f'<text x="{(ax.x0 + ax.x1) / 2:.0f}" y="{height - 6}" text-anchor="middle" {_FONT}>{escape(x_label)}</text>'
    )
    out.append(
        f'<text transform="translate(12 {(ax.y0 + ax.y1) / 2:.0f}) rotate(-90)" text-anchor="middle" '
        f"{_FONT}>{escape(y_label)}</text>"
    )
    out.append("</svg>")
    return "".join(out)


def bar_plot(
    labels: list[str],
    values: list[float],
    *,
    y_label: str,
    title: str = "",
    width: int = 640,
    height: int = 240,
    limit: float | None = None,
) -> str:
    """One bar per label about zero; ``limit`` draws ±limit as dashed lines."""
    vals = [v for v in values if v is not None and math.isfinite(v)]
    span = max([abs(v) for v in vals] + ([limit] if limit else []) + [1e-12])
    ax = _Axes(width, height, (0, max(len(labels), 1)), (-span * 1.1, span * 1.1), bottom=56)
    out = _figure_start(ax, title or y_label)
    yt, ylab = _axis_ticks((-span * 1.1, span * 1.1), ax.ylim, False)
    for v, lab in zip(yt, ylab):
        y = ax.Y(v)
        out.append(
            f'<line x1="{ax.x0}" x2="{ax.x1}" y1="{y:.1f}" y2="{y:.1f}" stroke="#e5e5e5"/>'
            f'<text x="{ax.x0 - 4}" y="{y + 4:.1f}" text-anchor="end" {_FONT}>{lab}</text>'
        )
    if limit:
        for v in (-limit, limit):
            out.append(
                f'<line x1="{ax.x0}" x2="{ax.x1}" y1="{ax.Y(v):.1f}" y2="{ax.Y(v):.1f}" stroke="#d62728" '
                'stroke-dasharray="4 3"/>'
            )
    bw = (ax.x1 - ax.x0) / max(len(labels), 1)
    zero = ax.Y(0.0)
    for i, (lab, v) in enumerate(zip(labels, values)):
        x = ax.x0 + i * bw
        if v is not None and math.isfinite(v):
            y = ax.Y(v)
            out.append(
                f'<rect x="{x + bw * 0.15:.1f}" y="{min(y, zero):.1f}" width="{bw * 0.7:.1f}" '
                f'height="{max(abs(zero - y), 0.5):.1f}" fill="{PALETTE[0]}"/>'
            )
        out.append(
            f'<text transform="translate({x + bw / 2:.1f} {ax.y0 + 8}) rotate(45)" {_FONT}>{escape(str(lab))}</text>'
        )
    out.append(f'<line x1="{ax.x0}" x2="{ax.x1}" y1="{zero:.1f}" y2="{zero:.1f}" stroke="#333"/>')
    out.append(
        f'<text transform="translate(12 {(ax.y0 + ax.y1) / 2:.0f}) rotate(-90)" text-anchor="middle" '
        f"{_FONT}>{escape(y_label)}</text>"
    )
    out.append("</svg>")
    return "".join(out)


def sphere_plot(directions, *, title: str = "", size: int = 220, max_points: int = 4000) -> str:
    """Unit vectors as points on two discs: z ≥ 0 seen from +z, z < 0 seen from −z."""
    pts = list(directions)
    if len(pts) > max_points:  # thin evenly: the picture, not every sample
        k = len(pts) / max_points
        pts = [pts[int(i * k)] for i in range(max_points)]
    r = size / 2 - 14
    width = 2 * size + 20
    height = size + 24
    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" class="figure" role="img" width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}" aria-label="{escape(title or "coverage")}">'
    ]
    for j, (name, sign) in enumerate(
        (("upper hemisphere (z ≥ 0), from +z", 1), ("lower hemisphere (z < 0), from −z", -1))
    ):
        cx, cy = size / 2 + j * (size + 20), size / 2 + 2
        out.append(f'<circle cx="{cx}" cy="{cy}" r="{r}" fill="#fff" stroke="#888"/>')
        for el in (30, 60):
            out.append(
                f'<circle cx="{cx}" cy="{cy}" r="{r * math.cos(math.radians(el)):.1f}" fill="none" stroke="#e5e5e5"/>'
            )
        out.append(
            f'<line x1="{cx - r}" x2="{cx + r}" y1="{cy}" y2="{cy}" stroke="#e5e5e5"/>'
            f'<line x1="{cx}" x2="{cx}" y1="{cy - r}" y2="{cy + r}" stroke="#e5e5e5"/>'
        )
        out.append(
            f'<text x="{cx + r + 2}" y="{cy + 4}" {_FONT}>+x</text>'
            f'<text x="{cx - 6}" y="{cy - r - 3}" {_FONT}>{"+y" if sign > 0 else "−y"}</text>'
        )
        dots = []
        for x, y, z in pts:
            if (z >= 0) == (sign > 0):
                dots.append(f'<circle cx="{cx + r * x:.1f}" cy="{cy - r * y * sign:.1f}" r="1.6"/>')
        out.append(f'<g fill="{PALETTE[0]}" fill-opacity="0.5">' + "".join(dots) + "</g>")
        out.append(f'<text x="{cx}" y="{height - 4}" text-anchor="middle" {_FONT}>{escape(name)}</text>')
    out.append("</svg>")
    return "".join(out)
