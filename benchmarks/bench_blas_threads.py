"""BLAS threads: ``station diagnose`` on one P1 time series, as a whole process, with one BLAS
thread (the station's default since station/__init__.py sets it) against OpenBLAS's own default
(a thread per core), on an idle machine and beside a process that keeps one core busy (a test
worker, a second station, a compile).

    python benchmarks/bench_blas_threads.py [--runs 3] [--seed 531037]

The capture: benchmarks/diag_generator.py's P1 bias step at 10σ from ``--seed`` (17 holds of
30 s at 100 Hz, 28 k rows), whose diagnosis spends most of its time in the slow-noise model's
eigendecompositions of up to 400 rows (solvers/diagnose/wander.py). Printed: per arm the
minimum and median wall time over ``--runs`` runs, alternating arms, and the ratio of medians.
The two verdicts must agree (the thread count changes the arithmetic's order, not the result).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import diag_generator as G  # noqa: E402

THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def _run(path: str, threads: int) -> tuple[float, list]:
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARS}
    env.update({k: str(threads) for k in THREAD_VARS})
    t0 = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-m", "station", "diagnose", path, "--json"],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return time.perf_counter() - t0, json.loads(out.stdout)["verdict"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--seed", type=int, default=531037)
    args = ap.parse_args()
    cores = os.cpu_count() or 1
    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "p1_step.csv")
        sc = G.scenario_for("accel-tabletop", np.random.default_rng(args.seed), "bias_step")
        size, _ = G.size_for(sc, "bias_step", 10.0)
        r = G.RENDER["accel-tabletop"](sc, "bias_step", size)
        G.write_csv(path, r.meta, r.columns)
        load1 = os.getloadavg()[0]
        print(f"station diagnose on a P1 time series (seed {args.seed}), {args.runs} runs per arm, {cores} cores")
        print(f"load average before the runs: {load1:.1f} (an 'idle' row is idle only where this is below 1)")
        print(f"{'load':<22} {'BLAS threads':>12} {'min s':>8} {'median s':>9}")
        for load in ("idle", "one core kept busy"):
            busy = None
            if load != "idle":
                busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
            try:
                times: dict[int, list[float]] = {1: [], cores: []}
                verdicts = set()
                for _ in range(args.runs):
                    for threads in (1, cores):
                        dt, verdict = _run(path, threads)
                        times[threads].append(dt)
                        verdicts.add(tuple(verdict))
            finally:
                if busy is not None:
                    busy.kill()
                    busy.wait()
            for threads, ts in times.items():
                print(f"{load:<22} {threads:>12} {min(ts):>8.2f} {statistics.median(ts):>9.2f}")
            ratio = statistics.median(times[cores]) / statistics.median(times[1])
            print(f"{load:<22} ratio of medians, {cores} threads / 1: {ratio:.2f}; verdicts {sorted(verdicts)}")
            if len(verdicts) != 1:
                print("the verdicts differ between thread counts", file=sys.stderr)
                return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
