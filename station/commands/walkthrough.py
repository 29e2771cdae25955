"""`station walkthrough [--procedure P] [--seed N]`: simulate, calibrate, compare with the truth.

A headless end-to-end run of one procedure on the simulator: what a newcomer (or CI)
can run with no device and no screen.
"""
from __future__ import annotations

import argparse
import os
import tempfile

import numpy as np


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("walkthrough", help="simulate a capture, calibrate it and compare with the truth")
    p.add_argument("--procedure", default="accel-tabletop",
                   choices=("accel-tabletop", "accel-centrifuge", "compass", "gyro-drift", "ldv"))
    p.add_argument("--seed", type=int, default=1)
    p.set_defaults(func=run)


def _flat(prefix, v):
    a = np.asarray(v, dtype=float)
    if a.ndim == 0:
        return {prefix: float(a)}
    return {prefix + "".join(f"[{i}]" for i in idx): float(a[idx]) for idx in np.ndindex(*a.shape)}


def run(args: argparse.Namespace) -> int:
    from solvers.simulate import simulate
    from station.calibrate import calibrate_capture, format_text
    from station.capture import Capture, read_capture, write_capture

    sim = simulate(args.procedure, seed=args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, f"{args.procedure}.capture.csv")
        write_capture(path, Capture(meta=sim.meta, columns=sim.columns, path=path))
        capture = read_capture(path)
        print(f"1. simulated {args.procedure} (seed {args.seed}): {capture.n_rows} rows → {os.path.basename(path)}")
        result = calibrate_capture(capture)
    print("2. calibrated:\n")
    print(format_text(result))
    print("\n3. against the simulator's truth (estimate − truth, in σ):")
    params, unc, truth = result.get("params", {}), result.get("uncertainty", {}), sim.truth
    for name, value in params.items():
        if name not in truth or not isinstance(value, (list, float, int)):
            continue
        est, sig, tru = _flat(name, value), _flat(name, unc.get(name, value)), _flat(name, truth[name])
        zs = [(k, (est[k] - tru[k]) / sig[k]) for k in est if k in tru and sig.get(k) and np.isfinite(sig[k]) and sig[k] > 0]
        if zs:
            print("   " + name + ": " + ", ".join(f"{z:+.1f}" for _, z in zs))
    return 0
