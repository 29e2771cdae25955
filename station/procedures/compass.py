"""P3 compass calibration for the CLI and the TUI: a capture in, the calibrate.md dict out.

The numerics are in ``solvers/compass.py`` (see its docstring for the chain, filters,
Kalman noise, RLS linearisation). This module reads the capture's units and place, runs
the chain, turns solver refusals into ``UnsupportedError`` (exit 2, one line) and writes
the warnings an operator must see:

- no place (``latitude_deg``/``longitude_deg``) → no IGRF: W is scaled to the data's own
  mean field radius (not anchored to a reference);
- accelerometer sign: metadata ``accel_sign: gravity | specific_force``, else detected from
  the accelerometer–field angle against the expected inclination; a gravity-direction
  accelerometer is flipped, with a warning, never silently;
- misfit: residuals above the noise estimated from the data (second differences).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from solvers import compass as C
from solvers.errors import SolverError
from solvers.frames import G_STANDARD_MPS2
from solvers.geomag import igrf_date, igrf_reference
from solvers.units import si_factor
from station.capture import fill_missing, strictly_increasing_t
from station.errors import InputError, UnsupportedError
from station.procedures.contract import DiagnosisInput

MODEL = "m = W (m_raw - h), |m| = F (IGRF total field at the capture's place and date)"
DIAGNOSIS_BASELINE = True  # diagnosis_input starts from the calibrate result
# station.guard: columns read as measurements (present but empty in every row: refused), and
# the parameters this procedure exists to deliver (any of them non-finite: refused)
MEASURED = ("mx", "my", "mz", "ax", "ay", "az", "gx", "gy", "gz")
CORE_PARAMS = ("hard_iron", "soft_iron")
# station.procedures.review: each parameter block's unit ({mag_unit}: the result's, else raw)
PARAM_UNITS = {"hard_iron": "{mag_unit}", "soft_iron": "nT per {mag_unit}"}
PARAM_SHAPES = {  # every parameter the result can hold (calibrate.md)
    "hard_iron": (3,),
    "soft_iron": (3, 3),
    **{
        f"reference.{k}": ()
        for k in ("north_nT", "east_nT", "down_nT", "total_nT", "inclination_deg", "declination_deg")
    },
}


def _soft_iron_ratio(result: dict) -> float | None:
    """nT per mag_unit → mag_unit per mag_unit (a ratio, ~1 on the diagonal): divided by the
    nT in one mag_unit; None for a unit without a physical factor."""
    f = si_factor("mag", result.get("mag_unit"))
    return None if f is None else 1.0 / f


# what the screens show it in: W as a ratio, calibrated field per raw field in the capture's
# unit (the result, its exports and the database keep nT per mag_unit)
DISPLAY_UNITS = {"soft_iron": ("{mag_unit}/{mag_unit}", _soft_iron_ratio)}
LIMIT_EXAMPLE = "e.g. hard_iron[0]=-5:5  soft_iron[0][0]=0.9:1.1"  # the limits box's example, as shown
REF_KEYS = ("north_nT", "east_nT", "down_nT", "total_nT", "inclination_deg", "declination_deg")
METHODS = ("rls", "batch", "ellipsoid")
# what scales with the sample rate: a stated rate that t contradicts is refused (calibrate, inspect)
RATE_CONSEQUENCE = "the filters' cut-offs and the Kalman filter's step scale with the rate"


def _xyz(capture, prefix: str) -> np.ndarray | None:
    names = [prefix + a for a in "xyz"]
    if not all(n in capture.columns for n in names):
        return None
    return np.column_stack([np.asarray(capture.columns[n], float) for n in names])


def _accel_si(capture, a: np.ndarray) -> tuple[np.ndarray | None, str | None]:
    """The accelerometer columns ``a`` in m/s²: through the capture's front end (a raw unit's zero
    and scale: ``accel_offset``, ``accel_scale_mps2_per_unit``) or its unit's factor. Returns
    (a_mps2, the front end's source or None); a_mps2 is None where the unit has neither. Raises
    ``FrontendError`` on a bad front end. The one conversion calibrate and diagnose share."""
    from station.procedures.accel_frontend import Frontend

    frontend = Frontend.from_meta(capture.meta)
    if frontend is not None:
        return frontend(a), frontend.source
    factor = si_factor("accel", capture.meta.get("accel_unit"))
    return (a * factor if factor is not None else None), None


def _accel_as_calibrated(capture, base: dict) -> np.ndarray | None:
    """The accelerometer columns as calibrate reads them for tilt (``_tilt_and_heading``), in m/s²
    (raw where the unit has no factor and no front end: only directions are used), turned to
    specific force where calibrate found (or was told) that it reports gravity. None without
    accelerometer columns."""
    a = _xyz(capture, "a")
    if a is None:
        return None
    a_si, _ = _accel_si(capture, a)  # calibrate has refused a bad front end already
    a = a if a_si is None else a_si
    if (base.get("accel_sign") or {}).get("used") == "gravity":
        a = -a
    return a


def _reference(capture, warnings: list[str]) -> dict | None:
    lat, lon = capture.float_meta("latitude_deg"), capture.float_meta("longitude_deg")
    if lat is None or lon is None:
        warnings.append(
            "no place in the metadata (latitude_deg, longitude_deg): no IGRF reference; "
            "the field magnitude is normalised to the data's own mean radius, so the "
            "calibration is NOT IGRF-anchored (W's overall scale is relative)"
        )
        return None
    date = capture.meta.get("date")
    if not date:
        warnings.append(
            "metadata has latitude_deg/longitude_deg but no 'date' (the IGRF field needs the date of "
            "the recording): no IGRF reference; the field magnitude is normalised to the data's own "
            "mean radius, so the calibration is NOT IGRF-anchored (add '# date: YYYY-MM-DD')"
        )
        return None
    alt = capture.float_meta("altitude_m", 0.0)
    try:
        _, note = igrf_date(date)
        if note:
            warnings.append(note)
        return igrf_reference(lat, lon, alt, date)
    except ValueError as exc:
        raise InputError(capture.path, capture.meta_lines.get("date"), f"metadata 'date': {exc}") from None


@dataclass
class Prepared:
    """A P3 capture read once: the raw magnetometer rows, which are complete, the times."""

    y: np.ndarray  # raw magnetometer (n, 3), the capture's mag_unit
    good: np.ndarray  # rows with all three components (n,)
    t: np.ndarray | None  # times (n,) of a time series, else None
    warnings: list[str] = field(default_factory=list)


def prepare(capture) -> Prepared:
    """The magnetometer columns of ``capture`` (a one-line error when one is missing)."""
    y = _xyz(capture, "m")
    if y is None:
        capture.column("mx"), capture.column("my"), capture.column("mz")  # raises the one-line error
    t = np.asarray(capture.columns["t"], float) if capture.is_time_series else None
    return Prepared(y, np.all(np.isfinite(y), axis=1), t)


# The raw field of a compass in physical units is the Earth's within hard and soft iron: a
# factor beyond this from IGRF's total is a unit said wrongly (uT data declared nT reads 1000x low)
UNIT_MISTAKE_FACTOR = 3.0


def _unit_mistake(mag_unit, mag_factor, before: dict, ref) -> str | None:
    """A warning when the raw field's mean magnitude, in the unit the capture declares, is more
    than UNIT_MISTAKE_FACTOR from IGRF's total at its place and date; it names the unit that
    would read closest to IGRF."""
    from solvers.units import MAG_UNITS

    mean = before.get("mean") if isinstance(before, dict) else None
    if not mag_factor or ref is None or not isinstance(mean, (int, float)) or not mean > 0:
        return None
    ratio = mean / ref["total_nT"]
    if 1 / UNIT_MISTAKE_FACTOR <= ratio <= UNIT_MISTAKE_FACTOR:
        return None
    best = min(MAG_UNITS, key=lambda u: abs(math.log(ratio * MAG_UNITS[u] / mag_factor)))
    as_best = mean * MAG_UNITS[best] / mag_factor
    return (
        f"the raw field reads {mean:.4g} nT as mag_unit {mag_unit}, {ratio:.3g}x the {ref['total_nT']:.0f} nT "
        f"IGRF gives at this place and date: is mag_unit right? (as {best} it would read {as_best:.4g} nT)"
    )


def calibrate(capture, method: str | None = None, *, prepared: Prepared | None = None) -> dict:
    method = method or "rls"
    if method not in METHODS:
        raise InputError(None, None, f"compass: unknown method {method!r} (choose {', '.join(METHODS)})")
    prep = prepared if prepared is not None else prepare(capture)
    warnings = list(prep.warnings)
    y_all = prep.y
    mag_unit = capture.meta.get("mag_unit")
    mag_factor = si_factor("mag", mag_unit)
    if mag_factor is None:
        warnings.append(f"mag_unit {mag_unit!r} has no physical factor: the data radius is in raw units")
    ref = _reference(capture, warnings)
    good = prep.good
    if not good.all():
        warnings.append(f"{int((~good).sum())} of {len(good)} rows left out: a magnetometer value is missing")
    y = y_all[good]
    noise_raw = None
    t = prep.t
    if t is not None:
        noise_raw = C.noise_from_second_differences(y)
        if not math.isfinite(noise_raw) or noise_raw <= 0:
            noise_raw = None
    try:
        cal = C.calibrate_mag(
            y, None if ref is None else ref["total_nT"], unit_factor_nT=mag_factor, method=method, noise_raw=noise_raw
        )
    except SolverError as exc:
        raise UnsupportedError(f"{capture.path or 'capture'}: compass: {exc}") from None
    if cal.batch.misfit_scaled:
        warnings.append(
            f"residuals are {math.sqrt(cal.batch.reduced_chi2):.1f}x the sensor noise "
            "(estimated from second differences): the ellipsoid model does not explain "
            "everything (time misalignment, field disturbances, nonlinearity); "
            "uncertainties are scaled up accordingly"
        )
    if not math.isfinite(cal.rls_minus_batch_sigma):
        warnings.append(
            f"only {cal.n_distinct} distinct orientations: axis-aligned ellipsoid (diagonal W) "
            "without RLS; the off-diagonal soft iron is not estimated"
        )
    if cal.rls_minus_batch_sigma > 0.1:
        warnings.append(f"the RLS differs from the batch solution by {cal.rls_minus_batch_sigma:.2f} sigma")
    unit_hint = _unit_mistake(mag_unit, mag_factor, cal.magnitude_before, ref)
    if unit_hint:
        warnings.append(unit_hint)
    if ref is None:
        reference = {k: None for k in REF_KEYS}
    else:
        reference = {k: float(ref[k]) for k in REF_KEYS}
    result = {
        "procedure": "compass",
        "device": capture.meta.get("device"),
        "model": MODEL,
        "method": method,
        "params": {"hard_iron": cal.h.tolist(), "soft_iron": cal.W.tolist(), "reference": reference},
        "uncertainty": {
            "hard_iron": cal.h_sigma.tolist(),
            "soft_iron": cal.W_sigma.tolist(),
            "reference": {k: None for k in REF_KEYS},
        },
        "residual_rms": cal.residual_rms_nT,
        "n_positions": cal.n_distinct,
        "warnings": warnings,
        "igrf_anchored": ref is not None,
        "field_nT": cal.field_nT,
        "mag_unit": mag_unit,
        "coverage": cal.coverage,
        "n_samples": cal.n_samples,
        "noise_raw": cal.noise_raw,
        "field_magnitude_before_nT": cal.magnitude_before,
        "field_magnitude_after_nT": cal.magnitude_after,
        "rls_minus_batch_max_sigma": cal.rls_minus_batch_sigma,
        "ellipsoid": {"hard_iron": cal.h_ellipsoid.tolist(), "soft_iron": cal.W_ellipsoid.tolist()},
    }
    _tilt_and_heading(capture, t, good, cal, ref, result, warnings)
    return result


def _tilt_and_heading(capture, t, good, cal, ref, result, warnings) -> None:
    """Accelerometer sign, Kalman pitch/roll and tilt-compensated heading (per held
    orientation for a time series, per row for a table of averages)."""
    a = _xyz(capture, "a")
    if a is None:
        warnings.append("no accelerometer columns: no tilt, no heading")
        return
    from station.procedures.accel_frontend import OFFSET_KEY, SCALE_KEY, FrontendError

    try:
        a_si, frontend_source = _accel_si(capture, a)
    except FrontendError as exc:
        raise InputError(capture.path, capture.meta_lines.get(exc.key), f"metadata {exc}") from None
    if a_si is None:
        warnings.append(
            f"accel_unit {capture.meta.get('accel_unit')!r} has no physical factor: "
            f"no tilt, no heading (give '{OFFSET_KEY}' and '{SCALE_KEY}', e.g. from the unit's "
            "P1 calibration)"
        )
        return
    if frontend_source is not None:  # a raw accelerometer with its zero and scale (accel_frontend.py)
        result["accel_frontend"] = frontend_source
    f_g = a_si / G_STANDARD_MPS2
    w = _xyz(capture, "g")
    w_factor = si_factor("gyro", capture.meta.get("gyro_unit"))
    if w is None and all(c in capture.columns for c in ("gx", "gy")):
        w = np.column_stack([capture.columns["gx"], capture.columns["gy"], np.zeros(capture.n_rows)])
    rate = None
    y_all = _xyz(capture, "m")
    if t is not None:
        rate = capture.series_rate_hz(RATE_CONSEQUENCE)
    if rate:
        f_f = C.lowpass(np.nan_to_num(f_g), C.ACCEL_CUTOFF_HZ, rate)
        y_f = C.lowpass(np.where(np.isfinite(y_all), y_all, np.nanmean(y_all, axis=0)), C.MAG_CUTOFF_HZ, rate)
    else:
        f_f, y_f = f_g, y_all
    m_cal = C.calibrated(y_f, cal.W, cal.h)
    inc = None if ref is None else ref["inclination_deg"]
    verdict = C.detect_accel_sign(f_f[good], m_cal[good], inc)
    stated = (capture.meta.get("accel_sign") or "").strip().lower().replace("-", "_").replace(" ", "_") or None
    if stated not in (None, "gravity", "specific_force"):
        raise InputError(
            capture.path,
            capture.meta_lines.get("accel_sign"),
            f"metadata 'accel_sign': {stated!r} is not 'gravity' or 'specific_force'",
        )
    sign = stated or verdict.sign
    if stated and stated != verdict.sign:
        warnings.append(
            f"metadata says accel_sign: {stated}, but the data suggest {verdict.sign} "
            f"({verdict.reason}); following the metadata"
        )
    if sign == "gravity":
        src = "metadata accel_sign: gravity" if stated else "detected"
        warnings.append(
            f"accelerometer reports the gravity direction, not specific force ({src}: "
            f"{verdict.reason}); flipped its sign for tilt and heading"
        )
        f_f = -f_f
    result["accel_sign"] = {
        "used": sign,
        "stated": stated,
        "detected": verdict.sign,
        "accel_field_angle_deg": verdict.angle_deg,
        "expected_specific_force_deg": verdict.expected_deg,
    }
    decl = 0.0 if ref is None else ref["declination_deg"]
    if ref is None:
        placed = all(capture.meta.get(k) for k in ("latitude_deg", "longitude_deg"))
        without = "a date (IGRF needs it)" if placed else "a place"
        warnings.append(f"no declination without {without}: true heading = magnetic heading")
    if t is None or rate is None:
        pitch, roll = C.pitch_roll_from_accel(f_f)
        mh, th = C.heading_deg(m_cal, pitch, roll, decl)
        result["headings"] = [_heading_row(i, pitch[i], roll[i], mh[i], th[i]) for i in range(len(mh))]
        return
    if w is None or w_factor is None:
        warnings.append("no usable gyro (columns or gyro_unit): pitch and roll from the accelerometer alone")
        pitch, roll = C.pitch_roll_from_accel(f_f)
    else:
        w_f = C.lowpass(np.nan_to_num(w * w_factor), C.GYRO_CUTOFF_HZ, rate)
        pitch, roll = C.kalman_pitch_roll(t, f_f, w_f)
    mh, th = C.heading_deg(m_cal, pitch, roll, decl)
    result["headings"] = _held_headings(t, f_g, w, pitch, roll, mh, th, warnings)
    result["heading_frame"] = "body x forward, y right, z down; heading of body x from north"


def _heading_row(i, pitch, roll, mh, th, t0=None, t1=None) -> dict:
    row = {
        "index": int(i),
        "pitch_deg": math.degrees(pitch),
        "roll_deg": math.degrees(roll),
        "heading_magnetic_deg": float(mh),
        "heading_true_deg": float(th),
    }
    if t0 is not None:
        row.update({"t_start_s": float(t0), "t_stop_s": float(t1)})
    return row


def _held_headings(t, f_g, w, pitch, roll, mh, th, warnings) -> list[dict]:
    """Median tilt and circular-mean heading over each static interval (solvers.stillness)."""
    try:
        from solvers.stillness import detect_static_intervals

        still = detect_static_intervals(
            strictly_increasing_t(t), np.nan_to_num(f_g), None if w is None else np.nan_to_num(w), nan_policy="omit"
        )
    except (SolverError, ValueError) as exc:
        warnings.append(f"no held orientations found for per-position headings ({exc})")
        return []
    rows = []
    for k, iv in enumerate(still.intervals):
        s = slice(iv.start, iv.stop)
        rows.append(
            _heading_row(
                k,
                float(np.median(pitch[s])),
                _circ_rad(roll[s]),
                C.circular_mean_deg(mh[s]),
                C.circular_mean_deg(th[s]),
                iv.t_start_s,
                iv.t_stop_s,
            )
        )
    return rows


def _circ_rad(a) -> float:
    return math.atan2(float(np.mean(np.sin(a))), float(np.mean(np.cos(a))))


def format_text(result: dict) -> str:
    from station.calibrate import jsonable
    from station.formatting import device_text, param_lines

    lines = [
        f"procedure  compass ({result.get('method')})",
        f"device     {device_text(result)}",
        f"model      {result.get('model')}",
    ]
    from station.procedures.review import shown_unit, shown_value

    p, u = result["params"], result["uncertainty"]

    def shown(block, x):
        return [shown(block, v) for v in x] if isinstance(x, list) else shown_value(result, block, x)

    for block in ("hard_iron", "soft_iron"):  # in the units the screens show (soft iron: a ratio)
        value, sigma = (shown(block, jsonable(x)) for x in (p[block], u[block]))
        lines += param_lines(f"{block} [{shown_unit(result, block)}]", value, sigma)
    ref = p["reference"]
    if result.get("igrf_anchored"):
        lines.append(
            f"  IGRF: F {ref['total_nT']:.1f} nT, N {ref['north_nT']:.1f}, E {ref['east_nT']:.1f}, "
            f"D {ref['down_nT']:.1f} nT, inclination {ref['inclination_deg']:.2f}°, "
            f"declination {ref['declination_deg']:.2f}°"
        )
    else:
        lines.append(f"  no IGRF reference: field normalised to {result['field_nT']:.6g} nT (data radius)")
    b, a = result["field_magnitude_before_nT"], result["field_magnitude_after_nT"]
    lines.append(
        f"|m| before {b['mean']:.6g} ± {b['std']:.3g} nT ({b['std_percent']:.2f} %), "
        f"after {a['mean']:.6g} ± {a['std']:.3g} nT ({a['std_percent']:.3f} %)"
    )
    lines.append(
        f"residual   {result['residual_rms']:.4g} nT RMS{residual_in_mag_unit(result)}; coverage {100 * result['coverage']:.0f}% "
        f"of the sphere; {result['n_positions']} distinct orientations; "
        f"RLS − batch ≤ {result['rls_minus_batch_max_sigma']:.3f} σ"
    )
    for h in result.get("headings", [])[:40]:
        mh, th = h["heading_magnetic_deg"], h["heading_true_deg"]
        if mh is not None and math.isfinite(mh):
            heading = f"heading {mh:7.2f}° magnetic, {th:7.2f}° true"
        else:  # C.heading_deg leaves it undefined beyond its tilt limit (NaN; null in JSON)
            heading = f"heading undefined (|pitch| > {C.HEADING_MAX_TILT_DEG:g}°)"
        lines.append(f"  held {h['index']:>2}: pitch {h['pitch_deg']:7.2f}°  roll {h['roll_deg']:7.2f}°  {heading}")
    for w in result.get("warnings", []):
        lines.append(f"warning    {w}")
    return "\n".join(lines)


def diagnosis_input(capture, base: dict, prepared: Prepared | None = None) -> DiagnosisInput:
    """The P3 diagnosis problem around the baseline ``base`` (a calibrate result)."""
    from solvers.diagnose import problems as DP
    from station.procedures.diagnose import screen

    prep = prepared if prepared is not None else prepare(capture)
    y, good, t = prep.y, prep.good, prep.t
    if t is None:
        t = np.asarray(capture.columns["t"], float) if "t" in capture.columns else None
    bad, screened = screen(capture)  # gaps and saturated samples: left out of the effect search
    if len(bad) == len(good) and (good & ~bad).sum() >= 16:
        good = good & ~bad
    if t is None:
        return _table_diagnosis_input(capture, base, y, good)
    W0 = np.asarray(base["params"]["soft_iron"], float)
    h0 = np.asarray(base["params"]["hard_iron"], float)
    F = float(base["field_nT"])
    incl = base["params"]["reference"].get("inclination_deg")
    # the primary rows' noise is the white noise measured in the samples (calibrate's is scaled up
    # by the misfit an effect not yet modelled leaves, which weighted the dip rows 80 times too much)
    noise = C.noise_from_second_differences(y[good]) if good.sum() >= 12 else math.nan
    # a turn between samples reads as noise in the raw axes (a tumble read at 10 Hz: up to 18
    # times the white noise, which weighted the magnitude rows 300 times too little beside the
    # dip rows, and a fit of a candidate traded the one for the other); the magnitude does not turn
    noise = C.turn_free_noise(noise, y[good], W0, h0)
    if not (math.isfinite(noise) and noise > 0):
        noise = base.get("noise_raw") or 1.0
    temp = fill_missing(capture.columns["temp_c"], t) if "temp_c" in capture.columns else None
    static = {}
    a = _accel_as_calibrated(capture, base)
    gyro = _xyz(capture, "g")
    quant = None if a is None else _undithered(t[good], y[good], a[good], None if gyro is None else gyro[good])
    if quant is not None:
        # the MAD of second differences reads 0 there (a still stretch reads one count)
        static.update(still=quant["still"], shared_raw=quant["shared_raw"])
        noise = quant["noise_raw"]
    if a is not None:
        ok = good & np.all(np.isfinite(a), axis=1)
        try:
            idx = np.flatnonzero(ok)
            gain = _mean_gain(W0)

            def field(ok=ok):
                # the baseline's field (m̂ keeps still in a hold) and a floor under its noise
                s_m = noise * gain / F * math.sqrt(2.0 / 3.0)
                return C.calibrated(y[ok], W0, h0), (s_m if math.isfinite(s_m) else 0.0)

            blocks = _dip_holds(strictly_increasing_t(t[ok]), a[ok], None if gyro is None else gyro[ok], field)
            kind = "hold"
            if blocks is None:
                blocks, kind = _gravity_runs(t[ok], a[ok]), "run"
            if blocks is not None:
                sel, starts = blocks
                k = idx[sel]
                # the accelerometer's white noise where the dip is taken (the moves between holds
                # carry the hand's own acceleration: over the whole record it read 5 times too much)
                s_a = C.noise_from_second_differences(a[k])
                norm_a = np.linalg.norm(a[k], axis=1)
                g_ref = float(np.median(norm_a))
                var_a = s_a**2 if math.isfinite(s_a) else 0.0
                # the hand's own acceleration, smooth (second differences miss it): across gravity
                # it tilts f̂ at random and shrinks f̂·m̂ by its variance over 2g², a bias of the dip,
                # not noise (tumbled nulls of the s27 dynamic generator: the dip rows' mean off
                # IGRF by +1.5 to +1.9σ, 3.7σ on s700142, where 0.2–0.4 m/s² of it predicts that).
                # Measured along gravity (|f| about g: a run's slow hand moves included; a hold's
                # about its own mean, which an accelerometer's scale error moves from hold to
                # hold), taken as the same across it: a hand moves the unit every way.
                if kind == "run":
                    dev = norm_a - g_ref
                else:
                    cnt = np.diff(np.r_[starts, len(k)])
                    dev = norm_a - np.repeat(np.add.reduceat(norm_a, starts) / cnt, cnt)
                var_a = max(var_a, float(np.mean(dev**2)))
                rel_var = (noise * gain / F) ** 2 + var_a / g_ref**2
                static["dip_blocks"] = {
                    "f": a[k],
                    "y": y[k],
                    "t": t[k],
                    "temp": None if temp is None else temp[k],
                    "starts": starts,
                    "rel_var": rel_var if math.isfinite(rel_var) else 0.0,
                    "kind": kind,
                }
        except (SolverError, ValueError):
            static.pop("dip_blocks", None)
    prob = DP.compass_problem(
        t[good], y[good], W0, h0, F, incl, noise_raw=noise, temp_c=None if temp is None else temp[good], **static
    )
    prob.screened = screened
    return DiagnosisInput(
        prob,
        {},
        "a sample far off the field sphere: a magnetic disturbance nearby or a glitch",
        param_units=diagnosis_units(capture.meta.get("mag_unit")),
    )


def _table_noise_raw(capture, good) -> np.ndarray | None:
    """Per row, the noise of its mean field (raw units, RMS over the axes) from the table's
    ``m*_std`` and ``n`` columns (capture-format), or None where the table does not give them."""
    stds = [capture.columns.get(f"m{a}_std") for a in "xyz"]
    if any(s is None for s in stds):
        return None
    s = np.sqrt(np.mean(np.column_stack([np.asarray(x, float) for x in stds]) ** 2, axis=1))
    n = np.asarray(capture.columns["n"], float) if "n" in capture.columns else np.ones(len(s))
    out = (s / np.sqrt(np.maximum(n, 1.0)))[good]
    return out if np.all(np.isfinite(out)) and np.all(out > 0) else None


def _table_diagnosis_input(capture, base: dict, y, good) -> DiagnosisInput:
    """A table of averages (one row per position, no ``t``): one magnitude row and, with the
    accelerometer's columns, one dip row per position; the noise of a row from its ``m*_std`` and
    ``n`` columns, else calibrate's (the residual's). Nothing in time is sought."""
    from solvers.diagnose import problems as DP

    W0 = np.asarray(base["params"]["soft_iron"], float)
    h0 = np.asarray(base["params"]["hard_iron"], float)
    F = float(base["field_nT"])
    incl = base["params"]["reference"].get("inclination_deg")
    noise = _table_noise_raw(capture, good)
    if noise is None:
        noise = base.get("noise_raw") or 1.0
    temp = np.asarray(capture.columns["temp_c"], float) if "temp_c" in capture.columns else None
    rows = np.arange(len(y), dtype=float)
    static = {}
    a = _accel_as_calibrated(capture, base)
    if a is not None:
        k = np.flatnonzero(good & np.all(np.isfinite(a), axis=1))
        if len(k) >= 4:
            static["dip_blocks"] = {
                "f": a[k],
                "y": y[k],
                "t": rows[k],
                "temp": None if temp is None else temp[k],
                "starts": np.arange(len(k)),
                "rel_var": 0.0,  # a mean of many samples: its shrinkage is negligible
                "kind": "position",
            }
    prob = DP.compass_problem(
        rows[good],
        y[good],
        W0,
        h0,
        F,
        incl,
        noise_raw=noise,
        temp_c=None if temp is None else temp[good],
        table=True,
        **static,
    )
    return DiagnosisInput(
        prob,
        {},
        "a position far off the field sphere: a magnetic disturbance nearby or a moved unit",
        group_kind="block of positions",
        param_units=diagnosis_units(capture.meta.get("mag_unit")),
    )


def _undithered(t, y, a, gyro) -> dict | None:
    """A magnetometer read through a quantiser its noise does not dither (counts of 150 nT
    with 20 nT of noise, as an AK8963 gives), or None: the rounding error of a still unit is a
    constant per still stretch (``solvers.compass.quantised_noise``). ``{"still": the stretches
    (the accelerometer's and gyro's static intervals, indices into t), "shared_raw": its
    variance per axis, "noise_raw": a moving sample's white noise}``."""
    from solvers.stillness import detect_static_intervals

    q = C.quantum(y)
    if not np.any(q > 0):
        return None
    try:
        st = detect_static_intervals(strictly_increasing_t(t), a, gyro, nan_policy="omit")
    except (SolverError, ValueError):
        return None
    still = _grown([(iv.start, iv.stop) for iv in st.intervals], y)
    sigma, tau2 = C.quantised_noise(y, still, q)
    if not np.all(np.isfinite(sigma)):
        return None
    noise2 = float(np.mean(sigma**2 + q**2 / 12.0))
    # a stretch is one row where the error it shares outweighs the white noise of its mean,
    # n τ² > σ² + q²/12 − τ² (below that, rows with the white noise alone understate its
    # variance less than 2 times): at 60 nT of noise on counts of 150 nT (τ 1.3 nT) none is
    t2 = float(np.mean(tau2))
    still = [(i, j) for i, j in still if t2 > 0 and (j - i) * t2 > noise2 - t2]
    if not still:
        return None
    return {"still": still, "shared_raw": tau2, "noise_raw": math.sqrt(noise2)}


def _grown(stretches, y) -> list[tuple[int, int]]:
    """Each still stretch grown, either way, over the samples that read within its own range on
    every axis (the detector's windows leave out half a second at each end of a hold, whose
    samples carry the same rounding error); never into a neighbour."""
    out = []
    for k, (i, j) in enumerate(stretches):
        lo, hi = np.min(y[i:j], axis=0), np.max(y[i:j], axis=0)
        first = out[-1][1] if out else 0
        last = stretches[k + 1][0] if k + 1 < len(stretches) else len(y)
        while i > first and np.all((y[i - 1] >= lo) & (y[i - 1] <= hi)):
            i -= 1
        while j < last and np.all((y[j] >= lo) & (y[j] <= hi)):
            j += 1
        out.append((i, j))
    return out


# the detector's window (and shortest hold) for the dip's holds: calibrate's 1 s first; where it
# finds fewer than 4, half a second. A hand tumbling the unit pauses for a second or two between
# turns, and a 1 s window (with its margins) keeps a few of those pauses or none: the dip was then
# taken on runs that hold the turns too, whose hand acceleration tilts f̂ (dip rows 1.8 times their
# white noise), and a bent field at 10σ of the pauses went unnamed (s743003 of the s27 dynamic
# generator: 3 holds at 1 s, 13 at 0.5 s). The detector's noise is relative to the record's
# quietest windows, which on a unit that never stops are slow turns (a constant spin reads as its
# rest rate): a short window's hold is kept only where neither f̂ nor m̂ turns, their spread about
# the hold's mean within DIP_HOLD_TURN_TOL times what their white noise gives
DIP_HOLD_WINDOWS_S = (1.0, 0.5)
DIP_HOLD_TURN_TOL = 3.0


def _dip_holds(t, a, gyro, field=None):
    """(sample indices, start of each hold within them) of the static holds calibrate's detector
    finds, at least 5 samples each; None where there are fewer than 4. Where the 1 s window finds
    fewer, a shorter one (``DIP_HOLD_WINDOWS_S``), whose holds count only where the unit does not
    turn in them: ``field()`` gives (the field per sample in any frame that turns with the unit,
    the white noise of a component of m̂ as a floor under what its samples show), called only when
    the short window is tried (None: no such hold)."""
    from solvers.stillness import detect_static_intervals

    units = None
    for k, window_s in enumerate(DIP_HOLD_WINDOWS_S):
        st = detect_static_intervals(t, a, gyro, nan_policy="omit", window_s=window_s, min_duration_s=window_s)
        ivs = [iv for iv in st.intervals if iv.n >= 5]
        if k > 0:
            if field is None:
                return None
            if units is None:
                units = _unit_directions(a, *field())
            ivs = [iv for iv in ivs if not _turns(units, iv.start, iv.stop)]
        if len(ivs) >= 4:
            break
    else:
        return None
    sizes = [iv.stop - iv.start for iv in ivs]
    return np.concatenate([np.arange(iv.start, iv.stop) for iv in ivs]), np.r_[0, np.cumsum(sizes)[:-1]].astype(int)


def _unit_directions(a, m, s_m):
    """[(f̂, its white noise), (m̂, its white noise)]: unit vectors per sample, the noise per
    component from the record's second differences (``s_m`` a floor for m̂'s, 1e-6 for both)."""
    out = []
    for v, floor in ((a, 0.0), (m, s_m)):
        u = v / np.linalg.norm(v, axis=1, keepdims=True)
        s = C.noise_from_second_differences(u)
        out.append((u, max(s if math.isfinite(s) else 0.0, floor, 1e-6)))
    return out


def _turns(units, i, j) -> bool:
    """Whether f̂ or m̂ (``_unit_directions``) spreads over samples ``i:j`` by more than
    DIP_HOLD_TURN_TOL times its white noise: the spread of a unit vector about its mean,
    Σ|v̂ − v̄|²/n, is 2σ² across it, 3 s² of the axes-averaged s² the second differences give."""
    for u, s in units:
        w = u[i:j]
        spread = math.sqrt(float(np.mean(np.sum((w - w.mean(axis=0)) ** 2, axis=1))))
        if not spread <= DIP_HOLD_TURN_TOL * math.sqrt(3.0) * s:
            return True
    return False


# a device turned by hand with no holds: runs of this long where the accelerometer's magnitude is
# within 10 % of the record's median (or 5 times its noise), at most GRAVITY_RUNS_MAX runs (longer
# ones on a long record). The hand's acceleration along gravity does not move the dip (f̂ keeps its
# direction), across it only to first order, and it averages out within a run: a tight magnitude
# window cuts the record into pieces instead (2 %: a bent field under 0.3 m/s² of hand
# acceleration named 6 of 12, 10 %: 12 of 12; docs/benchmarks.md "Compass dip without holds")
GRAVITY_RUN_S = 1.0
GRAVITY_RUNS_MAX = 400
GRAVITY_TOL = 0.1


def _gravity_runs(t, a):
    """(selected sample indices, start of each run within them) or None: the dip rows of a
    record without holds (``compass_problem``'s ``dip_blocks``)."""
    n = len(t)
    if n < 20:
        return None
    norm = np.linalg.norm(a, axis=1)
    ref = float(np.median(norm))
    sd = C.noise_from_second_differences(norm[:, None])
    tol = max(GRAVITY_TOL * ref, 5.0 * (sd if math.isfinite(sd) else 0.0))
    ok = np.abs(norm - ref) < tol
    dt_s = float(np.median(np.diff(t)))
    if not (dt_s > 0 and ref > 0):
        return None
    length = max(5, int(round(GRAVITY_RUN_S / dt_s)), int(math.ceil(ok.sum() / GRAVITY_RUNS_MAX)))
    sel, starts = [], []
    # the accepted samples, cut where a quarter of a run or more is missing (a gap in time, or
    # the hand's jerk), into runs of `length`; a shorter tail is dropped. A sample left out here
    # and there (a spike) does not cut a run: the dip is taken sample by sample.
    acc = np.flatnonzero(ok)
    brk = np.flatnonzero(np.diff(t[acc]) > max(3 * dt_s, 0.25 * GRAVITY_RUN_S)) + 1
    for seg in np.split(acc, brk):
        for j in range(len(seg) // length):
            starts.append(len(sel))
            sel.extend(seg[j * length : (j + 1) * length])
    if len(starts) < 4:
        return None
    return np.array(sel, int), np.array(starts, int)


def diagnosis_units(mag_unit: str | None) -> dict:
    """The unit of each compass parameter diagnose names, with its factor to nT (the residuals'
    unit) where the capture's unit has one, and its unit then: the hard-iron terms are in the
    capture's mag_unit, as calibrate's hard_iron."""
    u = mag_unit or "raw units"
    f = si_factor("mag", mag_unit)
    return {
        "h": (u, f, "nT"),
        "dh": (u, f, "nT"),
        "bT": (f"{u} per °C", f, "nT per °C"),
        "bt": (f"{u}/s", f, "nT/s"),
        "W": (f"nT per {u}", None, ""),
        "t_on_s": ("s", None, ""),
        "rho": ("rad", None, ""),
        "field_scale": ("× the IGRF field", None, ""),
    }


def _mean_gain(W) -> float:
    """The soft iron's mean gain, |det W|^(1/3) (nT per raw unit); 0 for what is not a finite 3×3."""
    W = np.asarray(W, float)
    return abs(float(np.linalg.det(W))) ** (1 / 3) if W.shape == (3, 3) and np.all(np.isfinite(W)) else 0.0


def residual_in_mag_unit(result: dict) -> str:
    """calibrate's residual (nT) in the capture's mag_unit, the hard iron's unit: '' for nT."""
    unit = result.get("mag_unit")
    f = si_factor("mag", unit)
    res = result.get("residual_rms")
    if unit == "nT" or not isinstance(res, (int, float)) or not math.isfinite(res):
        return ""
    if f is not None:
        return f" = {res / f:.4g} {unit}"
    gain = _mean_gain(result["params"].get("soft_iron"))
    if not gain > 0:
        return ""
    return f" ≈ {res / gain:.4g} {unit or 'raw units'} (through the soft iron's mean gain {gain:.4g} nT per {unit or 'raw unit'})"


def report_figures(result: dict, meta: dict, columns: dict) -> list[tuple[str, str]]:
    """The calibration report's figures of P3 (``station.report``): (caption, svg) of the
    calibrated field directions on the unit sphere."""
    from station import svgplot

    figs: list[tuple[str, str]] = []
    if not all(c in columns for c in ("mx", "my", "mz")):
        return figs
    try:
        W = np.asarray(result["params"]["soft_iron"], dtype=float)
        h = np.asarray(result["params"]["hard_iron"], dtype=float)
        raw = np.column_stack([columns[c] for c in ("mx", "my", "mz")])
        m = C.calibrated(raw[np.isfinite(raw).all(axis=1)], W, h)
        d = m / np.linalg.norm(m, axis=1, keepdims=True)
        cov = result.get("coverage")
        cap = f" ({100 * cov:.0f} % of the sphere within 30° of a visited direction)" if isinstance(cov, float) else ""
        figs.append(
            (
                f"Coverage: calibrated field directions on the unit sphere{cap}",
                svgplot.sphere_plot(d.tolist(), title="compass coverage"),
            )
        )
    except (KeyError, TypeError, ValueError):
        pass
    return figs
