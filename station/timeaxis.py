"""A time axis for terminal plots (plotext) that reads as dates, whatever the span.

Plot libraries given decimal years or POSIX seconds pick their own ticks; with all the
points on one day (or one point) the span is ~0 and the axis was widened to nonsense
(the drift plot ran from year 1013 to 3040). ``time_axis`` returns x as days since the
first time, a fixed x range that is never empty, and tick positions labelled as dates
(or times of day when the span is under two days). Dates are written with a four-digit year,
not strftime's ``%Y``: glibc writes year 1 as ``1``, and a calibration dated 0001-01-01 (a
logger's zero date) was labelled ``1-01-01``.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta


def _parse(text: str) -> datetime:
    t = str(text).strip()
    dt = datetime.fromisoformat(t[:-1] + "+00:00" if t[-1:] in "Zz" else t)
    return (dt if dt.tzinfo else dt.replace(tzinfo=UTC)).astimezone(UTC)


def time_axis(times: list[str], n_ticks: int = 4) -> dict:
    """x (days since the first time), xlim, ticks and their labels, and the axis label."""
    dts = [_parse(t) for t in times]
    t0 = min(dts)
    xs = [(d - t0).total_seconds() / 86400.0 for d in dts]
    span = max(xs) if xs else 0.0
    if span < 2.0:
        pad = max(span * 0.1, 1.0 / 24.0)  # at least an hour either side
        fmt, label = "%m-%d %H:%M", "date and time (UTC)"
    else:
        pad = span * 0.05
        fmt, label = "{:04d}-%m-%d", "date (UTC)"  # the year filled in below
    lo, hi = -pad, span + pad
    ticks = [span * k / (n_ticks - 1) for k in range(n_ticks)] if span > 0 and n_ticks > 1 else [0.0]
    days = [t0 + timedelta(days=t) for t in ticks]
    labels = [d.strftime(fmt).format(d.year) for d in days]
    return {"x": xs, "xlim": (lo, hi), "ticks": ticks, "labels": labels, "label": label, "t0": t0}
