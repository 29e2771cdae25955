"""Hand-built calibration results (calibrate.md shape) and small captures for the db tests."""

from __future__ import annotations

import sqlite3

import numpy as np


def accel_result(device="IMU-1", B=(0.1, -0.2, 0.3), M=None, sigma_B=0.01, sigma_M=0.001, **extra) -> dict:
    M = np.eye(3).tolist() if M is None else [list(map(float, r)) for r in M]
    out = {
        "procedure": "accel-tabletop",
        "device": device,
        "model": "A = B + M V",
        "params": {"B": [float(b) for b in B], "M": M},
        "uncertainty": {"B": [sigma_B] * 3, "M": [[sigma_M] * 3 for _ in range(3)]},
        "residual_rms": 0.01,
        "n_positions": 12,
        "warnings": [],
        "gauge": "M upper triangular",
    }
    out.update(extra)
    return out


def compass_result(device="MAG-1", hard_iron=(10.0, -5.0, 2.0), soft_iron=None, sigma=0.1) -> dict:
    W = soft_iron if soft_iron is not None else [[1000.0, 10.0, -5.0], [0.0, 990.0, 8.0], [0.0, 0.0, 1010.0]]
    return {
        "procedure": "compass",
        "device": device,
        "model": "m = W (m_raw - h)",
        "params": {
            "hard_iron": list(hard_iron),
            "soft_iron": [list(r) for r in W],
            "reference": {
                "north_nT": 27000.0,
                "east_nT": -2000.0,
                "down_nT": 45000.0,
                "total_nT": 52518.0,
                "inclination_deg": 59.0,
                "declination_deg": -4.2,
            },
        },
        "uncertainty": {
            "hard_iron": [sigma] * 3,
            "soft_iron": [[sigma] * 3 for _ in range(3)],
            "reference": {
                "north_nT": 0.0,
                "east_nT": 0.0,
                "down_nT": 0.0,
                "total_nT": 0.0,
                "inclination_deg": 0.0,
                "declination_deg": 0.0,
            },
        },
        "residual_rms": 50.0,
        "n_positions": 300,
        "warnings": [],
    }


def gyro_result(device="GYRO-1", drift=(1e-4, -2e-4, 5e-5)) -> dict:
    return {
        "procedure": "gyro-drift",
        "device": device,
        "model": "w' = w - eps",
        "params": {
            "drift": list(drift),
            "mode": "B",
            "pitch_deg": 0.5,
            "roll_deg": -0.2,
            "earth_rate_body": [5.6e-5, 4.4e-5, 0.0],
        },
        "uncertainty": {"drift": [1e-6] * 3, "pitch_deg": 0.01, "roll_deg": 0.01, "earth_rate_body": [1e-7] * 3},
        "residual_rms": 1e-3,
        "n_positions": 1,
        "warnings": ["no temperature column"],
    }


def ldv_result(device="LDV-1") -> dict:
    beam = {"dK": 0.002, "alpha_deg": 60.1, "beta_deg": 45.2, "gamma_deg": 59.8, "sigma_mps": 0.01}
    return {
        "procedure": "ldv",
        "device": device,
        "model": "V_L = (1 + dK)(Vx cos a + Vy cos b + Vz cos g)",
        "params": {"beam1": dict(beam), "beam2": dict(beam), "beam3": dict(beam), "condition_number": 3.2},
        "uncertainty": {
            "beam1": {k: 0.001 for k in beam},
            "beam2": {k: 0.001 for k in beam},
            "beam3": {k: 0.001 for k in beam},
            "condition_number": None,
        },
        "residual_rms": 0.01,
        "n_positions": 100,
        "warnings": [],
    }


def small_capture(seed=0, n=50, procedure="accel-tabletop", device="IMU-1", date=None, **meta) -> tuple[dict, dict]:
    rng = np.random.default_rng(seed)
    m = {"station-capture": "1", "procedure": procedure, "device": device, "accel_unit": "m/s^2"}
    if date:
        m["date"] = date
    m.update({k: str(v) for k, v in meta.items()})
    pos = np.empty(n, dtype=object)
    pos[:] = [str(i // 10 + 1) if i % 7 else "" for i in range(n)]
    cols = {
        "t": np.arange(n) / 100.0,
        "position": pos,
        "ax": rng.normal(0.0, 0.01, n),
        "ay": rng.normal(0.0, 0.01, n),
        "az": rng.normal(9.8, 0.01, n),
    }
    return m, cols


def database_before(path: str, n_migrations: int) -> sqlite3.Connection:
    """A database file as an older station left it: only the first ``n_migrations`` of
    ``db.schema.MIGRATIONS`` applied (by sqlite-utils' Migrations, as the station applies
    them); returns an open connection to it."""
    from sqlite_utils import Database, Migrations

    from db.schema import MIGRATIONS

    conn = sqlite3.connect(path)
    old = Migrations("station")
    for name, statements in MIGRATIONS[:n_migrations]:

        def run(db, statements=statements):
            for sql in statements:
                db.execute(sql)

        run.__name__ = name
        old(name=name)(run)
    old.apply(Database(conn))
    return conn
