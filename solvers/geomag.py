"""The IGRF reference field through ppigrf, converted with care.

ppigrf returns geodetic east, north, **up** components [nT]; the station reports north,
east, **down** (NOAA's convention): ``down = −up``. Inclination is positive when the field
points down (northern hemisphere); declination positive east of true north.
"""

from __future__ import annotations

import datetime as _dt
import math
from functools import lru_cache

import numpy as np


def parse_date(text: str | _dt.date | _dt.datetime) -> _dt.datetime:
    """ISO date or date-time → datetime (naive UTC)."""
    if isinstance(text, _dt.datetime):
        return text.replace(tzinfo=None)
    if isinstance(text, _dt.date):
        return _dt.datetime(text.year, text.month, text.day)
    s = str(text).strip().replace("Z", "+00:00")
    try:
        d = _dt.datetime.fromisoformat(s)
    except ValueError:
        d = _dt.datetime.combine(_dt.date.fromisoformat(s[:10]), _dt.time())
    if d.tzinfo is not None:
        d = d.astimezone(_dt.UTC).replace(tzinfo=None)
    return d


# Dates outside the coefficient file's span are moved to its nearest end, up to this far
# out; farther is refused (ValueError). IGRF's secular variation changes the field by up to
# ~100 nT/year, so five years past the end can be ~0.5 µT (1 %) off.
MAX_EXTRAPOLATION_YEARS = 5.0


@lru_cache(maxsize=1)
def igrf_coverage() -> tuple[_dt.datetime, _dt.datetime]:
    """First and last epoch of the IGRF coefficients ppigrf ships (IGRF-14: 1900-01-01..2030-01-01)."""
    from ppigrf.ppigrf import read_shc

    g, _ = read_shc()
    return g.index[0].to_pydatetime(), g.index[-1].to_pydatetime()


def igrf_date(date) -> tuple[_dt.datetime, str | None]:
    """The epoch the IGRF is evaluated at for ``date``, and a note when that is not ``date``.

    Policy: inside the model's coverage, ``date`` itself; up to ``MAX_EXTRAPOLATION_YEARS``
    outside it, the nearest end of the coverage (note says so); farther, ValueError.
    """
    d = parse_date(date)
    first, last = igrf_coverage()
    if first <= d <= last:
        return d, None
    edge = first if d < first else last
    years = abs((d - edge).total_seconds()) / (365.25 * 86400.0)
    span = f"IGRF coverage {first.date()} to {last.date()}"
    if years > MAX_EXTRAPOLATION_YEARS:
        raise ValueError(
            f"{d.date()} is {years:.1f} years outside the {span}; dates up to "
            f"{MAX_EXTRAPOLATION_YEARS:g} years outside use the nearest epoch, farther are refused"
        )
    return edge, (
        f"date {d.date()} is outside the {span}: the field of {edge.date()} is used "
        f"({years:.1f} years away; the field changes by up to ~100 nT per year)"
    )


@lru_cache(maxsize=256)
def _igrf_cached(lat: float, lon: float, alt_m: float, date_iso: str) -> tuple[float, float, float]:
    import ppigrf  # imported lazily: loading its coefficient table takes a moment

    be, bn, bu = ppigrf.igrf(lon, lat, alt_m / 1000.0, _dt.datetime.fromisoformat(date_iso))
    return float(np.ravel(bn)[0]), float(np.ravel(be)[0]), float(-np.ravel(bu)[0])


def igrf_reference(latitude_deg: float, longitude_deg: float, altitude_m: float, date) -> dict:
    """Reference field at a place and date: north_nT, east_nT, down_nT, total_nT,
    horizontal_nT, inclination_deg, declination_deg. Dates outside the model's coverage:
    see :func:`igrf_date` (nearest epoch, or ValueError)."""
    d, _ = igrf_date(date)
    n, e, dn = _igrf_cached(float(latitude_deg), float(longitude_deg), float(altitude_m), d.isoformat())
    h = math.hypot(n, e)
    return {
        "north_nT": n,
        "east_nT": e,
        "down_nT": dn,
        "total_nT": math.sqrt(h * h + dn * dn),
        "horizontal_nT": h,
        "inclination_deg": math.degrees(math.atan2(dn, h)),
        "declination_deg": math.degrees(math.atan2(e, n)),
    }


def field_ned(reference: dict) -> np.ndarray:
    """The reference as a NED vector [nT]."""
    return np.array([reference["north_nT"], reference["east_nT"], reference["down_nT"]])
