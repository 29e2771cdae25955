"""Captures written from /work/shared/spec alone (capture-format.md, procedures.md), with a
known truth, for the spec conformance tests of tests/test_spec_conformance_s26.py.

Nothing here imports the station: the physics is the spec's equations, re-derived.
"""

from __future__ import annotations

import numpy as np

OMEGA_IE_RAD_S = 7.2921151e-5


def normal_gravity_mps2(lat_deg: float, alt_m: float) -> float:
    """WGS-84 Somigliana normal gravity with the usual free-air term [m/s^2]."""
    s2 = np.sin(np.radians(lat_deg)) ** 2
    g0 = 9.7803253359 * (1 + 0.00193185265241 * s2) / np.sqrt(1 - 0.00669437999013 * s2)
    return float(g0 - 3.086e-6 * alt_m)


def rot(axis: str, ang_rad: float) -> np.ndarray:
    c, s = np.cos(ang_rad), np.sin(ang_rad)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def render(
    meta: list[tuple[str, str]],
    columns: list[str],
    rows: list[list[object]],
    *,
    order: list[str] | None = None,
    crlf: bool = False,
    bom: bool = False,
    blank_after_meta: bool = False,
    comment_lines: list[str] = (),
    fmt: str = "{:.9g}",
) -> bytes:
    """The capture as bytes: metadata, header, rows (column order ``order`` if given)."""
    order = order or columns
    idx = [columns.index(c) for c in order]
    lines = ["# station-capture: 1"] + [f"# {k}: {v}" for k, v in meta] + [f"# {c}" for c in comment_lines]
    if blank_after_meta:
        lines.append("")
    lines.append(",".join(order))
    for r in rows:
        cells = []
        for i in idx:
            v = r[i]
            cells.append("" if v is None else (fmt.format(v) if isinstance(v, float) else str(v)))
        lines.append(",".join(cells))
    text = ("\r\n" if crlf else "\n").join(lines) + ("\r\n" if crlf else "\n")
    return (b"\xef\xbb\xbf" if bom else b"") + text.encode("utf-8")


# ---------------------------------------------------------------- P1
P1_B = np.array([0.12, -0.08, 0.05])  # m/s^2
P1_M = np.array([[4.00, 0.02, -0.015], [0.01, 3.90, 0.025], [-0.02, 0.015, 4.10]])  # (m/s^2)/V


def p1_directions(n_extra: int = 0) -> list[np.ndarray]:
    """The 12 gravity directions of P1 (body frame, unit 'up' vector), plus extras."""
    d = [np.eye(3)[i] * s for i in range(3) for s in (1, -1)]
    for a, b in ((0, 1), (1, 2), (0, 2)):  # XY, YZ, XZ planes at 45 and 135 deg
        for ang in (45.0, 135.0):
            v = np.zeros(3)
            v[a], v[b] = np.cos(np.radians(ang)), np.sin(np.radians(ang))
            d.append(v)
    rng = np.random.default_rng(7)
    for _ in range(n_extra):
        v = rng.normal(size=3)
        d.append(v / np.linalg.norm(v))
    return d


def p1_volts(g: float, dirs, rng, noise_v: float = 0.0) -> list[np.ndarray]:
    Minv = np.linalg.inv(P1_M)
    return [Minv @ (g * u - P1_B) + rng.normal(0, noise_v, 3) for u in dirs]


# ---------------------------------------------------------------- P2
P2_S = np.array([1.29, 1.21, 1.26])
P2_B = np.array([0.213, 0.256, 0.516])
P2_D = np.array([5.7e-5, 3.1e-5, 4.5e-5])


def p2_forces(g: float, radius_m: float, speeds, n_orient: int, rng):
    """(ω, specific force [g] in the body frame) for n_orient random orientations at each
    speed ω [rad/s]: centripetal A = ω²R/g along one table axis, gravity 1 g perpendicular."""
    out = []
    for w in speeds:
        A = w**2 * radius_m / g
        out += [(w, R @ np.array([A, 0.0, 1.0])) for R in random_rotations(n_orient, rng)]
    return out


def p2_output(f: np.ndarray) -> np.ndarray:
    return P2_S * (f + P2_D * f * f) + P2_B


def random_rotations(n: int, rng) -> list[np.ndarray]:
    out = []
    for _ in range(n):
        q = rng.normal(size=4)
        a, b, c, d = q / np.linalg.norm(q)
        out.append(
            np.array(
                [
                    [a * a + b * b - c * c - d * d, 2 * (b * c - a * d), 2 * (b * d + a * c)],
                    [2 * (b * c + a * d), a * a - b * b + c * c - d * d, 2 * (c * d - a * b)],
                    [2 * (b * d - a * c), 2 * (c * d + a * b), a * a - b * b - c * c + d * d],
                ]
            )
        )
    return out


# ---------------------------------------------------------------- P3
P3_W0 = np.array([[1.08, 0.04, -0.03], [0.0, 0.95, 0.05], [0.0, 0.0, 1.02]])  # dimensionless shape
P3_H0 = np.array([0.21, -0.13, 0.34])  # hard iron as a fraction of the field
NT_PER = {"nT": 1.0, "uT": 1e3, "gauss": 1e5, "µT": 1e3, "mgauss": 1e2, "counts": 1e5 / 1090.0}


def igrf_ned_nT(lat: float, lon: float, alt_m: float, date: str) -> np.ndarray:
    import datetime

    import ppigrf

    d = datetime.datetime.fromisoformat(date[:10])
    Be, Bn, Bu = ppigrf.igrf(lon, lat, alt_m / 1e3, d)
    return np.array([float(np.ravel(Bn)[0]), float(np.ravel(Be)[0]), -float(np.ravel(Bu)[0])])


def p3_raw(field_ned_nT, Rs, unit: str, g: float):
    """(m_raw in unit, accel in m/s^2) per orientation R (body->NED)."""
    k = NT_PER[unit]
    W = P3_W0 * k  # unit -> nT
    h = P3_H0 * np.linalg.norm(field_ned_nT) / k  # in unit
    Winv = np.linalg.inv(W)
    mags, accs = [], []
    for R in Rs:
        m_body = R.T @ field_ned_nT
        mags.append(Winv @ m_body + h)
        accs.append(R.T @ np.array([0.0, 0.0, -g]))
    return W, h, mags, accs


# ---------------------------------------------------------------- P4
P4_EPS = np.array([3.0e-4, -2.0e-4, 1.5e-4])  # rad/s


def p4_earth_rate_body(lat_deg: float, heading_deg: float, pitch_deg: float = 0.0, roll_deg: float = 0.0) -> np.ndarray:
    """Earth rate in body axes x forward, y up, z right (level unless pitch/roll given).

    Navigation frame north-up-east as procedures.md P4. Body from nav: yaw (heading, about
    up, clockwise from north seen from above), then pitch (about z right, nose up), then
    roll (about x forward, right side down)."""
    L = np.radians(lat_deg)
    w_n = OMEGA_IE_RAD_S * np.array([np.cos(L), np.sin(L), 0.0])
    psi = np.radians(heading_deg)
    # nav (N,U,E) -> body at heading psi, level: x = cos N + sin E, y = U, z = -sin N + cos E
    C_psi = np.array([[np.cos(psi), 0, np.sin(psi)], [0, 1, 0], [-np.sin(psi), 0, np.cos(psi)]])
    th, ga = np.radians(pitch_deg), np.radians(roll_deg)
    # pitch about z (right): nose up moves x toward y(up)
    C_th = np.array([[np.cos(th), np.sin(th), 0], [-np.sin(th), np.cos(th), 0], [0, 0, 1]])
    # roll about x, right side down: the body z (right) axis gets a component along -up
    C_ga = np.array([[1, 0, 0], [0, np.cos(ga), np.sin(ga)], [0, -np.sin(ga), np.cos(ga)]])
    C_nb = C_ga @ C_th @ C_psi
    return C_nb @ w_n, C_nb


# ---------------------------------------------------------------- P5
P5_DK = np.array([0.012, -0.008, 0.02])
P5_ANG_DEG = np.array([[30.0, 70.0, 69.0], [40.0, 120.0, 112.0], [35.0, 90.0, 125.0]])  # alpha, beta, gamma


def p5_dirs() -> np.ndarray:
    """Unit beam directions from (alpha, beta) with gamma completed so cos^2 sum to 1."""
    out = []
    for a, b, g in P5_ANG_DEG:
        ca, cb = np.cos(np.radians(a)), np.cos(np.radians(b))
        cg = np.sqrt(max(0.0, 1 - ca * ca - cb * cb)) * np.sign(np.cos(np.radians(g)))
        out.append([ca, cb, cg])
    return np.array(out)


def p5_true_angles_deg() -> np.ndarray:
    return np.degrees(np.arccos(p5_dirs()))


def p5_epochs(n: int, rng) -> np.ndarray:
    """Body-frame velocities with a spread of directions (turns, slopes, sideslip)."""
    v = np.column_stack([rng.uniform(2, 20, n), rng.uniform(-4, 4, n), rng.uniform(-3, 3, n)])
    return v


def p5_beams(vb: np.ndarray, rng, noise: float = 0.0) -> np.ndarray:
    d = p5_dirs()
    return (1 + P5_DK)[None, :] * (vb @ d.T) + rng.normal(0, noise, (len(vb), 3))


def c_b_n(roll_deg, pitch_deg, yaw_deg) -> np.ndarray:
    """Body (FRD) to NED, aerospace ZYX: C = Rz(yaw) Ry(pitch) Rx(roll)."""
    return rot("z", np.radians(yaw_deg)) @ rot("y", np.radians(pitch_deg)) @ rot("x", np.radians(roll_deg))
