"""Fixed P1 captures and results for the TUI tests (no solver, no simulator: the screens
are tested, not the numbers), and a database seeded with them."""

from __future__ import annotations

import numpy as np

from solvers.positions import P1_POSITIONS

G_MPS2 = 9.80156


def p1_result(device="IMU-0042", drift=0.0, date="2026-03-01"):
    """(capture, result): a P1 table whose 12 readings the result maps onto |f| = g."""
    from station.capture import Capture

    B = np.array([-19.3, -19.1, -18.9]) + drift
    M = np.array([[11.70, 0.02, -0.01], [0.0, 11.52, 0.03], [0.0, 0.0, 11.61]]) * (1 + 0.001 * drift)
    names = list(P1_POSITIONS)
    V = np.array([np.linalg.solve(M, G_MPS2 * P1_POSITIONS[n] - B) for n in names])
    V[0] += 2e-5  # a little misfit on x_up
    cols = {
        "position": np.array(names, dtype=object),
        "ax": V[:, 0],
        "ay": V[:, 1],
        "az": V[:, 2],
        "n": np.full(12, 300.0),
    }
    meta = {
        "station-capture": "1",
        "procedure": "accel-tabletop",
        "device": device,
        "accel_unit": "V",
        "g_mps2": repr(G_MPS2),
        "date": date,
    }
    result = {
        "procedure": "accel-tabletop",
        "device": device,
        "model": "A = B + M V",
        "params": {"B": B.tolist(), "M": M.tolist()},
        "uncertainty": {"B": [0.004, 0.004, 0.005], "M": [[3e-4, 2e-3, 2e-3], [0, 3e-4, 2e-3], [0, 0, 3e-4]]},
        "residual_rms": 0.00031 + 0.0001 * drift,
        "n_positions": 12,
        "g_mps2": G_MPS2,
        "warnings": ["gauge: M upper triangular (rotation about gravity not observable)"],
    }
    return Capture(meta=meta, columns=cols), result


def seed_history(db, device="IMU-7", n=3, tolerances=None, interval_days=None, start_year=2024):
    """`n` accepted P1 calibrations of `device`, one a year from `start_year`, B drifting 0.02 m/s² a year."""
    from db.store import Store
    from station.store import save_result

    for k in range(n):
        cap, result = p1_result(device, drift=0.02 * k, date=f"{start_year + k}-03-01")
        save_result(db, cap, result, device_id=device, operator="test")
    if tolerances or interval_days:
        Store(db).add_device(device, tolerances=tolerances, interval_days=interval_days)
