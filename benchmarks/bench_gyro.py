"""Gyro drift (P4) benchmark: the estimate against the simulated truth over seeds.

    python benchmarks/bench_gyro.py [--trials N] [--seed0 S] [--quick]

For each seed a new simulated capture (``solvers.simulate`` 'gyro-drift': MEMS bias
~0.3 °/s per axis, white noise 0.002 rad/s at 100 Hz, a 60 s Gauss-Markov bias
instability of 2e-5 rad/s, Beijing, operator's heading error 3°, 180 s):

- mode A (reference IMU ten times better, with its own 1 °/h offset);
- mode B (static base, latitude known, heading 0 asked);
- several positions (4 headings × tilt, 480 s in all) through the station procedure.

Printed per mode: RMS of the error (°/h), mean reported 1σ (°/h), RMS of error/σ (1 when
the reported uncertainty is right), coverage at 1σ and 2σ (0.683, 0.954), and the
white-noise-only figure σ/√n for comparison (what a naive error would claim). Also the
time of one mode-B estimate against a bare numpy mean over the same samples.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from solvers import gyrodrift as gd  # noqa: E402
from solvers.simulate import simulate  # noqa: E402
from station.capture import Capture  # noqa: E402
from station.procedures import gyrodrift as proc  # noqa: E402

DEG_H = gd.DEG_H_RAD_S


def _cols(c, names):
    return np.column_stack([c[k] for k in names])


def run_mode(mode: str, seeds):
    err, sig, white = [], [], []
    for s in seeds:
        if mode == "A":
            sim = simulate("gyro-drift", seed=s, mode="reference")
            c = sim.columns
            r = gd.drift_reference(_cols(c, ["gx", "gy", "gz"]), _cols(c, ["ref_gx", "ref_gy", "ref_gz"]), 0.01)
            d, sg, sw = r.drift_rad_s, r.sigma_rad_s, r.mean_error.se_white
        elif mode == "B":
            sim = simulate("gyro-drift", seed=s, mode="static")
            c = sim.columns
            r = gd.drift_static(
                _cols(c, ["gx", "gy", "gz"]), _cols(c, ["ax", "ay", "az"]), 0.01, float(sim.meta["latitude_deg"]), 0.0
            )
            d, sg, sw = r.drift_rad_s, r.sigma_rad_s, r.mean_error.se_white
        else:
            sim = simulate("gyro-drift", seed=s, mode="static", headings_deg=[0, 90, 180, 270], duration_s=480)
            out = proc.calibrate(Capture(dict(sim.meta), dict(sim.columns)))
            d, sg = np.array(out["params"]["drift"]), np.array(out["uncertainty"]["drift"])
            sw = np.full(3, np.nan)
        err.append(d - np.array(sim.truth["drift"]))
        sig.append(sg)
        white.append(sw)
    return np.array(err), np.array(sig), np.array(white)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=300)
    ap.add_argument("--seed0", type=int, default=9000)
    ap.add_argument("--quick", action="store_true", help="40 trials (20 for several positions)")
    args = ap.parse_args(argv)
    n = 40 if args.quick else args.trials
    print(f"P4 gyro drift vs simulated truth ({n} seeds for A and B, {max(n // 4, 20)} for several positions)")
    print(
        "mode                 RMS err °/h   mean σ °/h   RMS(err/σ)   |err|<σ   |err|<2σ   naive σ/√n °/h  RMS(err/naive)"
    )
    for mode, label, k in (
        ("A", "A reference IMU", n),
        ("B", "B static base", n),
        ("M", "several positions", max(n // 4, 20)),
    ):
        t0 = time.perf_counter()
        e, s, w = run_mode(mode, range(args.seed0, args.seed0 + k))
        z = e / s
        naive = (
            f"{np.nanmean(w) / DEG_H:14.2f}  {np.sqrt(np.nanmean((e / w) ** 2)):8.2f}"
            if np.isfinite(w).any()
            else f"{'—':>14}  {'—':>8}"
        )
        print(
            f"{label:20s} {np.sqrt(np.mean(e**2)) / DEG_H:11.2f}   {np.mean(s) / DEG_H:10.2f}   "
            f"{np.sqrt(np.mean(z**2)):10.2f}   {np.mean(np.abs(z) < 1):7.3f}   {np.mean(np.abs(z) < 2):8.3f}   {naive}"
            f"   [{time.perf_counter() - t0:.1f} s]"
        )
    sim = simulate("gyro-drift", seed=args.seed0, mode="static")
    c = sim.columns
    w, f = _cols(c, ["gx", "gy", "gz"]), _cols(c, ["ax", "ay", "az"])
    reps = 20
    t0 = time.perf_counter()
    for _ in range(reps):
        gd.drift_static(w, f, 0.01, 39.98, 0.0)
    t_est = (time.perf_counter() - t0) / reps
    t0 = time.perf_counter()
    for _ in range(reps):
        w.mean(axis=0)
        f.mean(axis=0)
    t_base = (time.perf_counter() - t0) / reps
    print(
        f"\nspeed ({len(w)} samples): mode-B estimate with Allan error {t_est * 1e3:.1f} ms, bare means "
        f"{t_base * 1e3:.2f} ms (ratio {t_est / t_base:.0f}x)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
