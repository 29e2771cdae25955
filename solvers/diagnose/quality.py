"""Data-quality findings (diagnose.md ``quality``): gaps, saturation, a unit that moved during a
position, rows far beyond the noise. Each finding names where (a data line or a position)
and what would explain it. Pure numerics: the caller maps row indices to file lines."""

from __future__ import annotations

import numpy as np

OUTLIER_SIGMA = 5.0  # |studentized residual| beyond this is a finding
GAP_FACTOR = 5.0  # a time step this many times the median is a gap
SATURATION_RUN = 5  # this many equal consecutive samples at a column's extreme
STUCK_RUN = 20  # a run this long at the extreme is named whatever the signal does around it
ORDINARY_REPEAT = 0.02  # such runs in more than this fraction of the other samples: a quantised, quiet column
MOVED_FRACTION = 0.1  # a labelled position with more than this fraction of moving samples
GAP_MARGIN_S = 1.0  # samples this close to a gap are left out of the effect search (settling after it)


def gaps(t_s) -> list[dict]:
    """Steps in ``t`` larger than GAP_FACTOR × the median step (× the stamps' tick where most rows
    share their time stamp): (row index after the gap, …)."""
    t = np.asarray(t_s, float)
    ok = np.isfinite(t)
    idx = np.flatnonzero(ok)
    if len(idx) < 3:
        return []
    d = np.diff(t[idx])
    med = float(np.median(d))
    if med <= 0:  # coarse time stamps (whole seconds): most rows share their t; the stamp's tick is the step
        med = float(np.median(d[d > 0])) if np.any(d > 0) else 0.0
        if med <= 0:
            return []
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


def _runs(at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    edges = np.diff(np.concatenate([[0], at.astype(int), [0]]))
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)


def _ordinary_repeats(x: np.ndarray, ok: np.ndarray) -> bool:
    """True when runs of SATURATION_RUN equal values are ordinary away from the extremes (more
    than ORDINARY_REPEAT of those samples): a quiet sensor read through a coarse quantiser (ADC
    counts, a magnetometer's LSB above its noise) holds one value for many samples at any
    attitude (a quiet gyro may read one or two values all along), so such a run at the extreme
    is no sign of clipping."""
    inner = ok & (x != np.nanmax(x)) & (x != np.nanmin(x))
    if inner.sum() < max(10, 0.05 * ok.sum()):
        return True  # nearly every sample at one of two readings: a quantiser's, not a signal clipped at both ends
    xi = x[inner]
    new_run = np.r_[True, xi[1:] != xi[:-1]]
    lengths = np.diff(np.r_[np.flatnonzero(new_run), len(xi)])
    return float(lengths[lengths >= SATURATION_RUN].sum()) > ORDINARY_REPEAT * len(xi)


def _adc_limit(value: float, lo: float, hi: float) -> bool:
    """An integer reading at a two's-complement or unsigned ADC limit (±2^k or 2^k − 1, k ≥ 7)
    whose range holds the column's other readings (``lo`` … ``hi``): a 16-bit magnetometer that
    reads −256 in one hold and +400 in another is not clipped at −256."""
    v = abs(value)
    if v != round(v) or v < 127:
        return False
    for k in range(7, 33):
        if v not in (2**k, 2**k - 1):
            continue
        signed = -(2**k) <= lo and hi <= 2**k  # ±2^k, give or take the one count of the sign
        unsigned = value > 0 and lo >= 0 and hi <= 2**k
        if signed or unsigned:
            return True
    return False


def _siblings_still(columns: dict, name: str, a: int, b: int) -> bool:
    """Whether the other axes of ``name``'s sensor (``mx`` → ``my``, ``mz``), where the columns
    have them, each hold a single value over rows ``a:b``; False without such axes."""
    if len(name) != 2 or name[1] not in "xyz":
        return False
    others = [columns[name[0] + c] for c in "xyz" if c != name[1] and name[0] + c in columns]
    if not others:
        return False
    return all(np.ptp(np.asarray(o, float)[a:b]) == 0 for o in others)


def _smooth_turn(x: np.ndarray, a: int, b: int, at_max: bool) -> bool:
    """Whether a short run ``x[a:b]`` at the column's extreme is the signal turning there, read
    through a quantiser: a parabola through the samples on both sides (three each) stays within
    two steps of the reading over the run. A clipped signal, continued from both sides, goes
    beyond it; a run of STUCK_RUN or more is a stuck reading whatever its sides."""
    if b - a >= STUCK_RUN or a < 3 or b + 3 > len(x):
        return False
    idx = np.r_[a - 3 : a, b : b + 3]
    y = x[idx]
    if not np.all(np.isfinite(y)):
        return False
    v = np.unique(x[np.isfinite(x)])
    steps = np.diff(v)
    q = float(np.min(steps[steps > 0])) if (steps > 0).any() else 0.0
    c = np.polyfit(idx - a, y, 2)
    peak = np.polyval(c, np.arange(-1, b - a + 1))
    beyond = (peak.max() - x[a]) if at_max else (x[a] - peak.min())
    return bool(beyond <= 2.0 * q)


def saturation(columns: dict[str, np.ndarray]) -> list[dict]:
    """Runs of SATURATION_RUN or more identical values at a column's extreme reading: one
    finding per column and extreme (its longest run), with every such run in ``runs``
    (row start, stop) for the screen. In a column where such runs are ordinary anywhere
    (``_ordinary_repeats``: quantised and quiet) only an extreme at an ADC limit counts."""
    out = []
    for name, x in columns.items():
        x = np.asarray(x, float)
        ok = np.isfinite(x)
        if ok.sum() < 10 or np.ptp(x[ok]) == 0:
            continue
        ordinary = _ordinary_repeats(x, ok)
        for extreme in (np.nanmax(x), np.nanmin(x)):
            if ordinary and not _adc_limit(float(extreme), float(np.nanmin(x)), float(np.nanmax(x))):
                continue
            at = ok & (x == extreme)
            if at.sum() < SATURATION_RUN:
                continue
            starts, stops = _runs(at)
            # a run in which the sensor's other axes hold one value each too is the whole unit
            # still, read through a quantiser coarser than its noise (a hand pausing where this
            # axis peaks): nothing tells a clip there, and one axis pinned at its limit while the
            # others still move is what clipping looks like
            moving = [
                j
                for j, (a, b) in enumerate(zip(starts, stops))
                if not _siblings_still(columns, name, a, b) and not _smooth_turn(x, a, b, extreme == np.nanmax(x))
            ]
            starts, stops = starts[moving], stops[moving]
            if not len(starts):
                continue
            # longest run
            lengths = stops - starts
            k = int(np.argmax(lengths))
            if lengths[k] >= SATURATION_RUN:
                long = lengths >= SATURATION_RUN
                out.append(
                    {
                        "kind": "saturation",
                        "column": name,
                        "row": int(starts[k]),
                        "value": float(extreme),
                        "samples": int(at.sum()),
                        "runs": [(int(a), int(b)) for a, b in zip(starts[long], stops[long])],
                        "explanation": f"{name} stuck at {extreme:g}, its extreme reading, for {int(lengths[k])} "
                        "consecutive samples: the sensor is at its range limit (clipping)",
                    }
                )
    return out


def moved_positions(still_mask, labels, t_s=None, window_n: int = 0) -> list[dict]:
    """Labelled positions where the stillness detector saw motion in more than MOVED_FRACTION.
    ``t_s`` and the detector's window ``window_n`` (samples): the samples within a window of a
    gap in ``t`` do not count. A bench that records only the holds leaves a gap where the unit
    turned; the detector's windows that straddle it see two attitudes, which is no motion
    within the hold (5 s holds read 11 % moving on clean data). The same holds where one label
    follows another with no row between (a simulator or logger that writes only the holds, at
    an even rate): 3 s holds read 26 % moving on still, white-noise data and every position was
    named `moved`."""
    still = np.asarray(still_mask, bool)
    labels = np.asarray(labels, dtype=object)
    counted = np.ones(len(still), bool)
    if t_s is not None and window_n > 0:
        for q in gaps(t_s):
            counted[max(q["row"] - window_n, 0) : q["row"] + window_n] = False
    if window_n > 0 and len(labels) > 1:
        for k in np.flatnonzero((labels[1:] != labels[:-1]) & (labels[1:] != "") & (labels[:-1] != "")) + 1:
            counted[max(k - window_n, 0) : k + window_n] = False
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
            sel = slice(k + e, j - e) if m > 2 * e + 2 else slice(k, j)
            inner = still[sel][counted[sel]]
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


def group_outliers(studentized, groups, flagged, primary=None, threshold: float = OUTLIER_SIGMA) -> list:
    """Of the groups ``flagged``, those whose rows still lie far from the rest: a group's mean
    studentized residual times √(its rows) beyond ``threshold`` × the other groups' robust spread
    (1.4826 × the median of their |z|, at least 1), the calibration's own outlier rule on hold means
    (solvers.tabletop.find_outliers). ``primary``: the rows that count (others ignored)."""
    z = np.asarray(studentized, float)
    g = np.asarray(groups)
    use = np.ones(len(z), bool) if primary is None else np.asarray(primary, bool)
    zg = {}
    for k in np.unique(g[use]):
        r = z[use & (g == k)]
        zg[k] = float(r.sum() / np.sqrt(len(r)))
    others = [abs(v) for k, v in zg.items() if k not in set(flagged)]
    scale = max(1.0, 1.4826 * float(np.median(others))) if others else 1.0
    return [k for k in flagged if k not in zg or abs(zg[k]) > threshold * scale]


def screen(n: int, t_s=None, columns: dict | None = None, moved=()) -> tuple[np.ndarray, list[dict]]:
    """The data-quality screen run before any effect is sought (one for every procedure):
    ``(bad, findings)`` with ``bad`` (n,) the rows to leave out of the effect search and a
    finding per cause (rows as row indices, ``"screened": True``, ``screened_rows`` how many):

    - a gap (``gaps``): the samples within GAP_MARGIN_S (or one median step) of it on either
      side — whatever the link lost, the unit may have been touched or be settling;
    - saturation (``saturation`` of ``columns``): every run at the extreme reading and
      SATURATION_RUN samples either side (the true value is unknown there);
    - a moved position (``moved``, from ``moved_positions``): all of its rows (its mean mixes
      two attitudes)."""
    bad = np.zeros(int(n), bool)
    findings: list[dict] = []
    if t_s is not None:
        t = np.asarray(t_s, float)
        for q in gaps(t):
            k = q["row"]
            ok = np.isfinite(t)
            step = float(np.median(np.diff(t[ok]))) if ok.sum() > 2 else 0.0
            margin = max(GAP_MARGIN_S, step)
            before, after = float(t[k] - q["duration_s"]), float(t[k])
            m = ok & (t >= before - margin) & (t <= after + margin)
            q["screened_rows"] = int((m & ~bad).sum())
            q["screened"] = True
            q["explanation"] += f"; the samples within {margin:g} s of it are left out of the effect search"
            bad |= m
            findings.append(q)
    for q in saturation(columns or {}):
        m = np.zeros(int(n), bool)
        for a, b in q.pop("runs"):
            m[max(0, a - SATURATION_RUN) : min(int(n), b + SATURATION_RUN)] = True
        q["screened_rows"] = int((m & ~bad).sum())
        q["screened"] = True
        q["explanation"] += "; those samples (and their neighbours) are left out of the effect search"
        bad |= m
        findings.append(q)
    for q in moved:
        q = dict(q)
        m = np.zeros(int(n), bool)
        m[q["row"] : q["row_stop"]] = True
        q["screened_rows"] = int((m & ~bad).sum())
        q["screened"] = True
        q["explanation"] += "; the position is left out of the effect search"
        bad |= m
        findings.append(q)
    return bad, findings
