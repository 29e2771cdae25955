"""P4 (source 003): MEMS gyro drift at power-up, in the source's frames.

Frames (``solvers/frames.py``): body x forward, y up, z right; navigation north-up-east.
All rates in rad/s. The compensation is ``ω' = ω − ε`` (:func:`solvers.models.gyro.inverse`
with block ``eps``).

- Mode A, reference IMU (:func:`drift_reference`): ``ε_i = mean_k (ω_i(k) − Ω_i(k))``.
- Mode B, static base (:func:`drift_static`): ``ε^b = ω̄^b − C_b_n ω_ie^n`` with
  ``C_n_b`` from (ψ = heading, θ, γ) and θ, γ from the averaged accelerometer.
- Several static positions (:func:`drift_multi`): the stacked model
  ``ω̄_k = ε + s · C_b_n,k ω_ie^n`` solved for ε and the Earth-rate scale ``s``
  (1 when latitude and headings are right), or, with no latitude, for ε and the Earth
  rate's navigation components (which gives the latitude where they are identifiable).

Uncertainties (1 sigma): the mean's standard error from :mod:`solvers.allan` (correlated
noise included), plus, in mode A, the reference IMU's own drift; in mode B the Earth-rate
term's error from the heading (default σ 3°, the source allows ≤ 5°), the latitude
(σ 0.5°) and the tilt, propagated through the projection.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from solvers import allan, linalg
from solvers.errors import NotIdentifiable, SolverError, TooFewPositions
from solvers.fit import linear_fit
from solvers.frames import OMEGA_EARTH_RAD_S, p4_C_n_b, p4_pitch_roll_from_accel
from solvers.models.gyro import earth_rate_body

DEG_H_RAD_S = math.radians(1.0) / 3600.0  # 1 °/h in rad/s
MIN_DURATION_S = 30.0  # below this the error estimate itself is meaningless: refused
SOURCE_DURATION_S = 180.0  # the source's ">= 3 min"


class RecordTooShort(SolverError):
    """Not enough record to estimate a drift and its error."""


@dataclass
class DriftResult:
    """What a P4 estimate found. Rates in rad/s, body x fwd, y up, z right."""

    mode: str
    drift_rad_s: np.ndarray
    sigma_rad_s: np.ndarray
    mean_error: allan.MeanError | None = None
    pitch_deg: object = None
    roll_deg: object = None
    sigma_pitch_deg: object = None
    sigma_roll_deg: object = None
    earth_rate_body_rad_s: np.ndarray | None = None
    sigma_earth_rate_body_rad_s: np.ndarray | None = None
    extra: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)


def check_length(n: int, dt_s: float, what: str) -> list[str]:
    """Refuse (``RecordTooShort``) a record under ``MIN_DURATION_S`` or 64 samples; warn under
    the source's 3 min."""
    T = n * dt_s
    if n < 64 or T < MIN_DURATION_S:
        raise RecordTooShort(
            f"{what}: {T:.1f} s ({n} samples) is too short for a drift and its "
            f"error; record at least {SOURCE_DURATION_S:.0f} s (P4 asks for >= 3 min)"
        )
    if T < SOURCE_DURATION_S - 1e-9:
        return [f"{what}: record is {T:.0f} s, shorter than the 3 min P4 asks for"]
    return []


def drift_reference(omega_rad_s, ref_rad_s, dt_s: float, ref_drift_rad_s: float = DEG_H_RAD_S) -> DriftResult:
    """Mode A: mean of MEMS minus reference over the record.

    ``ref_drift_rad_s``: the reference IMU's own drift (1 sigma per axis, default 1 °/h,
    the source's fibre-optic example): added in quadrature to the standard error.
    """
    w = np.asarray(omega_rad_s, dtype=float)
    r = np.asarray(ref_rad_s, dtype=float)
    warnings = check_length(len(w), dt_s, "mode A")
    me = allan.mean_standard_error(w - r, dt_s)
    sigma = np.sqrt(me.se**2 + ref_drift_rad_s**2)
    extra = {"ref_drift_rad_s": ref_drift_rad_s}
    # Mounting check: regress the difference on the reference rate, d = ε + M Ω. A
    # misalignment or scale error M biases the mean difference by M · mean(Ω).
    R = r - r.mean(axis=0)
    if np.linalg.matrix_rank(R.T @ R) == 3:
        M = linalg.lstsq(R, (w - r) - (w - r).mean(axis=0), rcond=None)[0].T
        extra["rate_coupling"] = M
        bias = M @ r.mean(axis=0)
        extra["rate_coupling_bias_rad_s"] = bias
        if np.any(np.abs(bias) > 0.5 * sigma):
            warnings.append(
                "MEMS minus reference grows with the rate (misalignment or scale error, largest "
                f"{np.max(np.abs(M)):.3g} rad/rad): with a mean rate of "
                f"{np.linalg.norm(r.mean(axis=0)):.3g} rad/s it biases the drift by up to "
                f"{np.max(np.abs(bias)):.3g} rad/s"
            )
    return DriftResult("reference", me.mean, sigma, me, extra=extra, warnings=warnings)


def _pitch_roll_sigma(f_mean, f_se) -> tuple[float, float, float, float]:
    """Pitch, roll (deg) from a mean specific force (any unit) and their 1-sigma."""
    f = np.asarray(f_mean, dtype=float)
    p0, r0 = p4_pitch_roll_from_accel(f)
    J = np.empty((2, 3))
    h = 1e-6 * np.linalg.norm(f)
    for k in range(3):
        d = np.zeros(3)
        d[k] = h
        pp, rp = p4_pitch_roll_from_accel(f + d)
        pm, rm = p4_pitch_roll_from_accel(f - d)
        J[:, k] = [(pp - pm) / (2 * h), _wrap(rp - rm) / (2 * h)]
    cov = J @ np.diag(np.asarray(f_se, dtype=float) ** 2) @ J.T
    s = np.sqrt(np.diag(cov))
    return math.degrees(p0), math.degrees(r0), math.degrees(s[0]), math.degrees(s[1])


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def earth_rate_body_sigma(
    latitude_deg: float,
    pitch_deg: float,
    roll_deg: float,
    heading_deg: float,
    sigmas_deg: tuple[float, float, float, float],
) -> tuple[np.ndarray, np.ndarray]:
    """Earth rate in the body frame and its 1-sigma from the errors of (latitude, pitch,
    roll, heading) [deg], propagated by central differences."""

    def e(x):
        L, p, r, h = x
        return earth_rate_body(L, p4_C_n_b(math.radians(p), math.radians(r), math.radians(h)))

    x0 = np.array([latitude_deg, pitch_deg, roll_deg, heading_deg], dtype=float)
    J = np.empty((3, 4))
    for k in range(4):
        d = np.zeros(4)
        d[k] = 1e-4
        J[:, k] = (e(x0 + d) - e(x0 - d)) / 2e-4
    cov = J @ np.diag(np.asarray(sigmas_deg, dtype=float) ** 2) @ J.T
    return e(x0), np.sqrt(np.diag(cov))


def drift_static(
    omega_rad_s,
    f_body,
    dt_s: float,
    latitude_deg: float | None,
    heading_deg: float = 0.0,
    *,
    heading_sigma_deg: float = 3.0,
    latitude_sigma_deg: float = 0.5,
) -> DriftResult:
    """Mode B on one static position.

    ``omega_rad_s`` (N, 3) gyro in rad/s and ``f_body`` (N, 3) specific force in any unit
    (only its direction is used), both in P4's body frame. ``latitude_deg`` None: the Earth
    rate cannot be removed; the drift is the plain mean (with a warning).
    """
    w = np.asarray(omega_rad_s, dtype=float)
    warnings = check_length(len(w), dt_s, "mode B")
    me = allan.mean_standard_error(w, dt_s)
    res = DriftResult("static", me.mean.copy(), me.se.copy(), me, warnings=warnings)
    if f_body is not None:
        fm = allan.mean_standard_error(np.asarray(f_body, dtype=float), dt_s)
        p, r, sp, sr = _pitch_roll_sigma(fm.mean, fm.se)
    else:
        p, r, sp, sr = 0.0, 0.0, 2.0, 2.0
        res.warnings.append("no accelerometer: pitch and roll taken as 0 (±2°), Earth rate projected for a level unit")
    res.pitch_deg, res.roll_deg, res.sigma_pitch_deg, res.sigma_roll_deg = p, r, sp, sr
    if latitude_deg is None:
        res.warnings.append(
            "no latitude_deg: the Earth rate cannot be removed; drift is the plain mean "
            f"(it contains up to {OMEGA_EARTH_RAD_S:.3g} rad/s of Earth rate)"
        )
        res.earth_rate_body_rad_s = None
        return res
    e, se = earth_rate_body_sigma(latitude_deg, p, r, heading_deg, (latitude_sigma_deg, sp, sr, heading_sigma_deg))
    res.earth_rate_body_rad_s, res.sigma_earth_rate_body_rad_s = e, se
    res.drift_rad_s = me.mean - e
    res.sigma_rad_s = np.sqrt(me.se**2 + se**2)
    if abs(p) > 30 or abs(r) > 30:
        res.warnings.append(
            f"pitch {p:.1f}°, roll {r:.1f}°: far from level; check the body frame (x fwd, y up, z right)"
        )
    return res


@dataclass
class Position:
    """One static position's averages: gyro rad/s and specific force (any unit), P4 body frame."""

    omega: allan.MeanError
    f: allan.MeanError | None
    heading_deg: float
    label: str = ""


def drift_multi(
    positions: list[Position],
    latitude_deg: float | None,
    *,
    heading_sigma_deg: float = 3.0,
    headings_known: bool = True,
) -> DriftResult:
    """Several static positions: ε and the Earth rate together (module docstring).

    The Earth rate a position sees is ``C_b_n,k ω_ie^n``: its vertical part ``Ω sin L`` lies
    along that position's up direction (known from the accelerometer), its horizontal part
    ``Ω cos L`` along the body's north, which only a known heading gives. So:

    - latitude and headings known: ε and the Earth-rate scale ``s`` (1 expected); each
      position's heading error (σ ``heading_sigma_deg``) enters its weight;
    - latitude known, headings not: ε only; the vertical Earth rate is removed, the horizontal
      one (magnitude ``Ω cos L``, direction unknown) is noise in each position's covariance;
    - no latitude, headings known: ε and the Earth rate's north and up components;
    - neither: ε and the up component; the horizontal part is noise as above.

    Without a latitude the Earth-rate components carry their physical bounds as a weak prior
    (``|ω| ≤ Ω``: up ``0 ± Ω/√3``, north ``2Ω/π ± Ω/2``), so a set of positions that cannot
    separate them from ε still gives ε with an honest uncertainty (the Earth rate's size
    in it) instead of nonsense. The latitude is reported only when the data, not the prior,
    determine it (posterior σ of the components below Ω/4), and always within ±90°.
    """
    if len(positions) < 2:
        raise TooFewPositions("several-position solution needs at least 2 static positions")
    W = OMEGA_EARTH_RAD_S
    rows, y, covs, tilts, e_list = [], [], [], [], []
    for pos in positions:
        if pos.f is not None:
            p, r, sp, sr = _pitch_roll_sigma(pos.f.mean, pos.f.se)
        else:
            p, r, sp, sr = 0.0, 0.0, 2.0, 2.0
        tilts.append((p, r, sp, sr))
        C = p4_C_n_b(math.radians(p), math.radians(r), math.radians(pos.heading_deg))
        up = C.T[:, 1]  # the body's view of "up" (NUE's U)
        horiz = np.eye(3) - np.outer(up, up)
        cov = np.diag(pos.omega.se**2)
        if latitude_deg is not None and headings_known:
            e, se = earth_rate_body_sigma(latitude_deg, p, r, pos.heading_deg, (0.0, sp, sr, heading_sigma_deg))
            e_list.append(e)
            rows.append(np.column_stack([np.eye(3), e]))
            cov = cov + np.diag(se**2)
            y.append(pos.omega.mean)
        elif latitude_deg is not None:
            lat = math.radians(latitude_deg)
            e_up = W * math.sin(lat) * up
            e_list.append(e_up)
            rows.append(np.eye(3))
            cov = cov + 0.5 * (W * math.cos(lat)) ** 2 * horiz
            y.append(pos.omega.mean - e_up)
        elif headings_known:
            rows.append(np.column_stack([np.eye(3), C.T[:, :2]]))  # N and U columns of C_b_n
            y.append(pos.omega.mean)
        else:
            rows.append(np.column_stack([np.eye(3), up]))
            cov = cov + 0.5 * W**2 * horiz
            y.append(pos.omega.mean)
        covs.append(cov)
    # whiten each position's 3x3 covariance (the unknown horizontal Earth rate correlates axes)
    H_w, y_w = [], []
    for Hk, yk, ck in zip(rows, y, covs):
        Lk = np.linalg.cholesky(ck + 1e-30 * np.eye(3))
        H_w.append(np.linalg.solve(Lk, Hk))
        y_w.append(np.linalg.solve(Lk, yk))
    H, Y = np.vstack(H_w), np.concatenate(y_w)
    if latitude_deg is not None:
        names = ["eps_x", "eps_y", "eps_z"] + (["s"] if headings_known else [])
    else:
        names = ["eps_x", "eps_y", "eps_z"] + (["w_N", "w_U"] if headings_known else ["w_U"])
        # the physical bounds as a weak prior (one row per Earth-rate component)
        prior = [(2 * W / math.pi, W / 2)] if headings_known else []
        prior.append((0.0, W / math.sqrt(3.0)))
        for j, (m, s) in enumerate(prior):
            row = np.zeros(H.shape[1])
            row[3 + j] = 1.0 / s
            H = np.vstack([H, row])
            Y = np.append(Y, m / s)
    fr = linear_fit(H, Y, sigma=np.ones(len(Y)), names=names)
    if fr.unidentifiable:
        raise NotIdentifiable(
            "the static positions cannot separate "
            + ", ".join(fr.unidentifiable)
            + ": add positions tilted about different axes"
        )
    x = fr.params["x"]
    sx = np.sqrt(np.diag(fr.cov))
    w_mean = np.average(
        np.array([p.omega.mean for p in positions]), axis=0, weights=[p.omega.duration_s for p in positions]
    )
    res = DriftResult("static-multi", x[:3], sx[:3])
    res.pitch_deg = [t[0] for t in tilts]
    res.roll_deg = [t[1] for t in tilts]
    res.sigma_pitch_deg = [t[2] for t in tilts]
    res.sigma_roll_deg = [t[3] for t in tilts]
    n_data = 3 * len(positions)
    res.extra = {
        "reduced_chi2": fr.reduced_chi2,
        "misfit_scaled": fr.misfit_scaled,
        "condition_number": fr.condition_number,
        "headings_known": headings_known,
        "residuals_rad_s": np.concatenate([np.asarray(yk) - Hk @ x for Hk, yk in zip(rows, y)])[:n_data],
    }
    res.earth_rate_body_rad_s = w_mean - x[:3]
    res.sigma_earth_rate_body_rad_s = sx[:3]
    weights = [p.omega.duration_s for p in positions]
    if latitude_deg is not None and headings_known:
        res.extra["earth_rate_scale"] = float(x[3])
        res.extra["sigma_earth_rate_scale"] = float(sx[3])
        # the time-weighted mean Earth rate the model removed
        e_mean = np.average(np.array(e_list), axis=0, weights=weights)
        res.earth_rate_body_rad_s = float(x[3]) * e_mean
        res.sigma_earth_rate_body_rad_s = float(sx[3]) * np.abs(e_mean)
        if abs(x[3] - 1.0) > 3 * sx[3]:
            res.warnings.append(
                f"Earth-rate scale {x[3]:.3f} ± {sx[3]:.3f} differs from 1 by more than 3σ: "
                "check latitude, headings and the body frame"
            )
    elif latitude_deg is not None:
        res.earth_rate_body_rad_s = np.average(np.array(e_list), axis=0, weights=weights)
        res.sigma_earth_rate_body_rad_s = np.full(3, W * abs(math.cos(math.radians(latitude_deg))) / math.sqrt(2.0))
        res.warnings.append(
            "headings unknown: the vertical Earth rate (Ω sin L along each position's up) is "
            "removed; the horizontal part (Ω cos L, direction unknown) is in the uncertainty"
        )
    else:
        _no_latitude(res, x, fr.cov, headings_known)
    if fr.misfit_scaled:
        res.warnings.append(
            f"positions disagree beyond their noise (reduced χ² {fr.reduced_chi2:.2f}); uncertainties scaled up"
        )
    return res


def _no_latitude(res: DriftResult, x: np.ndarray, cov: np.ndarray, headings_known: bool) -> None:
    """What the positions say about the Earth rate without a latitude (``drift_multi``)."""
    W = OMEGA_EARTH_RAD_S
    if headings_known:
        wN, wU = float(x[3]), float(x[4])
        sN, sU = math.sqrt(cov[3, 3]), math.sqrt(cov[4, 4])
        identifiable = max(sN, sU) < W / 4
        lat = math.degrees(math.atan2(wU, max(wN, 0.0)))  # cos L ≥ 0: within ±90°
        s_lat = _latitude_sigma_deg(max(wN, 1e-12), wU, cov[3:5, 3:5]) if identifiable else None
        res.extra.update(
            {
                "earth_rate_north_rad_s": wN,
                "sigma_earth_rate_north_rad_s": sN,
                "earth_rate_magnitude_ratio": math.hypot(wN, wU) / W,
            }
        )
    else:
        wU = float(x[3])
        sU = math.sqrt(cov[3, 3])
        identifiable = sU < W / 4
        ratio = max(-1.0, min(1.0, wU / W))
        lat = math.degrees(math.asin(ratio))
        s_lat = min(90.0, math.degrees(sU / W / max(math.sqrt(1.0 - ratio * ratio), 1e-3))) if identifiable else None
    res.extra.update(
        {
            "earth_rate_up_rad_s": wU,
            "sigma_earth_rate_up_rad_s": sU,
            "latitude_identifiable": identifiable,
            "latitude_from_gyros_deg": lat if identifiable else None,
            "sigma_latitude_from_gyros_deg": s_lat,
        }
    )
    what = "north and up components" if headings_known else "its vertical component (headings unknown)"
    if identifiable:
        res.warnings.append(
            f"no latitude_deg: Earth rate fitted from the positions ({what}); implied latitude "
            f"{lat:.1f}° ± {s_lat:.1f}°"
        )
    else:
        res.warnings.append(
            f"no latitude_deg: the Earth rate ({what}: up {wU:.2e} ± {sU:.1e} rad/s against |Ω| = {W:.3g}) is not "
            "identifiable from these positions, so no latitude can be inferred; the drift carries the Earth "
            "rate's possible size in its uncertainty"
            + (
                ""
                if headings_known
                else " (headings unknown: only the vertical part is observable; give latitude_deg to remove it)"
            )
        )


def _latitude_sigma_deg(wN: float, wU: float, cov2: np.ndarray) -> float:
    r2 = wN * wN + wU * wU
    J = np.array([-wU / r2, wN / r2])  # d atan2(wU, wN) / d (wN, wU)
    return math.degrees(math.sqrt(max(float(J @ cov2 @ J), 0.0)))


def accuracy_statement(me: allan.MeanError, achieved_rad_s, accuracy_rad_s: float | None) -> tuple[dict, list[str]]:
    """Achieved 1-sigma vs the accuracy asked; time needed per axis when short of it."""
    achieved = np.asarray(achieved_rad_s, dtype=float)
    out = {
        "duration_s": me.duration_s,
        "achieved_sigma_rad_s": achieved,
        "achieved_sigma_deg_h": achieved / DEG_H_RAD_S,
    }
    warnings: list[str] = []
    if accuracy_rad_s is None:
        return out, warnings
    # the part that does not average down (reference drift, Earth-rate projection)
    sys2 = np.clip(achieved**2 - me.se**2, 0.0, None)
    room = np.sqrt(np.clip(accuracy_rad_s**2 - sys2, 0.0, None))
    need = np.array([allan.time_needed_s(me, rm)[k] if rm > 0 else np.inf for k, rm in enumerate(room)])
    out["accuracy_rad_s"] = accuracy_rad_s
    out["enough"] = bool(np.all(achieved <= accuracy_rad_s))
    out["time_needed_s"] = need
    if not out["enough"]:
        worst = float(np.max(need))
        what = (
            "the noise model fitted to the Allan deviation (bias instability, rate random walk) says no "
            "record length reaches it"
            if not math.isfinite(worst)
            else f"about {worst:.0f} s needed"
        )
        warnings.append(
            f"achieved 1σ {np.max(achieved) / DEG_H_RAD_S:.3g} °/h is above the accuracy asked "
            f"({accuracy_rad_s / DEG_H_RAD_S:.3g} °/h) after {me.duration_s:.0f} s: {what}"
        )
    return out, warnings
