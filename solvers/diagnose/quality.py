"""Data-quality findings (diagnose.md ``quality``): gaps, saturation, a unit that moved during a
position, rows far beyond the noise. Each finding names where (a data line or a position)
and what would explain it. Pure numerics: the caller maps row indices to file lines."""

from __future__ import annotations

import numpy as np

OUTLIER_SIGMA = 5.0  # |studentized residual| beyond this is a finding
GAP_FACTOR = 5.0  # a time step this many times the median is a gap
SATURATION_RUN = 5  # this many equal consecutive samples at a column's extreme
MOVED_FRACTION = 0.1  # a labelled position with more than this fraction of moving samples


def gaps(t_s) -> list[dict]:
    """Steps in ``t`` larger than GAP_FACTOR × the median step: (row index after the gap, …)."""
    t = np.asarray(t_s, float)
    ok = np.isfinite(t)
    idx = np.flatnonzero(ok)
    if len(idx) < 3:
        return []
    d = np.diff(t[idx])
    med = float(np.median(d))
    out = []
    for k in np.flatnonzero(d > GAP_FACTOR * med):
        out.append(
            {
                "kind": "gap",
                "row": int(idx[k + 1]),
                "t_s": float(t[idx[k]]),
                "duration_s": float(d[k]),
                "explanation": f"{d[k]:.3g} s without samples (median step {med:.3g} s): samples lost "
                "(a dropped link or a full buffer)",
            }
        )
    return out


def saturation(columns: dict[str, np.ndarray]) -> list[dict]:
    """Runs of SATURATION_RUN or more identical values at a column's extreme reading."""
    out = []
    for name, x in columns.items():
        x = np.asarray(x, float)
        ok = np.isfinite(x)
        if ok.sum() < 10 or np.ptp(x[ok]) == 0:
            continue
        for extreme in (np.nanmax(x), np.nanmin(x)):
            at = ok & (x == extreme)
            if at.sum() < SATURATION_RUN:
                continue
            # longest run
            edges = np.diff(np.concatenate([[0], at.astype(int), [0]]))
            starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
            lengths = stops - starts
            k = int(np.argmax(lengths))
            if lengths[k] >= SATURATION_RUN:
                out.append(
                    {
                        "kind": "saturation",
                        "column": name,
                        "row": int(starts[k]),
                        "value": float(extreme),
                        "samples": int(at.sum()),
                        "explanation": f"{name} stuck at {extreme:g}, its extreme reading, for {int(lengths[k])} "
                        "consecutive samples: the sensor is at its range limit (clipping)",
                    }
                )
    return out


def moved_positions(still_mask, labels) -> list[dict]:
    """Labelled positions where the stillness detector saw motion in more than MOVED_FRACTION."""
    still = np.asarray(still_mask, bool)
    labels = np.asarray(labels, dtype=object)
    out = []
    k, n = 0, len(labels)
    while k < n:
        j = k + 1
        while j < n and labels[j] == labels[k]:
            j += 1
        if labels[k]:
            # ignore the first/last second-ish edges: the detector's window straddles the move
            m = j - k
            e = max(1, m // 20)
            inner = still[k + e : j - e] if m > 2 * e + 2 else still[k:j]
            frac = float(1.0 - inner.mean()) if inner.size else 0.0
            if frac > MOVED_FRACTION:
                out.append(
                    {
                        "kind": "moved",
                        "position": str(labels[k]),
                        "row": int(k),
                        "row_stop": int(j),
                        "moving_fraction": frac,
                        "explanation": f"the unit moved during position {labels[k]} ({100 * frac:.0f} % of its "
                        "samples are not still): the position's mean mixes two attitudes; "
                        "repeat it or cut the moving part",
                    }
                )
        k = j
    return out


def outliers(studentized, row_labels, explain: str) -> list[dict]:
    """Rows whose residual is beyond OUTLIER_SIGMA (after the extended model), worst first."""
    s = np.asarray(studentized, float)
    big = np.flatnonzero(np.abs(s) > OUTLIER_SIGMA)
    big = big[np.argsort(-np.abs(s[big]))][:20]
    return [
        {
            "kind": "outlier",
            "where": row_labels[k] if row_labels else f"row {k + 1}",
            "index": int(k),
            "sigma": float(s[k]),
            "explanation": explain,
        }
        for k in big
    ]
