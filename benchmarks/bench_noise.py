"""`station noise` benchmark: does the stated 1-sigma of the noise density N and the random walk K
match the scatter of the estimates over independent records? And how long does one analysis take?

    python benchmarks/bench_noise.py [--records N] [--seconds S ...] [--rate HZ] [--seed S]

Each record is three axes of Kalibr's discrete IMU noise model (its wiki, "IMU Noise Model"):
white noise N / sqrt(dt) * w plus a random walk of K * sqrt(dt) * w per step, N = 4e-4 rad/s/√Hz,
K = 4e-5 rad/s²/√Hz (white/random-walk crossover τ = √3 N / K ≈ 17 s). Printed per record
length: rms over records and axes of z = (estimate − truth) / stated sigma for N and K (1 = honest;
above 1 = the sigma is understated), the fraction of K's 68 % intervals holding the truth, how
many records were warned as too short for K, and the
median analysis time per record with its ratio to the time of the plain Allan deviation
(solvers.allan.oadev) of the same record, measured in the same run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from solvers.allan import noise_fit, oadev, octave_taus

N_TRUE, K_TRUE = 4e-4, 4e-5


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--records", type=int, default=8)
    ap.add_argument("--seconds", type=float, nargs="+", default=[300.0, 600.0, 1800.0])
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--seed", type=int, default=1000, help="record i is drawn with seed + i")
    a = ap.parse_args()
    dt = 1.0 / a.rate
    print(f"N = {N_TRUE:g} rad/s/√Hz, K = {K_TRUE:g} rad/s²/√Hz, {a.rate:g} Hz, {a.records} records x 3 axes each")
    print("record_s  rms_z_N  rms_z_K  mean_z_K  K_in_68%  warned  t_fit_s  t_oadev_s  ratio")
    for seconds in a.seconds:
        n = int(seconds * a.rate)
        zn, zk, t_fit, t_ad, warned, inside = [], [], [], [], 0, 0
        for seed in range(a.records):
            rng = np.random.default_rng(a.seed + seed)
            y = N_TRUE / np.sqrt(dt) * rng.normal(size=(n, 3))
            y += np.cumsum(K_TRUE * np.sqrt(dt) * rng.normal(size=(n, 3)), axis=0)
            t0 = time.perf_counter()
            oadev(y, dt, octave_taus(n, dt, 1.0 / 3.0, per_octave=2))
            t_ad.append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            f = noise_fit(y, dt)
            t_fit.append(time.perf_counter() - t0)
            zn += list((f.white - N_TRUE) / f.white_sigma)
            zk += list((f.random_walk - K_TRUE) / f.random_walk_sigma)
            inside += int(np.sum((f.random_walk_lo <= K_TRUE) & (K_TRUE <= f.random_walk_hi)))
            warned += int(f.duration_s < np.max(f.random_walk_min_duration_s))
        rn, rk = np.sqrt(np.mean(np.square(zn))), np.sqrt(np.mean(np.square(zk)))
        tf, ta = float(np.median(t_fit)), float(np.median(t_ad))
        cover = inside / (3 * a.records)
        print(
            f"{seconds:8.0f}  {rn:7.2f}  {rk:7.2f}  {np.mean(zk):8.2f}  {cover:8.2f}  {warned:3d}/{a.records}"
            f"  {tf:7.2f}  {ta:9.3f}  {tf / ta:5.1f}"
        )


if __name__ == "__main__":
    main()
