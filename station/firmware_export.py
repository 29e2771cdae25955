"""Stored calibrations in the forms flight firmwares and C code load.

Formats:
- `json`: the calibrate.md result plus its record (id, device, time, hash).
- `ardupilot`: a Mission Planner / MAVProxy `.param` file (`NAME,VALUE`, `#` comments).
- `px4`: NuttX shell `param set` lines.
- `qgc`: a QGroundControl `.params` file (PX4): `vehicle-id<TAB>component-id<TAB>name<TAB>value<TAB>type`,
  type 9 = MAV_PARAM_TYPE_REAL32, 6 = INT32.
- `c-header`: every scalar of the result as `float`, prefixed by the device, with the model and
  units stated.

What each firmware does with its parameters (read in its source; tests/test_firmware_export.py
lists the files and commits, README "Firmware parameters" links them):

| firmware | sensor | applied to driver output in the sensor frame | parameters (instance n) |
|---|---|---|---|
| ArduPilot | accel | `a = (a_drv - INS_ACCOFFS) * INS_ACCSCAL` (m/s^2), then the board rotation (`AP_InertialSensor_Backend::_rotate_and_correct_accel`) | `INS_ACC{,2,3}OFFS_X/Y/Z`, `INS_ACC{,2,3}SCAL_X/Y/Z`; IMUs 4, 5: `INS{4,5}_ACCOFFS_*`, `INS{4,5}_ACCSCAL_*` |
| ArduPilot | gyro | `w = w_drv - INS_GYROFFS` (rad/s) | `INS_GYROFFS_*`, `INS_GYR2OFFS_*`, `INS_GYR3OFFS_*`, `INS{4,5}_GYROFFS_*` |
| ArduPilot | compass | `m = [DIA/ODI] * (COMPASS_SCALE * (m_drv + COMPASS_OFS))` (mGauss, offsets ADDED; `AP_Compass_Backend::correct_field`) | `COMPASS_OFS{,2,3}_*`, `COMPASS_DIA{,2,3}_*`, `COMPASS_ODI{,2,3}_*` |
| PX4 | accel | `a = R * ((a_drv - CAL_ACCn_OFF) .* CAL_ACCn_SCALE)` (m/s^2; `calibration::Accelerometer::Correct`) | `CAL_ACCn_{X,Y,Z}OFF`, `CAL_ACCn_{X,Y,Z}SCALE`, `CAL_ACCn_ID`, `_PRIO`, `_ROT` |
| PX4 | gyro | `w = R * (w_drv - CAL_GYROn_OFF)` (rad/s) | `CAL_GYROn_{X,Y,Z}OFF`, `_ID`, `_PRIO`, `_ROT` |
| PX4 | mag | `m = R * (S * (m_drv - CAL_MAGn_OFF))` (gauss, subtracted), `S` symmetric from `SCALE`/`ODIAG` | `CAL_MAGn_{X,Y,Z}OFF`, `{X,Y,Z}SCALE`, `{X,Y,Z}ODIAG`, `_ID`, `_PRIO`, `_ROT` |

PX4 applies slot n only to the sensor whose device id is `CAL_*n_ID`: the export writes the
id (from the capture's `sensor_device_id`/`<kind>_device_id`, the parameters in use, or
`--device-id`) and refuses without one. `CAL_*n_PRIO` is left as PX4's own calibration leaves
it (ParametersUpdate, ParametersSave): the priority in use when the firmware accepts it (-1,
0..100; 0 = disabled stays 0), else the firmware's default for the sensor, 75 external, 50
internal, and -1 ("Uninitialized", which PX4 replaces by one of the two when it loads the slot)
where the capture cannot say which. External: the log's own `<kind>_external`
(sensor_mag.is_external), else `CAL_*n_ROT` in use (PX4 forces -1 on an internal sensor), else
the device id's bus type (`calibration::DeviceExternal`: UAVCAN, serial, MAVLink external,
simulation internal; I2C and SPI depend on the board). `CAL_*n_ROT` is written only as it is in
use: an external sensor's mounting is not in the data (a comment says to set it).

Data already corrected by the board (capture metadata `corrected: true`, `firmware`, and the
parameters in use as `param.<NAME>`): the fitted correction acts on top of the parameters in
use, and the export composes the new absolute parameters from both (accel:
`o = o_old + o_fit / s_old`, `s = s_old * s_fit`; gyro `o = o_old + o_fit`, `/ s_old` on an
older PX4 with gyro scales; compass through the matrices, below). It refuses, in one line,
when the parameters in use are not in the capture, when they come from another firmware, or
when a board rotation cannot be composed.

Board rotation (the corrected data are in the body frame; where the firmware applies its
parameters, below): the fitted correction is taken to that frame first. ArduPilot INS offsets
and scales act in the sensor frame before `AHRS_ORIENTATION` (`_rotate_and_correct_accel`,
`_rotate_and_correct_gyro`); its compass offsets and matrix act after the rotation to the body
frame (`rotate_field`, then `correct_field`), so they compose with no rotation at all. PX4 applies
`R = Dcm(SENS_BOARD_{X,Y,Z}_OFF) · rot` after its offsets, scales and matrix (`Correct()`), rot =
`SENS_BOARD_ROT` for an internal sensor (`CAL_*n_ROT` = -1), `CAL_*n_ROT` for an external one.
Gyro offsets and the PX4 magnetometer (full symmetric matrix) compose under any rotation; the
accelerometer's per-axis scales only under one that maps axes onto axes (whole 90° steps, no
level adjustment), unless the fitted scales are equal: otherwise one line refuses. Rotation
numbers: `ROTATIONS` (PX4 `rot_lookup[]`, ArduPilot `rotations.h`; custom ones refused).

Bounds the firmware enforces are checked before anything is written: ArduPilot accel
offsets within ±3.5 m/s^2 (the INS_ACCOFFS @Range and `_accel_max_abs_offsets`) and scales
0.8..1.2 (`AccelCalibrator::accept_result`, the INS_ACCSCAL @Range); compass offsets below
COMPASS_OFFS_MAX (in use, else its default 1800 mGauss), DIA within 0.2..5, |ODI| < 1, all
strict as `CompassCalibrator::fit_acceptable` tests them; PX4 accelerometer and magnetometer
scales within 0.1..3.0 (their min and max in PX4's parameter definitions, `module.yaml`).

Raw volts or counts and the LDV have no parameters in either firmware and are refused.
"""

from __future__ import annotations

import json
import math
import re

from solvers.units import si_factor
from station.errors import UnsupportedError
from station.procedures import registry

FORMATS = ("json", "ardupilot", "px4", "qgc", "c-header")
AXES = "XYZ"
ODIAG_PAIRS = ((0, 1), (0, 2), (1, 2))  # X, Y, Z off-diagonal: (row, col) of the symmetric matrix
AP_ACC_OFFS_MAX_MPS2 = 3.5
AP_ACC_SCALE_RANGE = (0.8, 1.2)
AP_COMPASS_OFFS_MAX_DEFAULT_MGAUSS = 1800.0
AP_COMPASS_DIA_RANGE = (0.2, 5.0)
AP_COMPASS_ODI_MAX = 1.0
# COMPASS_SCALE is applied only from COMPASS_MIN_SCALE_FACTOR to COMPASS_MAX_SCALE_FACTOR
# (AP_Compass.cpp Compass::have_scale_factor; CompassCalibrator.h 0.85, 1.4)
AP_COMPASS_SCALE_APPLIED = (0.85, 1.4)
# CAL_ACCn_{X,Y,Z}SCALE and CAL_MAGn_{X,Y,Z}SCALE: min 0.1, max 3.0 (PX4's parameter
# definitions, src/modules/sensors/module.yaml); the offsets and ODIAG have no documented range.
PX4_SCALE_RANGE = (0.1, 3.0)
INT32 = range(-(1 << 31), 1 << 31)  # an integer parameter's values
# calibration::{Accelerometer,Gyroscope,Magnetometer}: DEFAULT_PRIORITY (internal sensor),
# DEFAULT_EXTERNAL_PRIORITY; CAL_*n_PRIO -1 = "Uninitialized" (module.yaml), which
# ParametersUpdate() replaces with one of the two (no error); 0 = disabled, valid 0..100
PX4_DEFAULT_PRIORITY, PX4_DEFAULT_EXTERNAL_PRIORITY, PX4_PRIORITY_UNSET = 50, 75, -1
# PX4 device id (src/lib/drivers/device/Device.hpp DeviceStructure): bus_type in its low 3 bits;
# calibration::DeviceExternal (Utilities.cpp): UAVCAN, SERIAL, MAVLINK external, SIMULATION
# internal, I2C/SPI as the board's bus configuration says (not known here)
PX4_BUS_EXTERNAL = {3: True, 4: False, 5: True, 6: True}
# DeviceStructure {bus_type: 3, bus: 5, address: 8, devtype: 8} in a uint32 union: ids fit in 24 bits
# ("small enough to fit in a float accurately", Device.hpp), so a negative id or one above 2^24 - 1 is no sensor's
PX4_DEVICE_ID_MAX = (1 << 24) - 1
QGC_REAL32, QGC_INT32 = 9, 6  # MAV_PARAM_TYPE


class Export:
    """Lines of the exported file and the conversions made (said in its comments)."""

    def __init__(self, comment: str):
        self.comment = comment
        self.notes: list[str] = []
        self.warnings: list[str] = []
        self.values: list[tuple[str, float | int]] = []

    def note(self, text: str) -> None:
        self.notes.append(text)

    def warn(self, text: str) -> None:
        """A value written that the firmware takes but its documentation bounds: in the file, and on
        the command line's stderr (``warnings``)."""
        self.warnings.append(text)

    def set(self, name: str, value: float) -> None:
        if value is None or not math.isfinite(value):
            raise UnsupportedError(f"{name} would be {value}: the calibration has no finite value for it")
        self.values.append((name, float(value)))

    def set_int(self, name: str, value: int) -> None:
        value = int(value)
        if value not in INT32:  # PX4's CAL_*n_ID, _PRIO, _ROT (module.yaml: int32; QGC type 6)
            raise UnsupportedError(f"{name} = {value}: beyond the firmware's int32 parameter ({INT32[0]}..{INT32[-1]})")
        self.values.append((name, value))


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
        body = vector(cal["params"], "drift")
        offsets = [x * factor for x in vector(raw, "value")]
        if any(not math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-15) for a, b in zip(offsets, body)):
            ex.note("drift mapped back from P4's body frame (x fwd, y up, z right) to the sensor's gx gy gz")
        return offsets
    return vector(cal["params"], "drift")


def _set_gyro_offsets(
    cal: dict,
    meta: dict,
    fmt: str,
    ex: Export,
    use: InUse,
    off_names,
    label: str,
    R=None,
    rot_name=None,
    scale_names=(),
) -> None:
    """Set the firmware's gyro offsets ``off_names`` (rad/s, the sensor's axes): the drift,
    composed with the offsets in use when the board had corrected the data (``label`` names
    them in the note: OFF = OFF_in_use + drift), through the board rotation ``R`` (body ← the
    frame the offsets act in; None: identity) read from ``rot_name``, and the per-axis gyro
    scales in use ``scale_names`` where the firmware has them (older PX4: (w - OFF) * SCALE)."""
    _, factor = _unit(meta, "gyro_unit", "gyro", fmt, cal["procedure"])
    drift = _gyro_offsets_rad_s(cal, factor, ex)
    if use.corrected:
        o_old = use.need(off_names, "gyro offsets")
        s_old = [use.get(n) for n in scale_names]
        s_old = s_old if s_old and all(v is not None and v > 0 for v in s_old) else None
        drift = _compose_gyro(o_old, drift, R, s_old)
        if R is not None:
            ex.note(f"drift taken from the body frame to the sensor frame: R^T drift, R from {rot_name}")
        if s_old is not None and any(v != 1 for v in s_old):
            ex.note(f"composed with the parameters in use: {label} = {label}_in_use + drift / SCALE_in_use")
        else:
            ex.note(f"composed with the parameters in use: {label} = {label}_in_use + drift")
    for name, v in zip(off_names, drift):
        ex.set(name, v)


def vector(params: dict, name: str, n: int = 3) -> list[float]:
    """``params[name]`` as n floats (None → NaN); UnsupportedError when it is not an n-vector."""
    v = params.get(name)
    if not isinstance(v, list) or len(v) != n:
        raise UnsupportedError(f"the calibration has no {n}-vector '{name}'")
    return [float("nan") if x is None else float(x) for x in v]


def matrix(params: dict, name: str) -> list[list[float]]:
    """``params[name]`` as 3x3 floats (None → NaN); UnsupportedError when it is not 3x3."""
    m = params.get(name)
    if not isinstance(m, list) or len(m) != 3 or any(not isinstance(r, list) or len(r) != 3 for r in m):
        raise UnsupportedError(f"the calibration has no 3x3 matrix '{name}'")
    return [[float("nan") if x is None else float(x) for x in r] for r in m]


def _symmetric_part(w):
    """P = sqrtm(Wᵀ W): the symmetric matrix with |P x| = |W x| (W = Q P, polar decomposition)."""
    import numpy as np

    W = np.asarray(w, dtype=float)
    vals, vecs = np.linalg.eigh(W.T @ W)
    if np.any(vals <= 0):
        raise UnsupportedError("the soft-iron matrix is singular")
    return vecs @ np.diag(np.sqrt(vals)) @ vecs.T


# --- the parameters in use (capture metadata) --------------------------------------------


class InUse:
    """The firmware parameters a capture's data were corrected with (`param.<NAME>` metadata)."""

    def __init__(self, meta: dict | None, fmt: str, firmware: str):
        meta = meta or {}
        self.fmt, self.firmware = fmt, firmware
        self.corrected = str(meta.get("corrected", "")).strip().lower() in ("true", "1", "yes")
        self.source_firmware = str(meta.get("firmware", "")).strip().lower() or None
        self.params: dict[str, float] = {}
        # parameters the log saw change while its data ran (the importers' params_changed): the
        # data before and after were corrected with different values (ArduPilot's in-flight
        # compass learning, COMPASS_LEARN, changes COMPASS_OFS* mid-flight)
        self.changed = {n.strip() for n in str(meta.get("params_changed", "")).split(",") if n.strip()}
        for key, value in meta.items():
            if key.startswith("param."):
                try:
                    self.params[key[6:]] = float(value)
                except (TypeError, ValueError):
                    continue
        if self.corrected and self.source_firmware and self.source_firmware != firmware:
            other = "qgc or px4" if self.source_firmware == "px4" else self.source_firmware
            raise UnsupportedError(
                f"{fmt}: the capture's data were corrected by {self.source_firmware} parameters (corrected: true); "
                f"only --format {other} can compose absolute parameters from them"
            )

    def get(self, name: str) -> float | None:
        return self.params.get(name)

    def unchanged(self, names, what: str) -> None:
        """A one-line refusal when one of `names` changed while the capture's data were logged:
        no one value of it corrected them all, so nothing can be composed on it."""
        changed = [n for n in names if n in self.changed]
        if changed:
            raise UnsupportedError(
                f"{self.fmt}: {', '.join(changed)} changed while the capture's data were logged (params_changed; "
                f"e.g. in-flight compass learning): the data before and after were corrected with different "
                f"{what}, so no absolute parameters can be composed (import a log recorded with them unchanged)"
            )

    def need(self, names: list[str], what: str) -> list[float]:
        """The values of `names`, or a one-line refusal naming the first one missing (or changed
        during the data)."""
        self.unchanged(names, what)
        missing = [n for n in names if n not in self.params]
        if missing:
            raise UnsupportedError(
                f"{self.fmt}: the capture's data were already corrected by the board (corrected: true), but its "
                f"metadata hold no param.{missing[0]}: the {what} in use are unknown, so no absolute parameters "
                "can be composed (record over MAVLink, which reads them, or import the log that holds them)"
            )
        return [self.params[n] for n in names]

    def rotation(self, enum_name: str, ex: Export, level_names: tuple[str, ...] = ()):
        """The rotation R (body ← the frame the parameters act in) of the rotation parameters in
        use, or None when it is the identity; a note when they are not in the capture, a one-line
        refusal when the firmware's rotation cannot be known (custom, unknown number)."""
        import numpy as np

        names = (enum_name, *level_names)
        self.unchanged(names, "board rotations")
        missing = [n for n in names if n not in self.params]
        if missing:
            ex.note(f"assumed no board rotation ({', '.join(missing)} not in the capture)")
        value = self.params.get(enum_name)
        R = np.eye(3)
        if value is not None and value != -1:
            R = rotation_matrix(self.firmware, value, enum_name, self.fmt)
        # PX4's board level adjustment (Utilities.cpp GetSensorLevelAdjustment): Dcm(Euler(x, y, z deg)) first
        level = [self.params.get(n, 0.0) for n in level_names]
        if any(abs(v) > 1e-3 for v in level):  # PX4 SITL stores SENS_BOARD_X_OFF = 1e-6 deg
            R = _euler_dcm(*level) @ R
        return None if np.allclose(R, np.eye(3), atol=1e-9) else R


# Rotation enums: roll, pitch, yaw in degrees, R = Rz(yaw) Ry(pitch) Rx(roll) (the firmwares'
# Euler 3-2-1; PX4 src/lib/conversion/rotation.{h,cpp} get_rot_matrix and rot_lookup[]; ArduPilot
# libraries/AP_Math/rotations.h, the same names and numbers 0-40, then 41 PITCH_7, 42 ROLL_45,
# 43 ROLL_315; its 38 and CUSTOM (100, 101, 102) are left out: refused, not guessed).
_COMMON_ROT = (
    (0, 0, 0), (0, 0, 45), (0, 0, 90), (0, 0, 135), (0, 0, 180), (0, 0, 225), (0, 0, 270), (0, 0, 315),
    (180, 0, 0), (180, 0, 45), (180, 0, 90), (180, 0, 135), (0, 180, 0), (180, 0, 225), (180, 0, 270),
    (180, 0, 315), (90, 0, 0), (90, 0, 45), (90, 0, 90), (90, 0, 135), (270, 0, 0), (270, 0, 45),
    (270, 0, 90), (270, 0, 135), (0, 90, 0), (0, 270, 0), (0, 180, 90), (0, 180, 270), (90, 90, 0),
    (180, 90, 0), (270, 90, 0), (90, 180, 0), (270, 180, 0), (90, 270, 0), (180, 270, 0), (270, 270, 0),
    (90, 180, 90), (90, 0, 270), (90, 68, 293), (0, 315, 0), (90, 315, 0),
)  # fmt: skip
ROTATIONS = {
    "px4": dict(
        enumerate(
            _COMMON_ROT
            + ((270, 0, 180), (270, 0, 270), (0, 90, 180), (0, 9, 180), (0, 45, 0), (270, 0, 225), (270, 0, 315))
        )
    ),
    "ardupilot": {
        **{i: r for i, r in enumerate(_COMMON_ROT) if i != 38},
        41: (0, 7, 0),
        42: (45, 0, 0),
        43: (315, 0, 0),
    },
}


def _euler_dcm(roll_deg: float, pitch_deg: float, yaw_deg: float):
    from solvers.frames import rot_x, rot_y, rot_z

    return rot_z(math.radians(yaw_deg)) @ rot_y(math.radians(pitch_deg)) @ rot_x(math.radians(roll_deg))


def rotation_matrix(firmware: str, value: float, name: str, fmt: str):
    """The firmware's rotation ``value`` of parameter ``name`` as a matrix (body ← sensor)."""
    rpy = ROTATIONS[firmware].get(int(value)) if float(value).is_integer() else None
    if rpy is None:
        raise UnsupportedError(
            f"{fmt}: {name} = {value:g} is a rotation the station does not know (custom or unlisted): "
            "the corrected data cannot be taken back to the sensor frame; set it to a listed rotation or "
            "calibrate the raw sensor data"
        )
    return _euler_dcm(*rpy)


def _signed_permutation(R) -> bool:
    import numpy as np

    A = np.abs(np.asarray(R))
    return bool(
        np.allclose(np.sort(A, axis=1), [[0, 0, 1]] * 3, atol=1e-6) and np.allclose(A.sum(axis=0), 1, atol=1e-6)
    )


def _check_range(
    fmt: str, name: str, value: float, lo: float | None, hi: float | None, why: str, strict: bool = False
) -> None:
    """Refuse ``value`` outside lo..hi (``strict``: the bounds themselves too, as the firmware's
    test is ``lo < value < hi``)."""
    below = lo is not None and (value <= lo if strict else value < lo)
    above = hi is not None and (value >= hi if strict else value > hi)
    if not math.isfinite(value) or below or above:
        rng = (
            f"{lo:g}..{hi:g}" if lo is not None and hi is not None else (f"> {lo:g}" if lo is not None else f"< {hi:g}")
        )
        if strict and lo is not None and hi is not None:
            rng = f"strictly between {lo:g} and {hi:g}"
        raise UnsupportedError(
            f"{fmt}: {name} = {value:.6g} is outside what the firmware accepts ({rng}, {why}); nothing written"
        )


# --- accelerometer ----------------------------------------------------------------------


def _accel_offsets_scales(cal: dict, meta: dict, fmt: str, ex: Export) -> tuple[list[float], list[float]]:
    """Per axis (offset m/s², scale) such that a = (a_fw - offset) * scale, a_fw in m/s²."""
    procedure = cal["procedure"]
    unit, k = _unit(meta, "accel_unit", "accel", fmt, procedure)
    entry = registry.get(procedure)
    convert = getattr(entry.load(), "firmware_accel", None) if entry is not None else None
    if convert is None:
        raise UnsupportedError(f"{fmt}: procedure '{procedure}' has no accelerometer offsets and scales")
    offsets, scales, notes = convert(cal["params"], k, unit)  # the procedure module's conversion
    for line in notes:
        ex.note(line)
    return offsets, scales


# --- formats ----------------------------------------------------------------------------


def _kind(cal: dict, fmt: str, firmware: str) -> str:
    kind = registry.firmware_kind(cal["procedure"])
    if kind is None:
        raise UnsupportedError(f"{fmt}: procedure '{cal['procedure']}' has no parameters in {firmware}")
    return kind


def _device_id(meta: dict, kind: str) -> int | None:
    """The sensor's device id in the capture, None when unknown (0: no device, below)."""
    for key in (f"{kind}_device_id", "sensor_device_id"):
        v = (meta or {}).get(key)
        if v not in (None, ""):
            try:
                dev = int(float(v))
            except ValueError:
                continue
            if dev != 0:
                return dev
    return None


# ArduPilot's slots: IMUs 1-3 in AP_InertialSensor::var_info (INS_ACC*, INS_GYR*), IMUs 4 and 5
# in its subgroups "4_"/"5_" of AP_InertialSensor_Params (INS4_*, INS5_*, built where
# INS_MAX_INSTANCES > 3); compasses 1-3 alone (Compass::var_info: COMPASS_OFS, OFS2, OFS3)
AP_SLOTS = {"accel": (1, 2, 3, 4, 5), "gyro": (1, 2, 3, 4, 5), "mag": (1, 2, 3)}
# the documented @Range of COMPASS_OFS* (AP_Compass.cpp), narrower than what the firmware's own
# calibration stores (below COMPASS_OFFS_MAX)
AP_COMPASS_OFS_DOC_RANGE_MGAUSS = 400.0


def _ap_names(kind: str, n: int) -> dict:
    s = "" if n == 1 else str(n)
    if kind in ("accel", "gyro") and n > 3:  # AP_InertialSensor_Params: ACCSCAL, ACCOFFS, ACC_ID, GYROFFS, GYR_ID
        g = f"INS{n}_"
        if kind == "accel":
            return {
                "off": [f"{g}ACCOFFS_{a}" for a in AXES],
                "scale": [f"{g}ACCSCAL_{a}" for a in AXES],
                "id": f"{g}ACC_ID",
            }
        return {"off": [f"{g}GYROFFS_{a}" for a in AXES], "id": f"{g}GYR_ID"}
    if kind == "accel":
        return {
            "off": [f"INS_ACC{s}OFFS_{a}" for a in AXES],
            "scale": [f"INS_ACC{s}SCAL_{a}" for a in AXES],
            "id": f"INS_ACC{s}_ID",
        }
    if kind == "gyro":
        return {
            "off": [f"INS_GYR{s}OFFS_{a}" for a in AXES],  # INS_GYROFFS_X, INS_GYR2OFFS_X, ...
            "id": f"INS_GYR{s}_ID",
        }
    return {
        "off": [f"COMPASS_OFS{s}_{a}" for a in AXES],
        "dia": [f"COMPASS_DIA{s}_{a}" for a in AXES],
        "odi": [f"COMPASS_ODI{s}_{a}" for a in AXES],
        "scale": f"COMPASS_SCALE{s}",
        "id": f"COMPASS_DEV_ID{s}",
    }


def _px4_names(kind: str, i: int) -> dict:
    k = {"accel": "ACC", "gyro": "GYRO", "mag": "MAG"}[kind]
    out = {
        "off": [f"CAL_{k}{i}_{a}OFF" for a in AXES],
        "id": f"CAL_{k}{i}_ID",
        "prio": f"CAL_{k}{i}_PRIO",
        "rot": f"CAL_{k}{i}_ROT",
    }
    if kind in ("accel", "mag"):
        out["scale"] = [f"CAL_{k}{i}_{a}SCALE" for a in AXES]
    if kind == "mag":
        out["odiag"] = [f"CAL_{k}{i}_{a}ODIAG" for a in AXES]
    return out


def _px4_lacks(use: InUse, names: dict, name: str) -> bool:
    """Whether the firmware has no parameter ``name``: the capture holds the PX4 board's own
    calibration parameters (its log or MAVLink list: the slot's offsets are there) and not this
    one. Older PX4 releases have no CAL_*n_PRIO (CAL_*_PRIME instead) and no CAL_MAGn_*ODIAG;
    a `param set` of a name the firmware lacks fails and a QGroundControl file loads with errors."""
    return use.source_firmware == "px4" and names["off"][0] in use.params and name not in use.params


def _px4_external(meta: dict, kind: str, use: InUse, names: dict, device_id: int) -> bool | None:
    """Whether PX4 takes the sensor for an external one, None when the capture cannot say.

    In this order: the log's own flag (`<kind>_external`, sensor_mag.is_external); the slot's
    CAL_*n_ROT in use (PX4 forces -1 on an internal sensor, 0..40 on an external one:
    ParametersUpdate); the device id's bus type (calibration::DeviceExternal)."""
    flag = str((meta or {}).get(f"{kind}_external", "")).strip().lower()
    if flag in ("true", "false"):
        return flag == "true"
    rot = use.get(names["rot"])
    if rot is not None:
        return rot >= 0
    return PX4_BUS_EXTERNAL.get(int(device_id) & 0x7)


def _px4_priority_rotation(use: InUse, names: dict, external: bool | None, ex: Export) -> None:
    """CAL_*n_PRIO and CAL_*n_ROT as PX4's own calibration leaves them (ParametersUpdate, then
    ParametersSave): a priority in use that the firmware accepts (-1 or 0..100) is kept, an
    invalid or unknown one becomes the firmware's default for the sensor (75 external, 50
    internal; -1 "Uninitialized" when the capture cannot say which, so the firmware picks on
    load); the rotation in use is kept (as PX4 resets it where it contradicts the sensor: 0 for
    an external sensor's negative one, -1 for an internal sensor's), and none is made up (an
    external sensor's mounting is not in the data)."""
    prio, rot = use.get(names["prio"]), use.get(names["rot"])
    default = {True: PX4_DEFAULT_EXTERNAL_PRIORITY, False: PX4_DEFAULT_PRIORITY, None: PX4_PRIORITY_UNSET}[external]
    if _px4_lacks(use, names, names["prio"]):
        ex.note(f"{names['prio']} not written: the firmware's parameters in the capture have none (an older PX4)")
    elif prio is not None and (prio == PX4_PRIORITY_UNSET or 0 <= prio <= 100) and float(prio).is_integer():
        ex.set_int(names["prio"], int(prio))
        if prio == 0:
            ex.note(f"{names['prio']} = 0 as in use: the slot is disabled, PX4 will not use this sensor")
    else:
        ex.set_int(names["prio"], default)
        was = "not in the capture" if prio is None else f"{prio:g} in use is outside -1..100, which PX4 resets"
        if external is None:
            ex.note(
                f"{names['prio']} = -1 ({was}; nor does the capture say whether the sensor is external): PX4 "
                "replaces -1 (Uninitialized) with 75 for an external sensor, 50 for an internal one, when it loads it"
            )
        else:
            ex.note(
                f"{names['prio']} = {default} ({was}): PX4's default for an {'ex' if external else 'in'}ternal sensor"
            )
    if rot is not None:
        # ParametersUpdate resets an external sensor's negative ROT to 0 (none), an internal one's to -1
        fixed = 0 if external and rot < 0 else -1 if external is False and rot != -1 else int(rot)
        ex.set_int(names["rot"], fixed)
        if fixed != rot:
            where = "an external" if external else "an internal"
            ex.note(f"{names['rot']} = {fixed} for {rot:g} in use: what PX4 resets it to for {where} sensor")
    elif not _px4_lacks(use, names, names["rot"]):
        ex.note(
            f"{names['rot']} not written (not in use in the capture): "
            + (
                "set it to the external sensor's mounting rotation (PX4 takes one outside 0..40 as none)"
                if external
                else "-1 for an internal sensor (PX4's default), the mounting rotation for an external one"
            )
        )


def _slot(in_use: InUse, device_id: int | None, names, slots) -> int | None:
    """The slot whose `_ID` parameter in use holds `device_id` (the firmware's own lookup)."""
    if device_id is None:
        return None
    for n in slots:
        if in_use.get(names(n)["id"]) == device_id:
            return n
    return None


def _check_instance(asked: int | None, slot: int | None, dev: int | None, fmt: str, id_name) -> None:
    """Refuse an --instance other than the slot whose id in use is the sensor's, ``slot``: the
    firmware applies that slot to the sensor, and the one asked for holds another sensor's
    values (a composition with them is wrong, and writing the sensor's id there too leaves two
    slots claiming it, the other sensor uncalibrated)."""
    if asked is None:
        return
    if slot is not None and slot != asked:
        raise UnsupportedError(
            f"{fmt}: --instance {asked}, but the sensor (device id {dev}) is in slot {slot} ({id_name(slot)} in use): "
            f"the firmware applies that slot, and {id_name(asked)}'s values belong to another sensor; leave out "
            f"--instance (or give {slot})"
        )


def _sym(m) -> list[list[float]]:
    return [[float(x) for x in row] for row in m]


def _mag_fit(cal: dict, meta: dict, fmt: str, unit_per: float):
    """(A, c·h): the fitted compass correction on data in the firmware's unit U (mGauss or
    gauss): m_U = A (d_U − c h), A = W / (nT per U), from m_nT = W (d − h), d in mag_unit."""
    import numpy as np

    unit, nT_per_unit = _unit(meta, "mag_unit", "mag", fmt, cal["procedure"])
    h, W = vector(cal["params"], "hard_iron"), matrix(cal["params"], "soft_iron")
    c = nT_per_unit / unit_per  # firmware units per capture unit
    A = np.asarray(W, dtype=float) / (unit_per * c)
    return unit, A, c * np.asarray(h, dtype=float)


def _compose_gyro(o_old, drift, R, s_old=None) -> list[float]:
    """New offsets: the board gives ``R ((w − o_old) ∘ s_old)`` (s_old = 1 where the firmware has
    no gyro scales), the fit removes a body-frame drift ``d``: ``R ((w − o_old − (Rᵀ d) / s_old) ∘
    s_old)``, so ``o = o_old + (Rᵀ d) / s_old`` (any rotation)."""
    import numpy as np

    d = np.asarray(drift, dtype=float)
    if R is not None:
        d = R.T @ d
    if s_old is not None:
        d = d / np.asarray(s_old, dtype=float)
    return [float(o_old[i] + d[i]) for i in range(3)]


def _compose_accel(off, scale, o_old, s_old, R, fmt, rot_name, use, ex):
    """New (offsets, scales): the board gives ``R (s_old ∘ (a − o_old))``, the fit applies
    ``s_fit ∘ (x − o_fit)`` in the body frame. ``Rᵀ diag(s_fit) R`` is diagonal only when R maps
    axes onto axes (a signed permutation): then ``s = s_old ∘ |Rᵀ| s_fit``,
    ``o = o_old + (Rᵀ o_fit) / s_old``; else the firmware's per-axis scales cannot hold it."""
    import numpy as np

    o_fit, s_fit = np.asarray(off, dtype=float), np.asarray(scale, dtype=float)
    if R is not None:
        if not _signed_permutation(R):
            if np.ptp(s_fit) > 1e-6 * np.max(np.abs(s_fit)):
                value = use.get(rot_name)
                raise UnsupportedError(
                    f"{fmt}: the board rotation in use ({rot_name} = {value:g}"
                    f"{', with the SENS_BOARD_*_OFF level adjustment' if fmt == 'px4' else ''}) mixes the sensor's "
                    "axes: the fitted per-axis scales, in the body frame, are not per-axis scales in the sensor frame "
                    "where the firmware applies them; calibrate the raw sensor data (or a board rotation of whole "
                    "90° steps)"
                )
        o_fit = R.T @ o_fit
        if _signed_permutation(R):  # Rᵀ diag(s) R = diag(|Rᵀ| s); for equal scales it is s I under any R
            s_fit = np.abs(R.T) @ s_fit
    return (
        [float(o_old[i] + o_fit[i] / s_old[i]) for i in range(3)],
        [float(s_old[i] * s_fit[i]) for i in range(3)],
    )


def _ap_diagonal_in_use(names: list[str], values: list[float], what: str, where: str, fmt: str) -> list[float]:
    """ArduPilot's reading of a diagonal in use (INS_ACCSCAL_*, COMPASS_DIA_*): all three zero
    (never set: AP_Param has no non-zero vector default) are taken as 1, 1, 1
    (`if (....is_zero()) set(Vector3f(1,1,1))` in AP_InertialSensor::init and
    AP_Compass_Backend::correct_field); a partly zero one is used as it is, so the board's data
    were multiplied by 0 on that axis: a broken calibration, refused in one line, never read as 1."""
    if all(v == 0 for v in values):
        return [1.0, 1.0, 1.0]
    zero = [n for n, v in zip(names, values) if v == 0]
    if zero:
        rest = ", ".join(f"{n} = {v:g}" for n, v in zip(names, values) if v != 0)
        raise UnsupportedError(
            f"{fmt}: {' and '.join(zero)} = 0 in use beside {rest}: ArduPilot takes the {what} as 1 only when "
            f"all three are 0 ({where}), so the board multiplied that axis by 0, a broken calibration in use; "
            "nothing can be composed on it (calibrate data the board has not corrected)"
        )
    return list(values)


def _ardupilot(cal: dict, meta: dict, instance: int | None, ex: Export) -> None:
    import numpy as np

    fmt = "ardupilot"
    kind = _kind(cal, fmt, "ArduPilot")
    use = InUse(meta, fmt, "ardupilot")
    dev = _device_id(meta, kind)
    slots = AP_SLOTS[kind]
    what = "compasses" if kind == "mag" else "IMUs"
    if instance is not None and instance not in slots:
        raise UnsupportedError(
            f"{fmt}: --instance {instance}: ArduPilot's parameters hold {what} {slots[0]}-{slots[-1]} "
            + ("(COMPASS_OFS, COMPASS_OFS2, COMPASS_OFS3)" if kind == "mag" else "(INS_, INS2-3, INS4_/INS5_)")
        )
    slot = _slot(use, dev, lambda k: _ap_names(kind, k), slots)
    _check_instance(instance, slot, dev, fmt, lambda k: _ap_names(kind, k)["id"])
    n = instance or slot
    if n is None:
        si = (meta or {}).get("sensor_instance")
        n = int(si) + 1 if si not in (None, "") and use.source_firmware == "ardupilot" else 1
        if n not in slots:  # the log's sensor has no slot: never another sensor's by default
            raise UnsupportedError(
                f"{fmt}: the capture's sensor is ArduPilot's {'compass instance' if kind == 'mag' else 'IMU instance'} {n - 1} "
                f"(sensor_instance), and ArduPilot's parameters hold {what} {slots[0]}-{slots[-1]} only: "
                "no slot to write; nothing written"
            )
    names = _ap_names(kind, n)
    if n > 3:
        ex.note(
            f"{names['id'][:5]} parameters exist in firmware built for more than {n - 1} IMUs "
            "(INS_MAX_INSTANCES, AP_InertialSensor_Params)"
        )
    # INS offsets and scales act in the sensor frame, before AHRS_ORIENTATION
    # (_rotate_and_correct_accel/_gyro); the compass's after its rotation to the body frame
    # (AP_Compass_Backend: rotate_field, then correct_field), so it needs none
    R = use.rotation("AHRS_ORIENTATION", ex) if use.corrected and kind != "mag" else None
    if kind == "accel":
        off, scale = _accel_offsets_scales(cal, meta, fmt, ex)
        if use.corrected:
            o_old = use.need(names["off"], "accelerometer offsets")
            s_old = use.need(names["scale"], "accelerometer scales")
            s_old = _ap_diagonal_in_use(names["scale"], s_old, "accelerometer scales", "AP_InertialSensor::init", fmt)
            off, scale = _compose_accel(off, scale, o_old, s_old, R, fmt, "AHRS_ORIENTATION", use, ex)
            ex.note(
                "composed with the parameters in use: OFFS = OFFS_in_use + OFFS_fit / SCAL_in_use, "
                "SCAL = SCAL_in_use * SCAL_fit"
                + (
                    ""
                    if R is None
                    else " (fit taken from the body frame to the sensor frame: R^T OFFS_fit, R^T SCAL_fit R)"
                )
            )
        for name, v in zip(names["off"], off):
            _check_range(fmt, name, v, -AP_ACC_OFFS_MAX_MPS2, AP_ACC_OFFS_MAX_MPS2, "INS_ACCOFFS @Range")
        for name, v in zip(names["scale"], scale):
            _check_range(fmt, name, v, *AP_ACC_SCALE_RANGE, "AccelCalibrator::accept_result")
        for name, v in zip(names["off"], off):
            ex.set(name, v)
        for name, v in zip(names["scale"], scale):
            ex.set(name, v)
    elif kind == "gyro":
        _set_gyro_offsets(cal, meta, fmt, ex, use, names["off"], "GYROFFS", R, "AHRS_ORIENTATION")
        ex.note(f"{names['off'][0][:-2]} = drift in rad/s, same sign (ArduPilot subtracts it); per raw axis gx, gy, gz")
        ex.note("ArduPilot re-estimates gyro offsets at every boot unless INS_GYR_CAL = 0")
    else:
        unit, A, ch = _mag_fit(cal, meta, fmt, 100.0)  # nT per mGauss
        ofs = -ch
        if use.corrected:
            o_old = np.asarray(use.need(names["off"], "compass offsets"))
            dia = use.need(names["dia"], "compass soft-iron diagonal")
            odi = use.need(names["odi"], "compass soft-iron off-diagonal")
            dia = _ap_diagonal_in_use(
                names["dia"], dia, "compass soft-iron diagonal", "AP_Compass_Backend::correct_field", fmt
            )
            P_old = np.diag(dia)
            for v, (i, j) in zip(odi, ODIAG_PAIRS):
                P_old[i, j] = P_old[j, i] = v
            use.unchanged([names["scale"]], "compass scale factors")
            sf = use.get(names["scale"]) or 0.0
            if not AP_COMPASS_SCALE_APPLIED[0] <= sf <= AP_COMPASS_SCALE_APPLIED[1]:
                # Compass::have_scale_factor: 0 (no scaling, its default) or any value outside is not applied
                if sf != 0:
                    ex.note(
                        f"{names['scale']} = {sf:g} in use is outside {AP_COMPASS_SCALE_APPLIED[0]:g}.."
                        f"{AP_COMPASS_SCALE_APPLIED[1]:g}: ArduPilot does not apply it (Compass::have_scale_factor)"
                    )
                sf = 1.0
            P_eff = sf * P_old
            # m = A (P_eff (r + o_old) − c h) = A P_eff (r + o_old − P_eff⁻¹ c h)
            ofs = o_old - np.linalg.solve(P_eff, ch)
            A = A @ P_eff / sf  # the firmware keeps multiplying by COMPASS_SCALE in use
            ex.note(
                "composed with the parameters in use: DIA/ODI = symmetric part of (fit matrix x matrix in use), "
                "OFS = OFS_in_use - (matrix in use)^-1 * hard_iron"
            )
        P = _symmetric_part(A)
        offs_max = use.get("COMPASS_OFFS_MAX") or AP_COMPASS_OFFS_MAX_DEFAULT_MGAUSS
        # CompassCalibrator::fit_acceptable: |offset| < COMPASS_OFFS_MAX, 0.2 < diag < 5, |offdiag| < 1
        for name, v in zip(names["off"], ofs):
            _check_range(fmt, name, v, -offs_max, offs_max, "COMPASS_OFFS_MAX", strict=True)
        beyond = [f"{name} = {v:.1f}" for name, v in zip(names["off"], ofs) if abs(v) > AP_COMPASS_OFS_DOC_RANGE_MGAUSS]
        if beyond:
            # written, as ArduPilot's own calibration writes them (below COMPASS_OFFS_MAX), and said
            ex.warn(
                f"{', '.join(beyond)} mGauss: beyond the documented @Range -{AP_COMPASS_OFS_DOC_RANGE_MGAUSS:g}.."
                f"{AP_COMPASS_OFS_DOC_RANGE_MGAUSS:g} (AP_Compass.cpp), within COMPASS_OFFS_MAX ({offs_max:g}), "
                "as the firmware's own calibration accepts it; a ground station may flag it on loading, and an offset "
                "this large often means magnetised or current-carrying parts near the compass"
            )
        for name, i in zip(names["dia"], range(3)):
            _check_range(fmt, name, P[i, i], *AP_COMPASS_DIA_RANGE, "CompassCalibrator::fit_acceptable", strict=True)
        for name, (i, j) in zip(names["odi"], ODIAG_PAIRS):
            _check_range(
                fmt,
                name,
                P[i, j],
                -AP_COMPASS_ODI_MAX,
                AP_COMPASS_ODI_MAX,
                "CompassCalibrator::fit_acceptable",
                strict=True,
            )
        for name, v in zip(names["off"], ofs):
            ex.set(name, v)
        for name, i in zip(names["dia"], range(3)):
            ex.set(name, P[i, i])
        for name, (i, j) in zip(names["odi"], ODIAG_PAIRS):
            ex.set(name, P[i, j])
        ex.note(f"COMPASS_OFS = -hard_iron in milligauss (ArduPilot ADDS offsets); hard_iron was in {unit}")
        ex.note(
            "COMPASS_DIA/ODI = symmetric part sqrtm(W^T W) of soft_iron, rescaled to map milligauss to milligauss; "
            "it gives the same |m| as the station's upper-triangular W (they differ by a rotation the field norm cannot see)"
        )


def _px4_only_slot(use: InUse, kind: str, dev: int | None) -> int:
    """The slot for a sensor the capture does not name: the one CAL_*n_ID in use, else 0 (a board
    without the parameters). Two or more in use and no device id (a PX4 log before
    sensor_selection, whose sensor_combined carries the sensor the voter chose): refused in one
    line, never slot 0 by default."""
    ids = {n: use.get(_px4_names(kind, n)["id"]) for n in range(4)}
    ids = {n: int(v) for n, v in ids.items() if v}
    if dev is None and len(ids) > 1:
        listed = " and ".join(f"{_px4_names(kind, n)['id']} = {v}" for n, v in ids.items())
        raise UnsupportedError(
            f"px4: which {kind} the data came from is unknown ({listed} in use, the capture names neither): "
            "give --instance N (the slot) or --device-id"
        )
    return next(iter(ids)) if len(ids) == 1 and dev is None else 0


def _px4(cal: dict, meta: dict, instance: int | None, device_id: int | None, ex: Export) -> None:
    import numpy as np

    fmt = "px4"
    kind = _kind(cal, fmt, "PX4")
    use = InUse(meta, fmt, "px4")
    if device_id == 0:
        # PX4 takes CAL_*n_ID = 0 for a free slot: no sensor ever matches it
        # (calibration::FindCurrentCalibrationIndex returns -1 for device id 0)
        raise UnsupportedError(
            f"px4: --device-id 0 is no sensor: PX4 applies {_px4_names(kind, 0)['id'][:-4]}n_* only to the sensor "
            f"whose device id CAL_*n_ID holds, and 0 marks a free slot; give the device_id of the board's sensor_{kind}"
        )
    dev = device_id if device_id is not None else _device_id(meta, kind)
    slot = _slot(use, dev, lambda k: _px4_names(kind, k), (0, 1, 2, 3))
    _check_instance(instance, slot, dev, fmt, lambda k: _px4_names(kind, k)["id"])
    i = instance if instance is not None else slot
    if i is None:
        si = (meta or {}).get("sensor_instance")
        i = int(si) if si not in (None, "") and use.source_firmware == "px4" and 0 <= int(si) <= 3 else None
    if i is None:
        i = _px4_only_slot(use, kind, dev)
    names = _px4_names(kind, i)
    if dev is None:
        dev_in_use = use.get(names["id"])
        dev = int(dev_in_use) if dev_in_use else None
    if dev is None:
        raise UnsupportedError(
            f"px4: the sensor's device id is unknown (no {kind}_device_id or sensor_device_id in the capture, no "
            f"{names['id']} in use): PX4 applies {names['id'][:-3]}_* only to the sensor whose device id is "
            f"{names['id']}; give --device-id (the device_id of the board's sensor_{kind})"
        )
    external = _px4_external(meta, kind, use, names, dev)
    R = rot_name = None
    if use.corrected:
        # Correct(): R · (...), R = level adjustment · rotation; the rotation is CAL_*n_ROT for an
        # external sensor (ROT ≥ 0; PX4 takes one outside 0..40 as none), SENS_BOARD_ROT for an
        # internal one (ROT = -1)
        rot_name = names["rot"] if external else "SENS_BOARD_ROT"
        R = use.rotation(rot_name, ex, ("SENS_BOARD_X_OFF", "SENS_BOARD_Y_OFF", "SENS_BOARD_Z_OFF"))
    ex.set_int(names["id"], dev)  # an int32 parameter first
    if not 1 <= dev <= PX4_DEVICE_ID_MAX:
        # DeviceStructure packs bus type, bus, address and devtype in its low 24 bits: no sensor has another id
        raise UnsupportedError(
            f"px4: {names['id']} = {dev} is no PX4 sensor's device id (bus type, bus, address and device type make "
            f"one of 1..{PX4_DEVICE_ID_MAX}): the slot would match no sensor; give the device_id of the board's "
            f"sensor_{kind}"
        )
    _px4_priority_rotation(use, names, external, ex)
    if not (use.source_firmware == "px4" and names["off"][0] in use.params):
        # v1.11 (the CubeOrange log) has CAL_*n_EN, no _PRIO, no CAL_MAGn_*ODIAG; v1.12 brought both
        ex.note(
            "names of PX4 v1.12 and later (CAL_*n_PRIO, CAL_MAGn_*ODIAG): the capture holds no parameter list of the "
            "board, so its version is unknown; for an older PX4 export a capture recorded from it (its log, MAVLink)"
        )
    if kind == "accel":
        off, scale = _accel_offsets_scales(cal, meta, fmt, ex)
        if use.corrected:
            o_old = use.need(names["off"], "accelerometer offsets")
            s_old = use.need(names["scale"], "accelerometer scales")
            off, scale = _compose_accel(off, scale, o_old, s_old, R, fmt, rot_name, use, ex)
            ex.note(
                "composed with the parameters in use: OFF = OFF_in_use + OFF_fit / SCALE_in_use, "
                "SCALE = SCALE_in_use * SCALE_fit"
                + (
                    ""
                    if R is None
                    else " (fit taken from the body frame to the sensor frame: R^T OFF_fit, R^T SCALE_fit R)"
                )
            )
        for name, v in zip(names["scale"], scale):
            _check_range(fmt, name, v, *PX4_SCALE_RANGE, "its min and max in PX4's parameter definitions")
        for name, v in zip(names["off"], off):
            ex.set(name, v)
        for name, v in zip(names["scale"], scale):
            ex.set(name, v)
    elif kind == "gyro":
        # older PX4 (CAL_GYROn_xSCALE, e.g. sample.ulg's list) applied (w - OFF) * SCALE in the driver
        gyro_scales = [f"{names['off'][i][:-3]}SCALE" for i in range(3)]
        _set_gyro_offsets(cal, meta, fmt, ex, use, names["off"], "OFF", R, rot_name, gyro_scales)
        ex.note("CAL_GYRO_OFF = drift in rad/s, same sign (PX4 subtracts it); per raw axis gx, gy, gz")
    else:
        unit, A, ch = _mag_fit(cal, meta, fmt, 1e5)  # nT per gauss
        off = ch
        if use.corrected:
            o_old = np.asarray(use.need(names["off"], "magnetometer offsets"))
            dia = use.need(names["scale"], "magnetometer scales")
            odi = [use.get(n) or 0.0 for n in names["odiag"]]  # absent before PX4 v1.12: no off-diagonal
            S_old = np.diag(dia)
            for v, (r, c) in zip(odi, ODIAG_PAIRS):
                S_old[r, c] = S_old[c, r] = v
            # m = A (R S_old (r − o_old) − c h) = R (Rᵀ A R) S_old (r − o_old − S_old⁻¹ Rᵀ c h)
            Rm = np.eye(3) if R is None else R
            off = o_old + np.linalg.solve(S_old, Rm.T @ ch)
            A = Rm.T @ A @ Rm @ S_old
            if R is not None:
                ex.note(
                    f"fit taken from the body frame to the sensor frame with R from {rot_name}: R^T A R, R^T hard_iron"
                )
            ex.note(
                "composed with the parameters in use: SCALE/ODIAG = symmetric part of (fit matrix x matrix in use), "
                "OFF = OFF_in_use + (matrix in use)^-1 * hard_iron"
            )
        P = _symmetric_part(A)
        for name, k in zip(names["scale"], range(3)):
            _check_range(fmt, name, P[k, k], *PX4_SCALE_RANGE, "its min and max in PX4's parameter definitions")
        for name, v in zip(names["off"], off):
            ex.set(name, v)
        for name, k in zip(names["scale"], range(3)):
            ex.set(name, P[k, k])
        if _px4_lacks(use, names, names["odiag"][0]):
            ex.note(
                f"{names['odiag'][0][:-6]}*ODIAG not written: the firmware's parameters in the capture have none (an "
                f"older PX4, diagonal scales only); dropped off-diagonal, largest |{max(abs(P[r, c]) for r, c in ODIAG_PAIRS):.3g}|"
            )
        else:
            for name, (r, c) in zip(names["odiag"], ODIAG_PAIRS):
                ex.set(name, P[r, c])
        ex.note(f"CAL_MAG_OFF = hard_iron in gauss, same sign (PX4 subtracts it); hard_iron was in {unit}")
        ex.note(
            "CAL_MAG_SCALE/ODIAG = symmetric part sqrtm(W^T W) of soft_iron, rescaled to map gauss to gauss; "
            "same |m| as the station's upper-triangular W (they differ by a rotation the field norm cannot see)"
        )
    if kind == "accel":
        ex.note(
            "PX4 takes a new CAL_ACC offset or scale only when it differs from the one in use by more than "
            "0.01 (vector length; Accelerometer::set_offset/set_scale)"
        )


def _header(cal: dict) -> list[str]:
    return [
        f"station calibration {cal['id']}: device {json.dumps(cal['device_id'], ensure_ascii=False)}, "
        f"{cal['procedure']}, {cal['time']}",
        f"record hash {cal.get('hash', '')}",
        f"station anchor {cal.get('anchor') or '-'} (`station verify --anchor HASH` checks the record still holds it)",
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
            out.extend(f'\\x{b:02x}""' for b in ch.encode("utf-8"))
    return '"' + "".join(out) + '"'


def _c_float(x: float) -> str:
    """A float literal that gives back the float32 nearest to x (9 significant digits)."""
    if not math.isfinite(x):
        return "NAN" if x != x else ("INFINITY" if x > 0 else "-INFINITY")
    text = f"{x:.9g}"
    if "e" not in text and "." not in text:
        text += ".0"
    return text + "f"


def _c_values(value) -> str | None:
    if isinstance(value, bool) or isinstance(value, str):
        return None
    if value is None:
        return "NAN"
    if isinstance(value, (int, float)):
        return _c_float(float(value))
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


def _c_header(cal: dict, meta: dict | None = None) -> str:
    meta = meta or {}
    guard = "STATION_CALIBRATION_" + str(cal["id"])
    prefix = (_c_ident(str(cal["device_id"])).strip("_") or "device").lower() + "_" + _c_ident(cal["procedure"]).lower()
    prefix = _c_ident(prefix)
    entry = registry.get(cal["procedure"])
    units = (entry.units_note if entry is not None else registry.Procedure.units_note).format(
        accel_unit=meta.get("accel_unit", "?"), mag_unit=meta.get("mag_unit", "?")
    )
    lines = [f"/* {_c_comment(line)} */" for line in _header(cal)]
    lines += [
        f"/* model: {_c_comment(str(cal.get('model') or cal['procedure']))} */",
        f"/* units: {_c_comment(units)} */",
        "/* float (single precision, as flight firmwares keep them); NAN = not determined; matrices are rows */",
        f"#ifndef {guard}_H",
        f"#define {guard}_H",
        "#include <math.h>",
        "",
        f"static const char {prefix}_device[] = {_c_string(str(cal['device_id']))};",
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
            lines.append(f"static const float {name}{_dims(value)} = {text};")

    emit(cal["params"], prefix)
    emit({"sigma": cal["uncertainty"]}, prefix)
    if cal.get("residual_rms") is not None:
        lines.append(f"static const float {prefix}_residual_rms = {_c_float(float(cal['residual_rms']))};")
    lines += ["", f"#endif /* {guard}_H */", ""]
    return "\n".join(lines)


def export(
    cal: dict,
    meta: dict,
    fmt: str,
    instance: int | None = None,
    device_id: int | None = None,
    vehicle: tuple[int, int] = (1, 1),
) -> str:
    """The text of calibration `cal` (a `Store.calibration` dict) in format `fmt`.

    `meta` is the stored capture's metadata (units; for data the board had already corrected,
    `corrected`, `firmware` and the parameters in use as `param.<NAME>`). `instance` is the
    firmware's sensor slot: ArduPilot 1..3, PX4 0..3 (default: the slot whose `_ID` in use
    holds the capture's sensor device id, else 1 / 0). `device_id` is PX4's `CAL_*n_ID` when
    the capture does not say it. `vehicle` is the QGroundControl file's (system, component).
    """
    if fmt == "json":
        doc = {
            "calibration_id": cal["id"],
            "device": cal["device_id"],
            "time": cal["time"],
            "accepted": cal["accepted"],
            "software_version": cal.get("software_version"),
            "hash": cal.get("hash"),
            "anchor": cal.get("anchor"),
            "result": cal["result"],
        }
        return json.dumps(doc, indent=2, ensure_ascii=False) + "\n"
    if fmt == "c-header":
        return _c_header(cal, meta)
    ex = Export("#")
    if fmt == "ardupilot":
        if instance is not None and instance not in (1, 2, 3, 4, 5):
            raise UnsupportedError("ardupilot: --instance is 1 to 5 (IMUs; compasses 1 to 3)")
        _ardupilot(cal, meta, instance, ex)
        body = [f"{name},{value:.9g}" if isinstance(value, float) else f"{name},{value}" for name, value in ex.values]
    elif fmt in ("px4", "qgc"):
        if instance is not None and instance not in (0, 1, 2, 3):
            raise UnsupportedError(f"{fmt}: --instance is 0..3")
        _px4(cal, meta, instance, device_id, ex)
        if fmt == "px4":
            body = [
                f"param set {name} {value:.9g}" if isinstance(value, float) else f"param set {name} {value}"
                for name, value in ex.values
            ]
        else:
            sysid, compid = vehicle
            body = ["# Vehicle-Id Component-Id Name Value Type"]
            body += [
                f"{sysid}\t{compid}\t{name}\t{value:.9g}\t{QGC_REAL32}"
                if isinstance(value, float)
                else f"{sysid}\t{compid}\t{name}\t{value}\t{QGC_INT32}"
                for name, value in ex.values
            ]
    else:
        raise UnsupportedError(f"unknown export format '{fmt}' (one of {', '.join(FORMATS)})")
    head = [f"# {_c_comment(line)}" for line in _header(cal)]
    head += [f"# converted: {_c_comment(n)}" for n in ex.notes]
    head += [f"# warning: {_c_comment(w)}" for w in ex.warnings]
    if fmt == "ardupilot" and registry.firmware_kind(cal["procedure"]) == "mag":
        # AP_Compass_Backend::accumulate_sample: rotate_field (to the body frame), then correct_field
        head += ["# offsets and matrix apply in the body frame, after the compass's rotation (ArduPilot compass)"]
    else:
        head += ["# offsets and scales apply in the sensor frame, before the board rotation"]
    head += [f"# calibration warning: {_c_comment(str(w))}" for w in cal.get("warnings") or []]
    return "\n".join(head + body) + "\n"
