"""Stillness detector benchmark: batch time on 1,000,000 samples and tracker throughput.

    python benchmarks/bench_stillness.py [--n N] [--repeat R] [--quick]

1. Batch. `detect_static_intervals` on a simulated 1 kHz multi-position recording of N
   samples (default 1,000,000: rests of 3-8 s, raised-cosine moves of 1-2.5 s, white noise),
   with and without gyro, against a baseline measured in the same run: a plain numpy
   moving variance (np.convolve of x and x^2 with a box of the same width, per axis), the
   imu_tk variance magnitude, one threshold and the run extraction; and the least O(n)
   version of that (one global cumulative sum, as in any textbook). Also the peak memory of the batch call (tracemalloc, which
   numpy reports to) and the planted rests recovered.
2. Tracker. `StillnessTracker.update` fed batches of 1, 10, 100, 1,000 and 10,000 rows:
   rows/s, microseconds per update, and the CPU share a 1 kHz stream would take. Target:
   well above 10,000 rows/s.

Times are the best of R runs (the machine may be shared; the load average is printed).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from solvers.stillness import StillnessTracker, detect_static_intervals  # noqa: E402

FS = 1000.0
G = 9.81


def simulate(n: int, seed: int = 0):
    """Rests and moves until n samples; returns t, accel [m/s^2], gyro [rad/s], planted rests."""
    rng = np.random.default_rng(seed)
    f = np.array([0.0, 0.0, G])  # specific force in body axes at the current pose
    acc, rate, truth = [], [], []
    k = 0
    while k < n:
        m = int(rng.uniform(3, 8) * FS)
        acc.append(np.tile(f, (m, 1)))
        rate.append(np.zeros((m, 3)))
        truth.append((k, k + m))
        k += m
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        th, dur = math.radians(rng.uniform(40, 150)), rng.uniform(1.0, 2.5)
        m = int(dur * FS)
        tt = (np.arange(m) + 0.5) / m
        phi = th * (tt - np.sin(2 * np.pi * tt) / (2 * np.pi))
        c, s = np.cos(-phi)[:, None], np.sin(-phi)[:, None]  # body rotates by +phi: f by -phi
        rot = f * c + np.cross(u, f) * s + np.outer(1 - c[:, 0], u) * (u @ f)
        acc.append(rot)
        rate.append((th * (1 - np.cos(2 * np.pi * tt)) / dur)[:, None] * u)
        f = rot[-1] if m else f
        k += m
    a = np.vstack(acc)[:n] + rng.normal(0, 0.02, (n, 3))
    w = np.vstack(rate)[:n] + rng.normal(0, 0.004, (n, 3))
    truth = [(s, min(e, n)) for s, e in truth if s < n]
    return np.arange(n) / FS, a, w, truth


def baseline(a: np.ndarray, w: int, noise_var: np.ndarray, k: float):
    """Plain numpy: box-filter moving variance per axis, imu_tk magnitude, threshold, runs."""
    box = np.ones(w) / w
    var = np.empty((len(a) - w + 1, 3))
    for j in range(3):
        x = a[:, j] - a[0, j]
        m1 = np.convolve(x, box, mode="valid")
        m2 = np.convolve(x * x, box, mode="valid")
        var[:, j] = (m2 - m1 * m1) * (w / (w - 1))
    still = np.linalg.norm(var, axis=1) < k * np.linalg.norm(noise_var)
    edges = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)


def baseline_cumsum(a: np.ndarray, w: int, noise_var: np.ndarray, k: float):
    """The least O(n) version: one global cumulative sum per moment, same threshold, runs."""
    x = a - a[0]
    c1 = np.cumsum(np.vstack([np.zeros((1, 3)), x]), axis=0)
    c2 = np.cumsum(np.vstack([np.zeros((1, 3)), x * x]), axis=0)
    s1, s2 = c1[w:] - c1[:-w], c2[w:] - c2[:-w]
    var = (s2 - s1 * s1 / w) / (w - 1)
    still = np.linalg.norm(var, axis=1) < k * np.linalg.norm(noise_var)
    edges = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)


def best_of(fn, repeat: int) -> tuple[float, object]:
    """Best wall time of `repeat` runs (and the last result)."""
    best, out = math.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def best_cpu(fn, repeat: int) -> tuple[float, float]:
    """Best (wall, process CPU) times of `repeat` runs; CPU time is what a busy machine
    does not inflate (much)."""
    wall, cpu = math.inf, math.inf
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall, cpu = min(wall, time.perf_counter() - t0), min(cpu, time.process_time() - c0)
    return wall, cpu


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="n=200,000, repeat 1")
    args = ap.parse_args()
    n, repeat = (200_000, 1) if args.quick else (args.n, args.repeat)
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs; numpy {np.__version__}")
    t, a, w, truth = simulate(n)
    print(f"simulated {n:,} samples at {FS:g} Hz: {len(truth)} planted rests")

    # 1. batch
    res = detect_static_intervals(t, a, w, sample_rate_hz=FS)
    res_a = detect_static_intervals(t, a, sample_rate_hz=FS)
    t_b, c_b = best_cpu(lambda: detect_static_intervals(t, a, w, sample_rate_hz=FS), repeat)
    t_a, c_a = best_cpu(lambda: detect_static_intervals(t, a, sample_rate_hz=FS), repeat)
    win = res.config.window_n
    t_np, c_np = best_cpu(lambda: baseline(a, win, res.noise.accel_var, res.config.threshold_factor), repeat)
    t_cs, c_cs = best_cpu(lambda: baseline_cumsum(a, win, res.noise.accel_var, res.config.threshold_factor), repeat)
    tracemalloc.start()
    detect_static_intervals(t, a, w, sample_rate_hz=FS)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    truth = [(s, e) for s, e in truth if e - s >= FS]  # a rest cut short by the end of the series
    found = sum(any(iv.start >= s - 50 and iv.stop <= e + 50 for iv in res.intervals) for s, e in truth)
    print("\nbatch detector (robust noise floor, window 1 s = 1001 samples); wall and CPU seconds")
    print(
        f"  accel + gyro : {t_b:6.3f} s wall {c_b:6.3f} s CPU  {n / c_b / 1e6:5.2f} M samples/s CPU"
        f"  CPU ratio to baseline {c_b / c_np:5.2f}"
    )
    print(
        f"  accel only   : {t_a:6.3f} s wall {c_a:6.3f} s CPU  {n / c_a / 1e6:5.2f} M samples/s CPU"
        f"  CPU ratio to baseline {c_a / c_np:5.2f}"
    )
    print(
        f"  baseline     : {t_np:6.3f} s wall {c_np:6.3f} s CPU  (np.convolve moving variance, accel only,"
        " no noise estimate, no interval statistics)"
    )
    print(
        f"  cumsum base  : {t_cs:6.3f} s wall {c_cs:6.3f} s CPU  (one global cumsum, accel only, same omissions);"
        f" accel-only detector / this = {c_a / c_cs:4.2f}"
    )
    print(f"  peak memory  : {peak / 1e6:7.1f} MB for {n * 6 * 8 / 1e6:.0f} MB of input")
    print(
        f"  intervals    : {len(res.intervals)} found, {found}/{len(truth)} planted rests recovered "
        f"(accel only: {len(res_a.intervals)})"
    )

    # 2. tracker
    print("\ntracker (accel + gyro, noise from the batch result; rows fed in batches of B)")
    print(f"  {'B':>6} {'rows/s wall':>12} {'rows/s CPU':>12} {'CPU us/update':>14} {'CPU at 1 kHz':>13}")
    for b in (1, 10, 100, 1000, 10000):
        rows = min(n, max(20_000, 200 * b))

        def feed(b=b, rows=rows):
            tr = StillnessTracker.from_result(res)
            for i in range(0, rows, b):
                tr.update(t[i : i + b], a[i : i + b], w[i : i + b])
            return tr

        wall, cpu = best_cpu(feed, repeat)
        print(
            f"  {b:>6} {rows / wall:12,.0f} {rows / cpu:12,.0f} {cpu / math.ceil(rows / b) * 1e6:14.1f} "
            f"{FS * cpu / rows:12.1%}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
