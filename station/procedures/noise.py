"""The gyro noise (Allan) run, UI-free: a still recording (``gyrodrift_guide.HoldGuide``) in,
a noise report out.

Numerics are ``solvers.allan``: the overlapping Allan deviation per axis, the noise
model ``AVAR(τ) = c0/τ + c1 + c2 τ`` (:func:`solvers.allan.fit_noise_model`) and the
record length a P4 run needs for a 1-sigma bias accuracy
(:func:`solvers.allan.time_needed_s`, the figure P4's own accuracy statement uses).

Reported per axis (IEEE Std 952 readings, rates converted to °/h):

- angle random walk ``N = sqrt(c0)`` [rad/√s] → ``N · 180/π · 60`` [°/√h] (white rate
  noise: ADEV(τ) = N/√τ; √h = 60 √s);
- bias instability ``B = min_τ ADEV(τ) / 0.664`` [°/h] (the flat part of the curve) and
  the τ where the minimum lies;
- time needed for ``accuracy_deg_h`` (1-sigma of the mean over a still record): the
  longer of the white extrapolation of the achieved error and the model's ``T`` with
  ``c0/T + c1 + c2 T <= accuracy²``; ``inf`` when the floor never gets there.

The Earth's rotation is a constant on a still unit: the Allan deviation does not see it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from solvers import allan
from solvers.units import si_factor
from station.capture import strictly_increasing_t

DEG_H_RAD_S = math.radians(1.0) / 3600.0  # 1 °/h in rad/s
BIAS_INSTABILITY_FACTOR = 0.664  # ADEV floor = sqrt(2 ln 2 / π) · B (IEEE 952, flicker rate noise)
AXES = ("x", "y", "z")
RATE_CONSEQUENCE = "the Allan figures scale with the rate"  # why a stated rate that t contradicts is refused


@dataclass
class NoiseReport:
    """Allan analysis of a still gyro record. Rates in °/h unless named otherwise."""

    duration_s: float
    sample_rate_hz: float
    taus_s: np.ndarray  # (m,)
    adev_deg_h: np.ndarray  # (m, 3)
    arw_deg_rt_h: np.ndarray  # (3,) angle random walk [°/√h]
    bias_instability_deg_h: np.ndarray  # (3,)
    bias_instability_tau_s: np.ndarray  # (3,) τ of the ADEV minimum
    mean_deg_h: np.ndarray  # (3,) mean rate (includes the Earth's rate)
    sigma_mean_deg_h: np.ndarray  # (3,) 1-sigma of the mean (solvers.allan.mean_standard_error)
    noise_model: np.ndarray  # (3, 3) c0 [rad²/s], c1 [rad²/s²], c2 [rad²/s³] per axis
    mean_error: allan.MeanError

    def time_needed_s(self, accuracy_deg_h: float) -> np.ndarray:
        """Record length per axis for a 1-sigma of ``accuracy_deg_h`` on the mean rate."""
        if not (isinstance(accuracy_deg_h, (int, float)) and math.isfinite(accuracy_deg_h) and accuracy_deg_h > 0):
            raise ValueError(f"accuracy must be a positive number of °/h, got {accuracy_deg_h!r}")
        return allan.time_needed_s(self.mean_error, accuracy_deg_h * DEG_H_RAD_S)

    def to_json(self, accuracy_deg_h: float | None = None) -> dict:
        out = {
            "kind": "gyro-noise",
            "duration_s": self.duration_s,
            "sample_rate_hz": self.sample_rate_hz,
            "tau_s": self.taus_s.tolist(),
            "adev_deg_h": self.adev_deg_h.T.tolist(),
            "arw_deg_rt_h": self.arw_deg_rt_h.tolist(),
            "bias_instability_deg_h": self.bias_instability_deg_h.tolist(),
            "bias_instability_tau_s": self.bias_instability_tau_s.tolist(),
            "mean_deg_h": self.mean_deg_h.tolist(),
            "sigma_mean_deg_h": self.sigma_mean_deg_h.tolist(),
            "noise_model_c0_c1_c2": self.noise_model.tolist(),
        }
        if accuracy_deg_h is not None:
            need = self.time_needed_s(accuracy_deg_h)
            out["accuracy_deg_h"] = accuracy_deg_h
            out["time_needed_s"] = [float(x) if math.isfinite(x) else None for x in need]
        return out


def noise_report(gyro, sample_rate_hz: float, gyro_unit: str | None) -> NoiseReport:
    """The Allan analysis of a still record ``gyro`` (N, 3) in ``gyro_unit``.

    Raises ValueError for a unit without a physical factor (counts: the rates could not
    be given in °/h) or fewer than 30 rows (too short for three τ)."""
    k = si_factor("gyro", gyro_unit)
    if k is None:
        raise ValueError(
            f"gyro_unit {gyro_unit or 'unknown'!r} has no physical factor: the Allan run needs rad/s or deg/s"
        )
    y = np.asarray(gyro, dtype=float).reshape(-1, 3)
    y = y[np.all(np.isfinite(y), axis=1)] * k
    if len(y) < 30:
        raise ValueError(f"only {len(y)} samples: the Allan run needs a longer still record")
    dt = 1.0 / float(sample_rate_hz)
    me = allan.mean_standard_error(y, dt)
    # the drawn curve: 4 τ per octave up to T/3; the model and the time needed are P4's own
    # (mean_standard_error: 2 per octave, the same fit)
    taus, adev, _ = allan.oadev(y, dt, allan.octave_taus(len(y), dt, 1.0 / 3.0, per_octave=4))
    model = me.noise_model if me.noise_model is not None else np.zeros((3, 3))
    imin = np.argmin(adev, axis=0)
    arw = np.sqrt(model[:, 0]) * math.degrees(1.0) * 60.0
    return NoiseReport(
        duration_s=me.duration_s,
        sample_rate_hz=float(sample_rate_hz),
        taus_s=taus,
        adev_deg_h=adev / DEG_H_RAD_S,
        arw_deg_rt_h=arw,
        bias_instability_deg_h=adev[imin, np.arange(3)] / BIAS_INSTABILITY_FACTOR / DEG_H_RAD_S,
        bias_instability_tau_s=taus[imin],
        mean_deg_h=me.mean / DEG_H_RAD_S,
        sigma_mean_deg_h=np.asarray(me.se) / DEG_H_RAD_S,
        noise_model=model,
        mean_error=me,
    )


# The longest still record a P4 run is worth: beyond a day the fitted noise model is
# extrapolated far past any record it was fitted on, and the floor is within a hair of
# the accuracy asked. Longer needs are "never" (README: "never" when the floor is above).
PRACTICAL_RECORD_S = 24 * 3600.0


def format_duration(seconds: float) -> str:
    """'45 s', '12 min', '3.2 h', 'never' (inf, or beyond ``PRACTICAL_RECORD_S``)."""
    if not math.isfinite(seconds) or seconds > PRACTICAL_RECORD_S:
        return "never"
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def p4_record_verdict(need_s, accuracy_deg_h: float) -> str:
    """One line on how long a still P4 record must be for a 1σ of ``accuracy_deg_h`` on every
    axis, from `NoiseReport.time_needed_s` (``need_s``, per axis of `AXES`). When some axis
    never gets there, it names those axes and says what the others need: "no record" alone
    read as contradicting the table beside it, where another axis needed 2.6 h."""
    need = [float(t) for t in need_s]
    bad = [ax for ax, t in zip(AXES, need) if not (math.isfinite(t) and t <= PRACTICAL_RECORD_S)]
    if not bad:
        return f"For 1σ ≤ {accuracy_deg_h:g} °/h a still P4 record needs {format_duration(max(need))}."
    hair = any(math.isfinite(t) for ax, t in zip(AXES, need) if ax in bad)
    others = [f"{ax} alone needs {format_duration(t)}" for ax, t in zip(AXES, need) if ax not in bad]
    return (
        f"No still P4 record reaches 1σ ≤ {accuracy_deg_h:g} °/h on every axis: the fitted noise floor of "
        f"{' and '.join(bad)} (bias instability, rate random walk) is above it"
        + (" or within a hair of it (> 24 h)" if hair else "")
        + (f"; {', '.join(others)}." if others else ".")
    )


# --- station noise: gyro and accelerometer, Kalibr's imu.yaml --------------------------------

SENSORS = {"gyro": (("gx", "gy", "gz"), "gyro_unit"), "accel": (("ax", "ay", "az"), "accel_unit")}
SI_UNIT = {"gyro": "rad/s", "accel": "m/s^2"}


def _factor(capture, kind: str, unit_key: str) -> tuple[float | None, str]:
    """SI factor of a sensor's columns and how it was found: the unit, or for gyro counts the
    nominal ``gyro_counts_per_rad_s`` / ``gyro_counts_per_deg_s`` the procedures also read."""
    unit = capture.meta.get(unit_key)
    k = si_factor(kind, unit)
    if k is None and kind == "gyro" and unit == "counts":
        per_rad = capture.float_meta_within("gyro_counts_per_rad_s", None, 1e12)
        per_deg = capture.float_meta_within("gyro_counts_per_deg_s", None, 1e10)
        if per_rad and per_rad > 0:
            return 1.0 / per_rad, f"gyro in counts: nominal {per_rad:g} counts per rad/s"
        if per_deg and per_deg > 0:
            return math.radians(1.0) / per_deg, f"gyro in counts: nominal {per_deg:g} counts per °/s"
    if k is None:
        why = f"{unit_key} {unit or 'unknown'!r} has no physical factor"
        if kind == "gyro" and unit == "counts":
            why += " (give gyro_counts_per_deg_s in the metadata)"
        return None, why
    return k, ""


def imu_noise(capture) -> dict:
    """Allan analysis of each sensor of a still time-series capture (solvers.allan.noise_fit).

    Returns {"sample_rate_hz", "duration_s", "sensors": {"gyro"|"accel": NoiseFit in SI}}. A
    record that moves (over MOVING_SHARE_WARN of its samples, by the stillness detector) has no
    sensor's noise to give: "sensors" is empty, "withheld" says why and "warnings" holds the
    warning (its Allan figures are not the sensor's noise: a turn gave 1e-151 ± 9e+144). Raises
    UnsupportedError (one line, naming the file) when the capture has no usable sensor: not a
    time series, raw units without a physical factor, under 100 rows, no rate; InputError for
    numbers no instrument produces or a time axis that does not advance (station.guard).
    """
    from station.errors import UnsupportedError
    from station.guard import check_extremes

    where = f"{capture.path}: " if capture.path else ""
    if not capture.is_time_series:
        raise UnsupportedError(
            f"{where}a table of averages has no noise to analyse: give a still time-series recording"
        )
    check_extremes(capture, columns=False)
    rate = capture.series_rate_hz(RATE_CONSEQUENCE)
    t = capture.columns["t"]
    if not rate or not math.isfinite(rate) or rate <= 0:
        raise UnsupportedError(
            f"{where}no sample rate: the capture has no sample_rate_hz and its t column does not advance"
        )
    out: dict = {"sample_rate_hz": float(rate), "sensors": {}, "skipped": {}, "notes": []}
    moving = _moving_share(capture)
    if moving is not None and moving > MOVING_SHARE_WARN:
        warning = (
            f"{moving:.0%} of the record moves (stillness detection): the Allan deviation of a record with motion "
            "is not the sensor's noise; record with the unit at rest"
        )
        out.update(
            duration_s=float(t[-1] - t[0]),
            warnings=[warning],
            withheld=f"figures withheld: {moving:.0%} of the record moves, so no figure would be the sensor's noise",
        )
        return out
    for kind, (cols, unit_key) in SENSORS.items():
        if not all(c in capture.columns for c in cols):
            continue
        k, how = _factor(capture, kind, unit_key)
        if k is None:
            out["skipped"][kind] = how
            continue
        if how:
            out["notes"].append(how)
        y = np.column_stack([capture.columns[c] for c in cols]) * k
        y = y[np.all(np.isfinite(y), axis=1)]
        if len(y) < 100:
            out["skipped"][kind] = f"only {len(y)} samples"
            continue
        out["sensors"][kind] = allan.noise_fit(y, 1.0 / rate)
        out["duration_s"] = len(y) / rate
    if not out["sensors"]:
        why = "; ".join(f"{k}: {v}" for k, v in out["skipped"].items()) or "no gx gy gz or ax ay az columns"
        raise UnsupportedError(f"{where}no gyro or accelerometer to analyse ({why})")
    return out


# Share of moving samples above which the figures are said not to be the sensor's noise. The
# stillness detector (solvers.stillness) finds every sample of the real still records in
# ../shared/data (MPU-6050, sunsided) at rest; a full-sphere turn record is half moving.
MOVING_SHARE_WARN = 0.01


def _moving_share(capture) -> float | None:
    """The share of rows the stillness detector does not find at rest; None without an
    accelerometer (it detects motion from the accelerometer's variance) or when it fails."""
    from solvers.errors import SolverError
    from solvers.stillness import detect_static_intervals

    if not all(c in capture.columns for c in ("ax", "ay", "az")):
        return None
    accel = np.column_stack([capture.columns[c] for c in ("ax", "ay", "az")])
    gyro = (
        np.column_stack([capture.columns[c] for c in ("gx", "gy", "gz")])
        if all(c in capture.columns for c in ("gx", "gy", "gz"))
        else None
    )
    try:
        st = detect_static_intervals(strictly_increasing_t(capture.columns["t"]), accel, gyro, nan_policy="omit")
    except (SolverError, ValueError):
        return None
    still = sum(iv.stop - iv.start for iv in st.intervals)
    return 1.0 - still / len(accel)


def noise_json(result: dict) -> dict:
    """JSON-ready figures in Kalibr's units (rates in SI: rad/s, m/s^2)."""
    doc = {"sample_rate_hz": result["sample_rate_hz"], "duration_s": result.get("duration_s"), "sensors": {}}
    for kind, f in result["sensors"].items():
        u = SI_UNIT[kind]
        doc["sensors"][kind] = {
            "unit": u,
            "noise_density": f.white.tolist(),
            "noise_density_sigma": f.white_sigma.tolist(),
            "noise_density_unit": f"{u}/sqrt(Hz)",
            "random_walk": f.random_walk.tolist(),
            "random_walk_sigma": f.random_walk_sigma.tolist(),
            "random_walk_unit": f"{u}/s/sqrt(Hz)",
            "bias_instability": f.bias_instability.tolist(),
            "bias_instability_tau_s": f.bias_instability_tau_s.tolist(),
            "bias_instability_unit": u,
            "random_walk_min_duration_s": [
                x if math.isfinite(x) else None for x in f.random_walk_min_duration_s.tolist()
            ],
            "tau_s": f.taus_s.tolist(),
            "adev": f.adev.T.tolist(),
            "adev_lo_68": f.adev_lo.T.tolist(),
            "adev_hi_68": f.adev_hi.T.tolist(),
        }
    if result.get("notes"):
        doc["notes"] = list(result["notes"])
    if result.get("warnings"):
        doc["warnings"] = list(result["warnings"])
    if result.get("withheld"):
        doc["withheld"] = result["withheld"]
    return doc


def random_walk_warning(f, kind: str) -> str | None:
    """A sentence when the record is too short for the random walk's stated sigma to hold."""
    need = float(np.max(f.random_walk_min_duration_s))
    if f.duration_s >= need:
        return None
    if not math.isfinite(need):
        return f"{kind} random walk not resolved on some axis (fitted 0): record longer"
    return (
        f"{kind} random walk poorly resolved: its sigma holds for records of {need:.0f} s or more, "
        f"this one is {f.duration_s:.0f} s"
    )


def kalibr_yaml(result: dict, rostopic: str = "/imu0") -> str:
    """Kalibr's imu.yaml: one value per sensor, the largest of the three axes (conservative:
    Kalibr models every axis with the same density), per-axis figures and 1-sigma in comments."""
    lines = [
        "# IMU noise model for Kalibr (station noise): white noise and bias random walk of a still record",
        f"# {result.get('duration_s', 0):.0f} s at {result['sample_rate_hz']:g} Hz; each value is the largest "
        "of the three axes",
    ]
    body = []
    for kind, key in (("accel", "accelerometer"), ("gyro", "gyroscope")):
        f = result["sensors"].get(kind)
        if f is None:
            lines.append(f"# no {key} in the capture: {key} values are missing and Kalibr will refuse the file")
            continue
        u = "m/s^2" if kind == "accel" else "rad/s"
        for name, v, s, unit in (
            ("noise_density", f.white, f.white_sigma, f"{u}/sqrt(Hz)"),
            ("random_walk", f.random_walk, f.random_walk_sigma, f"{u}/s/sqrt(Hz)"),
        ):
            i = int(np.argmax(v))
            per_axis = ", ".join(f"{a} {x:.4g} ± {e:.2g}" for a, x, e in zip("xyz", v, s))
            body.append(f"{key}_{name}: {float(v[i]):.6g}  # {unit}; per axis {per_axis}")
            if name == "random_walk":
                short = random_walk_warning(f, kind)
                if short:
                    lines.append(f"# {short}")
    body.append(f"update_rate: {result['sample_rate_hz']:.6g}  # Hz")
    body.append(f"rostopic: {rostopic}")
    return "\n".join(lines + body) + "\n"
