"""Static positions of the accelerometer procedures, as specific-force directions.

P1 (source 000): positions 1–6 put each axis up and down with the other two in the
table plane; positions 7–12 hold the XY, YZ and XZ planes vertical-ish with gravity at
45° and 135° between the plane's two axes. Each entry is the unit specific force in the
body frame (a perfect triad at rest reads ``g`` times it: the axis pointing up reads +g).
"""

from __future__ import annotations

import math

import numpy as np

from solvers.frames import rot_z, rotation_between

_S = math.sqrt(0.5)

P1_POSITIONS: dict[str, np.ndarray] = {
    "x_up": np.array([1.0, 0.0, 0.0]),
    "x_down": np.array([-1.0, 0.0, 0.0]),
    "y_up": np.array([0.0, 1.0, 0.0]),
    "y_down": np.array([0.0, -1.0, 0.0]),
    "z_up": np.array([0.0, 0.0, 1.0]),
    "z_down": np.array([0.0, 0.0, -1.0]),
    "xy_45": np.array([_S, _S, 0.0]),
    "xy_135": np.array([-_S, _S, 0.0]),
    "yz_45": np.array([0.0, _S, _S]),
    "yz_135": np.array([0.0, -_S, _S]),
    "xz_45": np.array([_S, 0.0, _S]),
    "xz_135": np.array([-_S, 0.0, _S]),
}

# What the operator is told for each position.
P1_INSTRUCTIONS: dict[str, str] = {
    "x_up": "+X face up (X axis pointing at the ceiling)",
    "x_down": "+X face down (X axis pointing at the table)",
    "y_up": "+Y face up",
    "y_down": "+Y face down",
    "z_up": "+Z face up (the usual way up)",
    "z_down": "+Z face down (upside down)",
    "xy_45": "Z axis level; X and Y both 45° above the table (use the 45° block)",
    "xy_135": "Z axis level; Y 45° up, X 45° down (135° from up)",
    "yz_45": "X axis level; Y and Z both 45° above the table",
    "yz_135": "X axis level; Z 45° up, Y 45° down",
    "xz_45": "Y axis level; X and Z both 45° above the table",
    "xz_135": "Y axis level; Z 45° up, X 45° down",
}


def C_n_b_for(f_dir_body, heading_rad: float = 0.0) -> np.ndarray:
    """An attitude (body → NED) at which the specific force reads along ``f_dir_body``.

    At rest the specific force in NED is ``(0, 0, −g)``; any heading about the vertical
    keeps it, so ``heading_rad`` picks one.
    """
    C_b_n0 = rotation_between([0.0, 0.0, -1.0], f_dir_body)
    return (C_b_n0 @ rot_z(heading_rad).T).T


def angle_between_deg(a, b) -> float:
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    c = float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))
