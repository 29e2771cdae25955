"""End-to-end honesty check: do `station calibrate`'s 1σ cover the simulator's truth?

    python benchmarks/bench_qa_coverage.py [--seeds N] [--only PROCEDURE]

Each trial is what a user gets from `station simulate --procedure P --seed S` with the default
options (bias instability, temperature warm-up, placement errors included): the capture is
written to a file, read back and calibrated (`station.calibrate.calibrate_capture`), and each
parameter's error is divided by its reported σ. Printed per case: RMS of z (1 = honest;
> 1 = σ too small; < 1 = σ conservative), the share within 1σ and 2σ (expected 0.68, 0.95)
and the worst parameters. P1 without position labels is fitted in the upper-triangular
gauge: its truth is rotated into that gauge (M = Q R, truth → (Qᵀ B, R)) before comparing.
Baseline in the same run: P1 without bias instability (`bias_instability_mps2=0`), where the
per-position std/sqrt(n) is the whole noise.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from solvers.simulate import simulate  # noqa: E402
from station.calibrate import calibrate_capture, jsonable  # noqa: E402
from station.capture import Capture, read_capture, write_capture  # noqa: E402

CASES = [
    ("accel-tabletop", {}),
    ("accel-tabletop", {"label_positions": False}),
    ("accel-tabletop", {"label_positions": False, "bias_instability_mps2": 0.0}),  # baseline
    ("accel-centrifuge", {}),
    ("compass", {}),
    ("gyro-drift", {}),
    ("gyro-drift", {"mode": "reference"}),
    ("ldv", {}),
    ("ldv", {"reference": "nav"}),
]
KEYS = {
    "accel-tabletop": ["B", "M"],
    "accel-centrifuge": ["S", "b", "D"],
    "compass": ["hard_iron", "soft_iron"],
    "gyro-drift": ["drift"],
}


def z_scores(procedure: str, d: dict, truth: dict) -> dict[str, float]:
    p, u, t = d["params"], d["uncertainty"], dict(truth)
    out = {}
    if procedure == "ldv":
        for i in range(3):
            for k in ("dK", "alpha_deg", "beta_deg", "gamma_deg"):
                s = u[f"beam{i + 1}"][k]
                if s:
                    out[f"beam{i + 1}.{k}"] = (p[f"beam{i + 1}"][k] - t[k][i]) / s
        return out
    if procedure == "accel-tabletop" and d.get("gauge") == "upper-triangular":
        Q, R = np.linalg.qr(np.array(t["M"]))
        sg = np.sign(np.diag(R))
        Q, R = Q * sg, (R.T * sg).T
        t = dict(t, M=R.tolist(), B=(Q.T @ np.array(t["B"])).tolist())
    for k in KEYS[procedure]:
        e, s, tr = (np.ravel(np.array(x, dtype=float)) for x in (p[k], u[k], t[k]))
        for j in range(len(e)):
            if np.isfinite(s[j]) and s[j] > 0:
                out[f"{k}[{j}]"] = (e[j] - tr[j]) / s[j]
    return out


def run_case(procedure: str, options: dict, seeds: int, folder: str) -> None:
    per: dict[str, list[float]] = {}
    t0 = time.perf_counter()
    for seed in range(seeds):
        sim = simulate(procedure, seed=seed, **options)
        path = os.path.join(folder, "capture.csv")
        write_capture(path, Capture(meta=sim.meta, columns=sim.columns, path=path))
        d = jsonable(calibrate_capture(read_capture(path)))
        for name, z in z_scores(procedure, d, sim.truth).items():
            per.setdefault(name, []).append(z)
    z = np.concatenate([np.array(v) for v in per.values()])
    worst = sorted(((float(np.sqrt(np.mean(np.square(v)))), k) for k, v in per.items()), reverse=True)[:3]
    label = procedure + (" " + " ".join(f"{k}={v}" for k, v in options.items()) if options else "")
    print(
        f"{label:<62} n={z.size:4d}  rms z {np.sqrt(np.mean(z**2)):5.2f}  "
        f"|z|<1 {np.mean(np.abs(z) < 1):4.2f}  |z|<2 {np.mean(np.abs(z) < 2):4.2f}  "
        f"worst {', '.join(f'{k} {r:.2f}' for r, k in worst)}  ({time.perf_counter() - t0:.0f} s)",
        flush=True,
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--only", default=None, help="one procedure")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        for procedure, options in CASES:
            if args.only in (None, procedure):
                run_case(procedure, options, args.seeds, folder)
    return 0


if __name__ == "__main__":
    sys.exit(main())
