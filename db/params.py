"""Calibration parameters as named scalars, JSON hygiene, tolerances and drift trends.

Scalar names follow the JSON path without the leading `$.` (the same names SQLite's
`json_tree` gives, so the `calibration_params` view agrees): `B[0]`, `M[1][2]`,
`drift[2]`, `beam1.dK`, `reference.total_nT`. Strings and booleans are not
parameters; `null` (a non-finite number when stored) has no value.

Pure Python on purpose (no numpy): `station due` and `station history` must start
fast.
"""

from __future__ import annotations

import json
import math
from datetime import UTC, date, datetime, timedelta

from solvers.jsonable import jsonable

DAYS_PER_YEAR = 365.25

# A drift trend moves a due date only when it is significant: at least
# DRIFT_MIN_CALIBRATIONS accepted calibrations (a degree of freedom left to check the
# scatter about the line against the reported sigmas), and |rate| at least
# DRIFT_SIGNIFICANCE times its sigma: a two-sided 0.27 % chance for a parameter that does
# not drift and whose sigmas are honest.
DRIFT_SIGNIFICANCE = 3.0
DRIFT_MIN_CALIBRATIONS = 3
# Without reported sigmas the rate's sigma comes from the scatter alone: Student's t with
# n - 2 degrees of freedom, the same two-sided 0.27 % (dof 1..30; beyond, dof 30's value,
# slightly stricter than the 3.0 it tends to).
_T_SIGNIFICANCE = (
    235.801, 19.207, 9.219, 6.62, 5.507, 4.904, 4.53, 4.277, 4.094, 3.957,
    3.85, 3.764, 3.694, 3.636, 3.586, 3.544, 3.507, 3.475, 3.447, 3.422,
    3.4, 3.38, 3.361, 3.345, 3.33, 3.316, 3.303, 3.291, 3.28, 3.27,
)  # fmt: skip


def clean_json(obj):
    """Plain JSON types (``solvers.jsonable``, strict): non-finite numbers become null.

    SQLite's JSON functions reject `NaN`, and SQLite itself stores a NaN REAL as NULL,
    so non-finite numbers are stored as null everywhere (documented in the README).
    """
    return jsonable(obj, strict=True)


def dumps(obj) -> str:
    """Canonical JSON text of already-clean data (stable key order, no NaN)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False)


def flatten(obj, prefix: str = "") -> dict[str, float | None]:
    """Scalar parameters by name, in document order; None where the value is null."""
    out: dict[str, float | None] = {}
    if isinstance(obj, dict):
        for key, value in obj.items():
            out.update(flatten(value, f"{prefix}.{key}" if prefix else str(key)))
    elif isinstance(obj, list):
        for i, value in enumerate(obj):
            out.update(flatten(value, f"{prefix}[{i}]"))
    elif obj is None:
        out[prefix] = None
    elif isinstance(obj, bool) or isinstance(obj, str):
        pass
    elif isinstance(obj, (int, float)):
        out[prefix] = float(obj)
    return out


def block_of(name: str) -> str:
    """`B[1]` -> `B`, `M[0][2]` -> `M`; names without an index are their own block."""
    i = name.find("[")
    return name[:i] if i > 0 else name


def matches(name: str, pattern: str) -> bool:
    """A parameter selector: the exact name, or a block name (`B` selects `B[0]`..`B[2]`)."""
    return name == pattern or (block_of(name) == pattern and name != pattern and "[" in name)


def tolerance_for(name: str, tolerances: dict) -> float | None:
    """The tolerance for one scalar: its exact name first, else its block's."""
    if name in tolerances:
        return float(tolerances[name])
    block = block_of(name)
    if block != name and block in tolerances:
        return float(tolerances[block])
    return None


# --- time -----------------------------------------------------------------------------


def parse_time(value) -> datetime:
    """ISO 8601 date or date-time (str or datetime) -> aware UTC datetime; naive = UTC."""
    if isinstance(value, datetime):
        dt = value
    else:
        text = str(value).strip()
        if not text:
            raise ValueError("empty date")
        try:
            dt = datetime.fromisoformat(text[:-1] + "+00:00" if text[-1] in "Zz" else text)
        except ValueError:
            raise ValueError(f"date {text!r} is not an ISO 8601 date or date-time") from None
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=UTC)
    return dt.astimezone(UTC)


def iso(dt: datetime) -> str:
    """The stored form: `YYYY-MM-DDTHH:MM:SSZ` (UTC, whole seconds, sorts as text)."""
    d = dt.astimezone(UTC)  # not strftime: its %Y gives '999' for the year 999 on glibc, no ISO date
    return f"{d.year:04d}-{d.month:02d}-{d.day:02d}T{d.hour:02d}:{d.minute:02d}:{d.second:02d}Z"


def normalize_time(value) -> str:
    return iso(parse_time(value))


def capture_time(meta, now=None) -> str | None:
    """When a capture was measured, stored form, or None without a ``date``: its ``date`` where
    that has a time of day. A date alone leaves the time of day open; it is ``recorded_at``
    where that falls on the date (``station record`` writes both), else the time of the save
    (``now``: a datetime or ISO text, default the clock) moved into that date: the save itself
    on the same UTC date, the date's last second (23:59:59) for an earlier date, its first
    second for a date still ahead (written east of UTC before midnight UTC). A capture
    calibrated on the day it was measured so counts as saved then, and one calibrated on a
    later day sorts after every calibration stored earlier for its date, as it would had it
    been saved that evening; read as midnight, a capture saved in the afternoon sorted before
    a calibration saved that morning and left that one in use. ValueError: ``date`` not ISO."""
    text = str(meta.get("date") or "").strip()
    if not text:
        return None
    try:
        day = date.fromisoformat(text)
    except ValueError:
        return normalize_time(text)  # a date-time (ValueError for what is neither)
    rec = str(meta.get("recorded_at") or "").strip()
    if rec[:10] == day.isoformat():
        try:
            return normalize_time(rec)
        except ValueError:
            pass  # the date stands
    start = datetime(day.year, day.month, day.day, tzinfo=UTC)
    save = parse_time(now) if now is not None else now_utc()
    return iso(min(max(save, start), start + DAY_LAST_SECOND))


DAY_LAST_SECOND = timedelta(seconds=86399)  # a date's 23:59:59, from its 00:00:00


def now_utc() -> datetime:
    return datetime.now(UTC)


def years_between(a: datetime, b: datetime) -> float:
    return (b - a).total_seconds() / 86400.0 / DAYS_PER_YEAR


# --- trend ----------------------------------------------------------------------------


def linear_trend(t_years: list[float], values: list[float], sigmas: list[float | None]) -> dict:
    """Weighted least-squares line `value = a + rate * t` (t in years).

    Weights 1/sigma^2 when every sigma is a positive number; otherwise unweighted, with
    the scatter about the line as the noise (needs 3 points for a rate sigma). When the
    weighted scatter exceeds the sigmas (chi^2/dof > 1) the covariance is scaled by
    chi^2/dof (Birge ratio), so an unmodelled wobble widens the rate's sigma instead
    of being ignored; it is never scaled down.

    Returns rate (per year), rate_sigma, intercept at t=0, value_at(t) needs both,
    chi2_per_dof (None without dof), weighted. rate is None with fewer than 2 distinct times.
    """
    n = len(values)
    out = {"n": n, "rate": None, "rate_sigma": None, "intercept": None, "chi2_per_dof": None, "t_mean": None}
    if n == 0:
        return out
    weighted = all(s is not None and s > 0 and math.isfinite(s) for s in sigmas)
    out["weighted"] = weighted
    w = [1.0 / (s * s) for s in sigmas] if weighted else [1.0] * n
    sw = sum(w)
    tm = sum(wi * ti for wi, ti in zip(w, t_years)) / sw
    ym = sum(wi * yi for wi, yi in zip(w, values)) / sw
    out["t_mean"] = tm
    sxx = sum(wi * (ti - tm) ** 2 for wi, ti in zip(w, t_years))
    if n < 2 or sxx <= 0.0 or not math.isfinite(sxx):
        out["intercept"] = ym
        return out
    sxy = sum(wi * (ti - tm) * (yi - ym) for wi, ti, yi in zip(w, t_years, values))
    rate = sxy / sxx
    intercept = ym - rate * tm
    chi2 = sum(wi * (yi - intercept - rate * ti) ** 2 for wi, ti, yi in zip(w, t_years, values))
    dof = n - 2
    var_rate = None
    if weighted:
        scale = max(1.0, chi2 / dof) if dof > 0 else 1.0
        var_rate = scale / sxx
    elif dof > 0:
        var_rate = (chi2 / dof) / sxx
    out.update(
        rate=rate,
        rate_sigma=None if var_rate is None else math.sqrt(var_rate),
        intercept=intercept,
        chi2_per_dof=(chi2 / dof) if dof > 0 else None,
    )
    return out


def trend_verdict(fit: dict) -> dict:
    """Whether a `linear_trend` fit shows a drift: the rate differs from zero beyond its
    uncertainty, with enough calibrations to say so.

    Significant when n >= DRIFT_MIN_CALIBRATIONS and |rate| / rate_sigma reaches the
    threshold: DRIFT_SIGNIFICANCE (3) with every sigma reported (rate_sigma already widened
    by the Birge ratio when the scatter exceeds them), Student's t for the same two-sided
    0.27 % when the sigma comes from the scatter alone. Returns significant, sigmas
    (|rate| / rate_sigma, None without a rate), threshold and why (a short phrase).
    """
    n = int(fit.get("n") or 0)
    rate, rate_sigma = fit.get("rate"), fit.get("rate_sigma")
    out = {"significant": False, "sigmas": None, "threshold": None}
    if rate is None:
        out["why"] = f"{n} calibration{'s' if n != 1 else ''} at fewer than two times"
        return out
    if rate_sigma is not None and rate_sigma > 0:
        out["sigmas"] = abs(rate) / rate_sigma
    elif rate_sigma is not None:  # points exactly on a line with no reported sigma
        out["sigmas"] = math.inf if rate else 0.0
    if n < DRIFT_MIN_CALIBRATIONS:
        out["why"] = f"{n} calibrations ({DRIFT_MIN_CALIBRATIONS} needed)"
        return out
    if fit.get("weighted", True):
        threshold = DRIFT_SIGNIFICANCE
    else:
        threshold = _T_SIGNIFICANCE[min(n - 2, len(_T_SIGNIFICANCE)) - 1]
    out["threshold"] = threshold
    s = out["sigmas"]
    if s is None:
        out["why"] = "no sigma for the rate"
        return out
    out["significant"] = s >= threshold
    out["why"] = f"{s:.1f}σ {'≥' if out['significant'] else '<'} {threshold:g}σ"
    return out
