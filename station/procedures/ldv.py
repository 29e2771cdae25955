"""P5 laser velocimeter calibration from a capture (calibrate.md, procedure ``ldv``).

``calibrate(capture, method=None, *, reference=None) -> dict``.

Columns: ``vl1 vl2 vl3`` (beam outputs, m/s) at times ``t``; the reference velocity either

- in the body frame: ``vx vy vz`` (m/s; the angles come out relative to these axes), or
- in the navigation frame with attitude: ``vn ve vd`` (NED, m/s) and ``roll_deg
  pitch_deg yaw_deg``, rotated into the body with ``v_b = C_n_bᵀ v_n``, ``C_n_b =
  Rz(yaw) Ry(pitch) Rx(roll)`` (aerospace z-y-x Euler angles, body x forward, y right,
  z down; :func:`solvers.frames.euler_to_C_n_b`).

Two streams with different clocks (the reference usually comes from the INS/DGPS at its
own rate). Conventions, in order:

1. a separate reference capture: the keyword ``reference`` (path) or the metadata key
   ``reference_file`` (relative to the capture's folder); its ``t`` is the reference clock;
2. in the same file, a ``ref_t`` column giving the reference samples' times (rows need not
   pair up: empty fields where one stream has no sample);
3. in the same file, one ``t`` column with the streams interleaved (LDV rows with empty
   reference fields and vice versa).

``reference_time_offset_s`` (metadata, default 0) is the reference clock minus the LDV
clock; the reference is rotated into the body at its own samples, then its body velocity
is linearly interpolated to the LDV times. LDV samples outside the reference span, or
inside a reference gap longer than 5 reference intervals, are left out (counted in a
warning). When every row holds both streams and there is no ``ref_t``, rows pair as they
are, unless ``reference_time_offset_s`` is set: then the reference is shifted by it along
``t`` and interpolated as above.

``method``: ``force`` computes even when the velocity set is ill-conditioned (loud
warning); otherwise such a capture is refused.

The reference's noise (:func:`reference_noise`, used by calibrate and diagnose alike): the
velocity noise ``reference_sigma_mps`` (metadata) and, for a navigation-frame reference, the
attitude noise ``reference_attitude_sigma_deg`` (metadata; per axis; 0 turns it off), else read
from the attitude series itself. The attitude noise turns the body velocity by ``v × δθ``
(≈ 25 mm/s at 70 m/s and 0.02°), across the velocity where an aircraft's spread is small:
least squares on a noisy regressor is biased (errors in variables), so when a noise is known
the moment-corrected estimator is used and its uncertainty widened (``estimator``,
``reference_noise`` in the result).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from solvers import frames
from solvers import ldv as ldv_solver
from solvers.errors import SolverError
from station.capture import fill_missing
from station.errors import InputError, UnsupportedError
from station.procedures.contract import DiagnosisInput

MODEL = "V_L = (1 + δK)(V_x cos α + V_y cos β + V_z cos γ) (P5), per beam"
DIAGNOSIS_BASELINE = True  # diagnosis_input starts from the calibrate result
# station.guard: columns read as measurements (present but empty in every row: refused), and
# the parameters this procedure exists to deliver (any of them non-finite: refused)
MEASURED = (
    "vl1",
    "vl2",
    "vl3",
    "vx",
    "vy",
    "vz",
    "vn",
    "ve",
    "vd",
    "roll_deg",
    "pitch_deg",
    "yaw_deg",
    "wx",
    "wy",
    "wz",
)
CORE_PARAMS = ("beam1", "beam2", "beam3")
# station.guard: a beam reading one value in every row is dead or saturated (refused)
# station.procedures.review: a unit by parameter name (".dK": the dK of any beam)
PARAM_UNITS = {".dK": "1"}
PARAM_SHAPES = {  # every parameter the result can hold (calibrate.md)
    **{f"beam{b}.{k}": () for b in (1, 2, 3) for k in ("dK", "alpha_deg", "beta_deg", "gamma_deg", "sigma_mps")},
    "condition_number": (),
}
LIMIT_EXAMPLE = "e.g. beam1.dK=-0.02:0.02  beam1.alpha_deg=58:62"  # the limits box's example (screens/limits.py)
DEAD_IF_CONSTANT = ("vl1", "vl2", "vl3")
DEAD_IF_CONSTANT_SAYS = (
    "beam '{name}' reads {value:g} m/s in every row: a dead or saturated beam, its angles and scale "
    "factor cannot be determined"
)
NAV_COLS = ("vn", "ve", "vd", "roll_deg", "pitch_deg", "yaw_deg")
BODY_COLS = ("vx", "vy", "vz")


def _cols(capture, names):
    return np.column_stack([np.asarray(capture.columns[c], dtype=float) for c in names])


def _reference_body(cap, tcol: str):
    """(t_ref, v_body (n,3), kind, attitude noise σ [rad] or None) from a capture holding the
    reference columns (:func:`solvers.ldv.attitude_noise_rad` on its attitude series)."""
    att_sigma = None
    if all(c in cap.columns for c in BODY_COLS):
        v = _cols(cap, BODY_COLS)
        kind = "body"
    elif all(c in cap.columns for c in NAV_COLS):
        nav = _cols(cap, NAV_COLS)
        ok = np.all(np.isfinite(nav), axis=1)
        v = np.full((len(nav), 3), np.nan)
        r, p, y = np.radians(nav[ok, 3]), np.radians(nav[ok, 4]), np.radians(nav[ok, 5])
        C = np.stack([frames.euler_to_C_n_b(a, b, c) for a, b, c in zip(r, p, y)])
        v[ok] = np.einsum("nji,nj->ni", C, nav[ok, :3])  # C_n_bᵀ v_n
        kind = "nav"
        att_sigma = ldv_solver.attitude_noise_rad(C)
    else:
        have = ", ".join(cap.columns)
        raise InputError(
            cap.path,
            cap.header_line,
            "ldv needs a reference velocity: columns vx vy vz (body) "
            f"or vn ve vd with roll_deg pitch_deg yaw_deg (have {have})",
        )
    t = np.asarray(cap.columns[tcol], dtype=float) if tcol in cap.columns else None
    return t, v, kind, att_sigma


def _interp(t_ref, v_ref, t_out, warnings):
    ok = np.isfinite(t_ref) & np.all(np.isfinite(v_ref), axis=1)
    t_ref, v_ref = t_ref[ok], v_ref[ok]
    order = np.argsort(t_ref, kind="stable")
    t_ref, v_ref = t_ref[order], v_ref[order]
    if len(t_ref) < 2:
        raise UnsupportedError("fewer than 2 reference samples: nothing to interpolate")
    out = np.column_stack([np.interp(t_out, t_ref, v_ref[:, k]) for k in range(3)])
    dt = float(np.median(np.diff(t_ref)))
    i = np.clip(np.searchsorted(t_ref, t_out), 1, len(t_ref) - 1)
    gap = t_ref[i] - t_ref[i - 1]
    inside = (t_out >= t_ref[0]) & (t_out <= t_ref[-1]) & (gap <= 5 * dt)
    if (~inside).any():
        warnings.append(f"{int((~inside).sum())} LDV samples outside the reference span or in its gaps left out")
    out[~inside] = np.nan
    return out


def _resolve(path_text: str, capture) -> str:
    if os.path.isabs(path_text):
        return path_text
    base = os.path.dirname(os.fspath(capture.path)) if capture.path else ""
    cand = os.path.join(base, path_text)
    return cand if os.path.exists(cand) or not os.path.exists(path_text) else path_text


def aligned_velocities(capture, reference=None, warnings=None):
    """(v_body (n,3), vl (n,3), info) paired on the LDV clock (module docstring);
    ``info["rows"]``: the capture rows (indices) the pairs come from."""
    warnings = [] if warnings is None else warnings
    missing = [c for c in ("vl1", "vl2", "vl3") if c not in capture.columns]
    if missing:
        raise InputError(
            capture.path,
            capture.header_line,
            f"ldv needs beam column(s) {', '.join(missing)} (have {', '.join(capture.columns)})",
        )
    vl = _cols(capture, ("vl1", "vl2", "vl3"))
    offset = capture.float_meta("reference_time_offset_s", 0.0)
    ref_path = reference or capture.meta.get("reference_file")
    info = {}
    if ref_path:
        from station.capture import read_capture

        ref_cap = read_capture(_resolve(os.fspath(ref_path), capture))
        if "t" not in ref_cap.columns or "t" not in capture.columns:
            raise InputError(ref_cap.path, None, "a separate reference stream needs a 't' column in both files")
        t_ref, v_ref, kind, info["attitude_sigma_rad"] = _reference_body(ref_cap, "t")
        info["alignment"] = f"reference file {os.path.basename(os.fspath(ref_path))}, interpolated to LDV times"
    else:
        tcol = "ref_t" if "ref_t" in capture.columns else "t"
        t_ref, v_ref, kind, info["attitude_sigma_rad"] = _reference_body(capture, tcol)
        if t_ref is None:
            t_ref = None
        both = np.all(np.isfinite(vl), axis=1) & np.all(np.isfinite(v_ref), axis=1)
        if tcol == "t" and (t_ref is None or (both.all() and not offset)):
            info["alignment"] = "rows paired as recorded"
            if offset:
                warnings.append(
                    f"reference_time_offset_s {offset:g} not applied: rows pair as recorded and there is no "
                    "'t' column to shift the reference along"
                )
            ok = np.all(np.isfinite(vl), axis=1) & np.all(np.isfinite(v_ref), axis=1)
            if (~ok).any():
                warnings.append(f"{int((~ok).sum())} rows with missing values left out")
            return v_ref[ok], vl[ok], dict(info, reference=kind, rows=np.flatnonzero(ok))
        if t_ref is None:
            raise UnsupportedError(
                f"{capture.path or 'capture'}: rows hold either LDV or reference samples but there is no time column to align them"
            )
        info["alignment"] = (
            "'ref_t' column"
            if tcol == "ref_t"
            else (
                "rows paired, reference shifted by reference_time_offset_s" if both.all() else "interleaved rows on 't'"
            )
        ) + ", reference interpolated to LDV times"
    if "t" not in capture.columns:
        raise InputError(capture.path, capture.header_line, "aligning two streams needs a 't' column")
    t = np.asarray(capture.columns["t"], dtype=float)
    ldv_ok = np.all(np.isfinite(vl), axis=1) & np.isfinite(t)
    partial = np.any(np.isfinite(vl), axis=1) & ~ldv_ok  # rows of the LDV stream that cannot be used
    if partial.any():
        warnings.append(f"{int(partial.sum())} LDV rows with a missing beam value or time left out")
    v_at = _interp(t_ref - offset, v_ref, t[ldv_ok], warnings)
    good = np.all(np.isfinite(v_at), axis=1)
    if offset:
        info["reference_time_offset_s"] = offset
    return v_at[good], vl[ldv_ok][good], dict(info, reference=kind, rows=np.flatnonzero(ldv_ok)[good])


@dataclass
class Prepared:
    """A P5 capture read once: reference and beam velocities paired on the LDV clock."""

    v_body: np.ndarray  # reference velocity in the body frame (n, 3), m/s
    vl: np.ndarray  # beam outputs (n, 3), m/s
    info: dict  # alignment, reference kind, rows (capture row of each pair)
    warnings: list[str] = field(default_factory=list)
    # the reference's noise per epoch (n, 3, 3) [m²/s²] (reference_noise), None: not known
    ref_cov: np.ndarray | None = None
    ref_noise: dict = field(default_factory=dict)  # its parts and where they came from


# Station metadata keys (unknown keys are kept: capture-format.md): the reference velocity's
# white noise per axis, and its attitude's (a nav-frame reference), which then replaces the
# figure read from the attitude series; 0 turns either off.
REF_SIGMA_KEY = "reference_sigma_mps"
ATT_SIGMA_KEY = "reference_attitude_sigma_deg"


def reference_noise(capture, v_body, vl, info) -> tuple[np.ndarray | None, dict]:
    """The reference's noise covariance per epoch, the one model calibrate (errors-in-variables
    estimator and its uncertainty) and diagnose (the regressor and the rows' whitening) both use:
    velocity noise from ``reference_sigma_mps`` (metadata), attitude noise from
    ``reference_attitude_sigma_deg`` (metadata) or else from the attitude series' own
    high-frequency part (:func:`solvers.ldv.attitude_noise_rad`; not used where it would put
    more into a beam than its whole residual, or next to nothing:
    :func:`solvers.ldv.reference_noise_share`), propagated into the body
    velocity as ``σ_att² (|v|² I − v vᵀ)`` (:func:`solvers.ldv.reference_noise_cov`)."""
    sig_v = capture.float_meta_within(REF_SIGMA_KEY, None, 1e5, zero=True)
    note: dict = {}
    if sig_v:
        note["velocity_sigma_mps"] = sig_v
    sig_att = None
    given = capture.float_meta_within(ATT_SIGMA_KEY, None, 90.0, zero=True)  # a bad value: refused on its line
    if info.get("reference") == "nav":
        if given is not None:
            sig_att = math.radians(given)
            note["attitude_sigma_deg"] = given
            note["attitude_sigma_source"] = "metadata"
        elif info.get("attitude_sigma_rad"):
            sig_att = float(info["attitude_sigma_rad"])
            share = (
                ldv_solver.reference_noise_share(v_body, vl, ldv_solver.reference_noise_cov(v_body, None, sig_att))
                if len(v_body) >= 4
                else np.zeros(1)
            )
            if np.any(share > 1.0) or np.all(share < ldv_solver.REF_NOISE_NEGLIGIBLE):
                sig_att = None  # more than the beams' whole residual (the series' motion), or nothing
            else:
                note["attitude_sigma_deg"] = math.degrees(sig_att)
                note["attitude_sigma_source"] = "attitude series (second and third differences)"
    return ldv_solver.reference_noise_cov(v_body, sig_v, sig_att), note


def prepare(capture, reference=None) -> Prepared:
    """The paired velocities of ``capture`` (``reference``: a separate reference capture's path)."""
    warnings: list[str] = []
    v_b, vl, info = aligned_velocities(capture, reference, warnings)
    cov, note = reference_noise(capture, v_b, vl, info)
    return Prepared(v_b, vl, info, warnings, cov, note)


# A vehicle at rest: the reference speed the guide calls parked, and the fewest moving epochs a
# fit is tried on when some epochs are parked. At rest the beams and the reference read their
# noise, whose directions are random: a well-conditioned set of nothing (a 2 s parked record gave
# δK = -0.73 ± 0.65, cond 2.4). A record whose every epoch moves is not parked, however few its
# epochs: P5 asks for n >= 3 epochs in different motion states (a table of 3 to 9 averaged epochs
# was refused as "hardly moved: 4 of 4 epochs at 0.5 m/s or more"); the solver's own minimum
# (4 epochs: 3 for X, a 4th for its σ) and the conditioning check judge it.
PARKED_MPS = 0.5
MIN_MOVING_EPOCHS = 10
# Fewer residual degrees of freedom than this (n − 3 per beam): the σ is itself uncertain by
# more than ~20 % and a warning gives the Student-t interval.
FEW_DOF = 10


def _refuse_parked(capture, v_body: np.ndarray, force: bool) -> None:
    speed = np.linalg.norm(v_body, axis=1)
    moving = int(np.count_nonzero(speed >= PARKED_MPS))
    if moving < MIN_MOVING_EPOCHS and moving < len(speed) and not force:
        raise UnsupportedError(
            f"{capture.path or 'capture'}: ldv: the vehicle hardly moved: {moving} of {len(speed)} epochs at a "
            f"reference speed of {PARKED_MPS:g} m/s or more (at rest the beams see only their noise); drive, with "
            "turns, slopes and braking"
        )


def calibrate(capture, method: str | None = None, *, reference=None, prepared: Prepared | None = None) -> dict:
    force = (method or "").strip().lower() == "force"
    if method and not force:
        raise UnsupportedError(f"ldv: unknown method {method!r} (only 'force')")
    prep = prepared if prepared is not None else prepare(capture, reference)
    warnings = list(prep.warnings)
    v_b, vl, info = prep.v_body, prep.vl, prep.info
    _refuse_parked(capture, v_b, force)
    try:
        res = ldv_solver.calibrate_ldv(v_b, vl, ref_cov_mps2=prep.ref_cov, force=force)
    except SolverError as exc:
        raise UnsupportedError(f"{capture.path or 'capture'}: {exc}") from None
    warnings += res.warnings
    if res.n - 3 < FEW_DOF:
        from scipy import stats

        warnings.append(
            f"{res.n} epochs: each beam's σ rests on {res.n - 3} degree{'' if res.n == 4 else 's'} of freedom "
            f"(n − 3); a 95 % interval is ±{float(stats.t.isf(0.025, res.n - 3)):.3g}σ, not ±1.96σ: record more epochs"
        )
    params, unc, fit = {}, {}, {}
    for j, b in enumerate(res.beams):
        key = f"beam{j + 1}"
        params[key] = {
            "dK": b.dK,
            "alpha_deg": b.angles_deg[0],
            "beta_deg": b.angles_deg[1],
            "gamma_deg": b.angles_deg[2],
            "sigma_mps": b.sigma_mps,
        }
        unc[key] = {
            "dK": b.sigma_dK,
            "alpha_deg": b.sigma_angles_deg[0],
            "beta_deg": b.sigma_angles_deg[1],
            "gamma_deg": b.sigma_angles_deg[2],
            "sigma_mps": b.sigma_mps / np.sqrt(2.0 * max(res.n - 3, 1)),
        }
        fit[key] = {"X": b.X, "cov_X": b.cov_X, "eiv_bias_X": b.eiv_bias_X}
        cosines = np.cos(np.radians(b.angles_deg))
        if abs(float(cosines @ cosines) - 1.0) > 1e-9:
            warnings.append(f"{key}: direction cosines do not form a unit vector")
    params["condition_number"] = res.condition_number
    unc["condition_number"] = 0.0
    resid = np.concatenate([b.residuals for b in res.beams])
    return {
        "procedure": "ldv",
        "device": capture.meta.get("device"),
        "model": MODEL,
        "params": params,
        "uncertainty": unc,
        "residual_rms": float(np.sqrt(np.mean(resid**2))),
        "n_positions": res.n,
        "warnings": warnings,
        "reference": info.get("reference"),
        "euler_convention": "C_n_b = Rz(yaw) Ry(pitch) Rx(roll), NED, body x fwd y right z down",
        "alignment": info.get("alignment"),
        "estimator": "errors-in-variables corrected" if prep.ref_cov is not None else "ordinary least squares",
        "reference_noise": dict(prep.ref_noise),
        "fit": fit,
    }


def format_text(result: dict) -> str:
    from station.formatting import device_text

    p, u = result["params"], result["uncertainty"]
    lines = [
        "procedure  ldv",
        f"device     {device_text(result)}",
        f"model      {result['model']}",
        f"reference  {result.get('reference')} ({result.get('alignment')}); {result.get('estimator')}",
        f"cond(HᵀH)  {p['condition_number']:.3g}  ({result['n_positions']} epochs)",
    ]
    for j in (1, 2, 3):
        b, s = p[f"beam{j}"], u[f"beam{j}"]
        lines.append(
            f"beam{j}      δK {b['dK']:+.5f} ± {s['dK']:.1e}  α {b['alpha_deg']:.3f} ± {s['alpha_deg']:.3f}°"
            f"  β {b['beta_deg']:.3f} ± {s['beta_deg']:.3f}°  γ {b['gamma_deg']:.3f} ± {s['gamma_deg']:.3f}°"
            f"  σ {b['sigma_mps']:.4f} m/s"
        )
    lines.append(f"residual   {result['residual_rms']:.4g} m/s RMS")
    noise = result.get("reference_noise") or {}
    if noise:
        parts = []
        if noise.get("velocity_sigma_mps"):
            parts.append(f"velocity {noise['velocity_sigma_mps']:.3g} m/s (metadata)")
        if noise.get("attitude_sigma_deg") is not None:
            parts.append(f"attitude {noise['attitude_sigma_deg']:.3g}° ({noise.get('attitude_sigma_source')})")
        lines.append("ref noise  " + ", ".join(parts))
    for w in result.get("warnings", []):
        lines.append(f"warning    {w}")
    return "\n".join(lines)


def body_rate_from_attitude(t_s, roll_deg, pitch_deg, yaw_deg) -> np.ndarray:
    """Body angular rate (n, 3) [rad/s] from an attitude series (``C_n_b = Rz Ry Rx``): the
    rotation vector of ``C_kᵀ C_k+1`` over the step, at the step's middle, interpolated to the
    samples' times. Rows without a finite attitude or time, and steps across a gap longer than
    5 median steps, give NaN (the lever arm is then not tested)."""
    t = np.asarray(t_s, float)
    ok = np.isfinite(t) & np.isfinite(roll_deg) & np.isfinite(pitch_deg) & np.isfinite(yaw_deg)
    out = np.full((len(t), 3), np.nan)
    idx = np.flatnonzero(ok)
    if len(idx) < 3:
        return out
    r, p, y = (np.radians(np.asarray(a, float)[idx]) for a in (roll_deg, pitch_deg, yaw_deg))
    C = np.stack([frames.euler_to_C_n_b(a, b, c) for a, b, c in zip(r, p, y)])
    tt = t[idx]
    dt = np.diff(tt)
    step = np.einsum("nji,njk->nik", C[:-1], C[1:])  # C_kᵀ C_k+1: the turn in the body frame
    good = (dt > 0) & (dt <= 5 * float(np.median(dt[dt > 0]))) if np.any(dt > 0) else np.zeros(len(dt), bool)
    if not good.any():
        return out
    w = np.stack([frames.matrix_to_rotvec(m) for m in step[good]]) / dt[good, None]
    mid = (tt[:-1] + tt[1:])[good] / 2.0
    inside = (tt >= mid[0]) & (tt <= mid[-1])
    # a sample between two steps that straddle a gap: no rate there
    gap_after = np.r_[~good, False]
    gap_before = np.r_[False, ~good]
    keep = inside & ~(gap_after & gap_before)
    out[idx[keep]] = np.column_stack([np.interp(tt[keep], mid, w[:, k]) for k in range(3)])
    return out


def _finite(t, x):
    ok = np.isfinite(t) & np.isfinite(x)
    return (t[ok], x[ok]) if ok.any() else (np.array([0.0]), np.array([np.nan]))


def diagnosis_input(capture, base: dict, prepared: Prepared | None = None) -> DiagnosisInput:
    """The P5 diagnosis problem around the baseline ``base`` (a calibrate result)."""
    from solvers.diagnose import problems as DP
    from station.procedures.diagnose import screen

    prep = prepared if prepared is not None else prepare(capture)
    v_b, vl, rows, ref_cov = prep.v_body, prep.vl, prep.info.get("rows"), prep.ref_cov
    bad, screened = screen(capture)  # gaps and saturated samples: left out of the effect search
    if rows is not None and bad[rows].any() and (~bad[rows]).sum() >= 16:
        keep = ~bad[np.asarray(rows)]
        v_b, vl, rows = v_b[keep], vl[keep], np.asarray(rows)[keep]
        ref_cov = None if ref_cov is None else ref_cov[keep]

    def pick(name):
        return None if name not in capture.columns or rows is None else np.asarray(capture.columns[name], float)[rows]

    W = None
    if rows is not None and all(c in capture.columns for c in ("wx", "wy", "wz")):
        W = np.column_stack([pick(c) for c in ("wx", "wy", "wz")])
    elif rows is not None and "t" in capture.columns and all(c in capture.columns for c in NAV_COLS[3:]):
        # no wx wy wz: the body rate from the attitude the reference carries (capture-format:
        # wx wy wz are optional), so that a lever arm (ω × r) can still be tested
        t_all = np.asarray(capture.columns["t"], float)
        W = body_rate_from_attitude(t_all, *(np.asarray(capture.columns[c], float) for c in NAV_COLS[3:]))
        W = np.column_stack([np.interp(t_all[rows], *_finite(t_all, W[:, k])) for k in range(3)])
    X0 = np.array([base["fit"][f"beam{j + 1}"]["X"] for j in range(3)], float)
    temp = None
    if rows is not None and "temp_c" in capture.columns:  # a few empty fields: interpolated over time
        temp = fill_missing(capture.columns["temp_c"], capture.columns.get("t"))[rows]
    prob = DP.ldv_problem(pick("t"), v_b, vl, X0, temp_c=temp, omega_body_rad_s=W, ref_cov_mps2=ref_cov)
    prob.screened = screened
    return DiagnosisInput(prob, {"rows": rows}, "a sample far off: a dropout of the LDV or the reference")


def results_lines(result: dict) -> list[str]:
    """What the TUI's Results summary says of P5 beyond the residual: the velocity set's
    conditioning."""
    cond = (result.get("params") or {}).get("condition_number")
    if isinstance(cond, (int, float)):
        return [f"velocity set: cond(HᵀH) = {cond:.3g} (well enough conditioned to separate the angles)"]
    return []
