"""Physical units of raw sensor columns: factors to SI (m/s², rad/s, nT, m/s)."""

from __future__ import annotations

import math

from solvers.frames import G_STANDARD_MPS2

# factor: value_in_unit * factor = value in SI (accel m/s², gyro rad/s, mag nT)
ACCEL_UNITS = {"g": G_STANDARD_MPS2, "m/s^2": 1.0, "mps2": 1.0, "mg": G_STANDARD_MPS2 / 1000.0}
GYRO_UNITS = {"rad/s": 1.0, "deg/s": math.pi / 180.0, "mrad/s": 1e-3, "deg/h": math.pi / 180.0 / 3600.0}
MAG_UNITS = {"nT": 1.0, "uT": 1e3, "gauss": 1e5, "G": 1e5, "mG": 1e2, "mgauss": 1e2}
RAW_UNITS = {"V", "mV", "counts"}  # no fixed physical factor: a calibration supplies it


def si_factor(kind: str, unit: str | None) -> float | None:
    """Factor from ``unit`` to SI for sensor ``kind`` ('accel', 'gyro', 'mag'); None if raw."""
    if unit is None:
        return None
    table = {"accel": ACCEL_UNITS, "gyro": GYRO_UNITS, "mag": MAG_UNITS}[kind]
    return table.get(unit)
