"""Stored calibrations in the forms flight firmwares and C code load.

Formats:
- `json`: the calibrate.md result plus its record (id, device, time, hash).
- `ardupilot`: a Mission Planner / MAVProxy `.param` file (`NAME,VALUE`, `#` comments).
  Accel `INS_ACCOFFS_*` (m/s², subtracted) and `INS_ACCSCAL_*` (multiplied after),
  gyro `INS_GYROFFS_*` (rad/s, subtracted), compass `COMPASS_OFS_*` (milligauss,
  ADDED), `COMPASS_DIA_*`/`COMPASS_ODI_*` (symmetric matrix applied after):
  AP_InertialSensor_Backend::_rotate_and_correct_accel, AP_Compass_Backend::correct_field.
- `px4`: NuttX shell `param set` lines. `CAL_ACC0_{X,Y,Z}OFF` (m/s², subtracted),
  `CAL_ACC0_{X,Y,Z}SCALE` (multiplied after), `CAL_GYRO0_{X,Y,Z}OFF` (rad/s,
  subtracted), `CAL_MAG0_{X,Y,Z}OFF` (gauss, subtracted), `CAL_MAG0_{X,Y,Z}SCALE`
  and `CAL_MAG0_{X,Y,Z}ODIAG` (symmetric matrix applied after):
  src/lib/sensor_calibration/{Accelerometer,Gyroscope,Magnetometer}.
- `c-header`: every scalar of the result as `static const double` arrays.

Both firmwares apply these in the sensor frame, before the board rotation, and take
the driver's output in SI-like units (m/s², rad/s, gauss or milligauss): a
calibration of raw volts or counts has no meaning there and is refused, as are the
procedures they have no parameters for (the LDV).
"""
from __future__ import annotations

import json
import math
import re

from solvers.frames import G_STANDARD_MPS2
from solvers.units import si_factor
from station.errors import UnsupportedError

FORMATS = ("json", "ardupilot", "px4", "c-header")
AXES = "XYZ"


class Export:
    """Lines of the exported file and the conversions made (said in its comments)."""

    def __init__(self, comment: str):
        self.comment = comment
        self.notes: list[str] = []
        self.values: list[tuple[str, float]] = []

    def note(self, text: str) -> None:
        self.notes.append(text)

    def set(self, name: str, value: float) -> None:
        if value is None or not math.isfinite(value):
            raise UnsupportedError(f"{name} would be {value}: the calibration has no finite value for it")
        self.values.append((name, float(value)))


def _unit(meta: dict, key: str, kind: str, fmt: str, procedure: str) -> tuple[str, float]:
    unit = (meta or {}).get(key)
    factor = si_factor(kind, unit) if unit else None
    if factor is None:
        raise UnsupportedError(
            f"{fmt}: {procedure} calibration of raw '{unit or 'unknown units'}' ({key}) has no meaning in that firmware, "
            f"whose drivers deliver physical units; calibrate a capture in physical units instead"
        )
    return unit, factor


def _gyro_offsets_rad_s(cal: dict, factor: float, ex: Export) -> list[float]:
    """The gyro offsets on the sensor's own axes gx gy gz, in rad/s, with the sensor's signs.

    `params.drift` is in P4's body frame (x fwd, y up, z right), which differs from the sensor's
    axes when the capture declared another `frame` or a `gyro_flip`; `drift_raw` (stored with the
    result) is the same drift on the capture's axes in its gyro unit.
    """
    raw = (cal.get("extra") or {}).get("drift_raw")
    if isinstance(raw, dict) and raw.get("axes") == "the capture's gx gy gz":
        body = _vec(cal["params"], "drift")
        offsets = [x * factor for x in _vec(raw, "value")]
        if any(not math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-15) for a, b in zip(offsets, body)):
            ex.note("drift mapped back from P4's body frame (x fwd, y up, z right) to the sensor's gx gy gz")
        return offsets
    return _vec(cal["params"], "drift")


def _vec(params: dict, name: str, n: int = 3) -> list[float]:
    v = params.get(name)
    if not isinstance(v, list) or len(v) != n:
        raise UnsupportedError(f"the calibration has no {n}-vector '{name}'")
    return [float("nan") if x is None else float(x) for x in v]


def _mat(params: dict, name: str) -> list[list[float]]:
    m = params.get(name)
    if not isinstance(m, list) or len(m) != 3 or any(not isinstance(r, list) or len(r) != 3 for r in m):
        raise UnsupportedError(f"the calibration has no 3x3 matrix '{name}'")
    return [[float("nan") if x is None else float(x) for x in r] for r in m]


def _symmetric_part(w: list[list[float]]):
    """P = sqrtm(Wᵀ W): the symmetric matrix with |P x| = |W x| (W = Q P, polar decomposition)."""
    import numpy as np

    W = np.asarray(w, dtype=float)
    vals, vecs = np.linalg.eigh(W.T @ W)
    if np.any(vals <= 0):
        raise UnsupportedError("the soft-iron matrix is singular")
    return vecs @ np.diag(np.sqrt(vals)) @ vecs.T


# --- accelerometer ----------------------------------------------------------------------

def _accel_offsets_scales(cal: dict, meta: dict, fmt: str, ex: Export) -> tuple[list[float], list[float]]:
    """Per axis (offset m/s², scale) such that a = (a_fw - offset) * scale, a_fw in m/s²."""
    p, procedure = cal["params"], cal["procedure"]
    unit, k = _unit(meta, "accel_unit", "accel", fmt, procedure)
    if procedure == "accel-tabletop":
        B, M = _vec(p, "B"), _mat(p, "M")
        scales = [M[i][i] / k for i in range(3)]
        offsets = [-B[i] / scales[i] for i in range(3)]
        ex.note(f"from A = B + M V (P1) with V in {unit}: scale = M_ii / ({k:.6g} m/s^2 per {unit}), "
                "offset = -B_i / scale_i (sign flipped: the firmware subtracts it before scaling)")
        off_diag = max(abs(M[i][j] / M[i][i]) for i in range(3) for j in range(3) if i != j)
        ex.note(f"dropped: off-diagonal M_ij (cross-axis, largest |M_ij/M_ii| = {off_diag:.3g}); "
                "the firmware has no cross-axis accelerometer terms")
    elif procedure == "accel-centrifuge":
        S, b = _vec(p, "S"), _vec(p, "b")
        scales = [G_STANDARD_MPS2 / (k * S[i]) for i in range(3)]
        offsets = [k * b[i] for i in range(3)]
        ex.note(f"from N = S Phi [f + D f^2] + b (P2), f in g, N in {unit}: scale = g0 / (S_i * {k:.6g} m/s^2 per {unit}), "
                f"offset = b_i in m/s^2 (g0 = {G_STANDARD_MPS2} m/s^2, the firmware's)")
        dropped = ["D (second-order, g/g^2)"]
        if "gamma" in p:
            dropped.append("gamma (misalignment)")
        ex.note("dropped: " + ", ".join(dropped) + "; the firmware model is offset and scale only")
    else:
        raise AssertionError(procedure)
    return offsets, scales


# --- formats ----------------------------------------------------------------------------

def _ardupilot(cal: dict, meta: dict, instance: int) -> Export:
    ex = Export("#")
    procedure = cal["procedure"]
    n = "" if instance == 1 else str(instance)
    if procedure in ("accel-tabletop", "accel-centrifuge"):
        offsets, scales = _accel_offsets_scales(cal, meta, "ardupilot", ex)
        for i, a in enumerate(AXES):
            ex.set(f"INS_ACC{n}OFFS_{a}", offsets[i])
        for i, a in enumerate(AXES):
            ex.set(f"INS_ACC{n}SCAL_{a}", scales[i])
    elif procedure == "gyro-drift":
        unit, factor = _unit(meta, "gyro_unit", "gyro", "ardupilot", procedure)
        drift = _gyro_offsets_rad_s(cal, factor, ex)
        gyr = "GYRO" if instance == 1 else f"GYR{instance}"
        for i, a in enumerate(AXES):
            ex.set(f"INS_{gyr}OFFS_{a}", drift[i])
        ex.note("INS_GYROFFS = drift in rad/s, same sign (ArduPilot subtracts it); per raw axis gx, gy, gz")
        ex.note("ArduPilot re-estimates gyro offsets at every boot unless INS_GYR_CAL = 0")
    elif procedure == "compass":
        unit, nT_per_unit = _unit(meta, "mag_unit", "mag", "ardupilot", procedure)
        h, W = _vec(cal["params"], "hard_iron"), _mat(cal["params"], "soft_iron")
        c = nT_per_unit / 100.0  # milligauss per capture unit
        P = _symmetric_part([[w / (100.0 * c) for w in row] for row in W])
        suffix = "" if instance == 1 else str(instance)
        for i, a in enumerate(AXES):
            ex.set(f"COMPASS_OFS{suffix}_{a}", -c * h[i])
        for i, a in enumerate(AXES):
            ex.set(f"COMPASS_DIA{suffix}_{a}", P[i][i])
        for name, (i, j) in zip(AXES, ((0, 1), (0, 2), (1, 2))):
            ex.set(f"COMPASS_ODI{suffix}_{name}", P[i][j])
        ex.note(f"COMPASS_OFS = -hard_iron in milligauss (ArduPilot ADDS offsets); hard_iron was in {unit}")
        ex.note("COMPASS_DIA/ODI = symmetric part sqrtm(W^T W) of soft_iron, rescaled to map milligauss to milligauss; "
                "it gives the same |m| as the station's upper-triangular W (they differ by a rotation the field norm cannot see)")
    else:
        raise UnsupportedError(f"ardupilot: procedure '{procedure}' has no parameters in ArduPilot")
    return ex


def _px4(cal: dict, meta: dict, instance: int) -> Export:
    ex = Export("#")
    procedure = cal["procedure"]
    if procedure in ("accel-tabletop", "accel-centrifuge"):
        offsets, scales = _accel_offsets_scales(cal, meta, "px4", ex)
        for i, a in enumerate(AXES):
            ex.set(f"CAL_ACC{instance}_{a}OFF", offsets[i])
        for i, a in enumerate(AXES):
            ex.set(f"CAL_ACC{instance}_{a}SCALE", scales[i])
    elif procedure == "gyro-drift":
        _, factor = _unit(meta, "gyro_unit", "gyro", "px4", procedure)
        drift = _gyro_offsets_rad_s(cal, factor, ex)
        for i, a in enumerate(AXES):
            ex.set(f"CAL_GYRO{instance}_{a}OFF", drift[i])
        ex.note("CAL_GYRO_OFF = drift in rad/s, same sign (PX4 subtracts it); per raw axis gx, gy, gz")
    elif procedure == "compass":
        unit, nT_per_unit = _unit(meta, "mag_unit", "mag", "px4", procedure)
        h, W = _vec(cal["params"], "hard_iron"), _mat(cal["params"], "soft_iron")
        c = nT_per_unit / 1e5  # gauss per capture unit
        P = _symmetric_part([[w * 1e-5 / c for w in row] for row in W])
        for i, a in enumerate(AXES):
            ex.set(f"CAL_MAG{instance}_{a}OFF", c * h[i])
        for i, a in enumerate(AXES):
            ex.set(f"CAL_MAG{instance}_{a}SCALE", P[i][i])
        for name, (i, j) in zip(AXES, ((0, 1), (0, 2), (1, 2))):
            ex.set(f"CAL_MAG{instance}_{name}ODIAG", P[i][j])
        ex.note(f"CAL_MAG_OFF = hard_iron in gauss, same sign (PX4 subtracts it); hard_iron was in {unit}")
        ex.note("CAL_MAG_SCALE/ODIAG = symmetric part sqrtm(W^T W) of soft_iron, rescaled to map gauss to gauss; "
                "same |m| as the station's upper-triangular W (they differ by a rotation the field norm cannot see)")
    else:
        raise UnsupportedError(f"px4: procedure '{procedure}' has no parameters in PX4")
    return ex


def _header(cal: dict) -> list[str]:
    return [
        f"station calibration {cal['id']}: device {json.dumps(cal['device_id'], ensure_ascii=False)}, "
        f"{cal['procedure']}, {cal['time']}",
        f"record hash {cal.get('hash', '')}",
    ]


def _c_ident(name: str) -> str:
    ident = re.sub(r"[^0-9A-Za-z_]", "_", name)
    return ident if not ident[:1].isdigit() else "_" + ident


def _c_comment(text: str) -> str:
    return text.replace("*/", "* /").replace("\r", " ").replace("\n", " ")


def _c_string(text: str) -> str:
    out = []
    for ch in text:
        if ch in '\\"':
            out.append("\\" + ch)
        elif 32 <= ord(ch) < 127:
            out.append(ch)
        else:
            out.extend(f"\\x{b:02x}\"\"" for b in ch.encode("utf-8"))
    return '"' + "".join(out) + '"'


def _c_values(value) -> str | None:
    if isinstance(value, bool) or isinstance(value, str):
        return None
    if value is None:
        return "NAN"
    if isinstance(value, (int, float)):
        return repr(float(value))
    if isinstance(value, list):
        parts = [_c_values(v) for v in value]
        if any(p is None for p in parts):
            return None
        return "{" + ", ".join(parts) + "}"
    return None


def _dims(value) -> str:
    dims = ""
    while isinstance(value, list):
        dims += f"[{len(value)}]"
        value = value[0] if value else None
    return dims


def _c_header(cal: dict) -> str:
    guard = "STATION_CALIBRATION_" + str(cal["id"])
    prefix = "station_" + _c_ident(cal["procedure"]).lower()
    lines = [f"/* {_c_comment(line)} */" for line in _header(cal)]
    lines += [
        "/* values as stored (SI unless the name says otherwise; NAN = not determined) */",
        f"#ifndef {guard}_H",
        f"#define {guard}_H",
        "#include <math.h>",
        "",
        f"static const char {prefix}_device[] = {_c_string(cal['device_id'])};",
        f"static const long {prefix}_calibration_id = {int(cal['id'])};",
    ]

    def emit(obj, path):
        for key, value in obj.items():
            name = f"{path}_{_c_ident(key)}"
            if isinstance(value, dict):
                emit(value, name)
                continue
            text = _c_values(value)
            if text is None:
                if isinstance(value, str):
                    lines.append(f"static const char {name}[] = {_c_string(value)};")
                continue
            lines.append(f"static const double {name}{_dims(value)} = {text};")

    emit(cal["params"], prefix)
    emit({"sigma": cal["uncertainty"]}, prefix)
    if cal.get("residual_rms") is not None:
        lines.append(f"static const double {prefix}_residual_rms = {float(cal['residual_rms'])!r};")
    lines += ["", f"#endif /* {guard}_H */", ""]
    return "\n".join(lines)


def export(cal: dict, meta: dict, fmt: str, instance: int | None = None) -> str:
    """The text of calibration `cal` (a `Store.calibration` dict) in format `fmt`.

    `meta` is the stored capture's metadata (units). `instance` is the firmware's
    sensor slot: ArduPilot 1..3 (default 1), PX4 0..3 (default 0).
    """
    if fmt == "json":
        doc = {
            "calibration_id": cal["id"],
            "device": cal["device_id"],
            "time": cal["time"],
            "accepted": cal["accepted"],
            "software_version": cal.get("software_version"),
            "hash": cal.get("hash"),
            "result": cal["result"],
        }
        return json.dumps(doc, indent=2, ensure_ascii=False) + "\n"
    if fmt == "c-header":
        return _c_header(cal)
    if fmt == "ardupilot":
        instance = 1 if instance is None else instance
        if instance not in (1, 2, 3):
            raise UnsupportedError("ardupilot: --instance is 1, 2 or 3")
        ex = _ardupilot(cal, meta, instance)
        body = [f"{name},{value:.9g}" for name, value in ex.values]
    elif fmt == "px4":
        instance = 0 if instance is None else instance
        if instance not in (0, 1, 2, 3):
            raise UnsupportedError("px4: --instance is 0..3")
        ex = _px4(cal, meta, instance)
        body = [f"param set {name} {value:.9g}" for name, value in ex.values]
    else:
        raise UnsupportedError(f"unknown export format '{fmt}' (one of {', '.join(FORMATS)})")
    head = [f"# {_c_comment(line)}" for line in _header(cal)]
    head += [f"# converted: {_c_comment(n)}" for n in ex.notes]
    head += ["# offsets and scales apply in the sensor frame, before the board rotation"]
    head += [f"# calibration warning: {_c_comment(str(w))}" for w in cal.get("warnings") or []]
    return "\n".join(head + body) + "\n"
