"""Compass (P3) benchmark: efficiency of the ellipsoid + RLS fit against the Cramér–Rao
bound, RLS against the batch solution, and RLS throughput.

    python benchmarks/bench_compass.py [--trials N] [--seed0 S] [--quick]

1. Efficiency. For each trial a new simulated capture (``solvers.simulate`` 'compass':
   24 held orientations on the sphere plus the moves between them, 0.15 µT white noise per
   axis, a new device W, h per seed). The station's estimate (ellipsoid → RLS, noise
   estimated from the data as in production) is compared with the truth; each error is
   divided by sqrt(CRLB) of that trial, the CRLB being the inverse Fisher information of the
   same model (radial residual ``|W(y−h)| − F``, variance ``σ²|Wᵀû|²``, the true σ, at the
   true W, h and the trial's samples). Efficiency = RMS over trials of the normalised error,
   per parameter (1.0 = efficient; target <= 1.1). Also: the share of |error| < reported 1σ
   (expect ~68 %).
2. RLS → batch: max over parameters of |θ_rls − θ_batch| / σ_batch (target < 0.1), for the
   fixed-linearisation pass (production) and for the running extended RLS (live use).
3. Throughput of the RLS (samples/s, target >= 10,000), both forms, against a baseline
   measured in the same run: the batch fit (solvers.fit) on the same samples.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from solvers import compass as C  # noqa: E402
from solvers.simulate import simulate  # noqa: E402

NAMES = [f"W[{i}][{j}]" for i, j in zip(*C.UPPER)] + ["h[0]", "h[1]", "h[2]"]


def trial(seed: int):
    sim = simulate("compass", seed=seed)
    c, tr = sim.columns, sim.truth
    y = np.column_stack([c["mx"], c["my"], c["mz"]])
    F = tr["reference"]["total_nT"]
    noise = C.noise_from_second_differences(y)
    cal = C.calibrate_mag(y, F, noise_raw=noise, method="rls")
    Wt, ht = np.array(tr["soft_iron"]), np.array(tr["hard_iron"])
    th_true = C.theta_of(Wt, ht)
    crlb = np.sqrt(np.diag(C.fisher_covariance(y, Wt, ht, tr["mag_noise_uT"])))
    th = C.theta_of(cal.W, cal.h)
    sig = np.concatenate([cal.W_sigma[C.UPPER], cal.h_sigma])
    return (th - th_true) / crlb, np.abs(th - th_true) < sig, cal.rls_minus_batch_sigma, y, cal


def running_vs_batch(y, cal) -> float:
    """max |θ_running − θ_batch| / σ_batch for the live (running extended) RLS."""
    th_b = C.theta_of(cal.batch.params["W"], cal.batch.params["h"])
    sig_b = np.concatenate([cal.batch.sigma["W"][C.UPPER], cal.batch.sigma["h"]])
    P0 = C.RLS_RUNNING_P0_INFLATION * C.fisher_covariance(y, cal.W_ellipsoid, cal.h_ellipsoid, cal.noise_raw)
    run = C.MagRLS(cal.W_ellipsoid, cal.h_ellipsoid, cal.field_nT, P0, noise_raw=cal.noise_raw)
    run.process(y)
    return float(np.max(np.abs(run.theta - th_b) / sig_b))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--seed0", type=int, default=1000)
    ap.add_argument("--quick", action="store_true", help="20 trials")
    args = ap.parse_args(argv)
    n = 20 if args.quick else args.trials

    t0 = time.perf_counter()
    norm, inside, diffs, run_diffs = [], [], [], []
    last = None
    for k in range(n):
        e, ins, d, y, cal = trial(args.seed0 + k)
        norm.append(e)
        inside.append(ins)
        diffs.append(d)
        last = (y, cal)
        if k % 10 == 0:
            run_diffs.append(running_vs_batch(y, cal))
    norm, inside = np.array(norm), np.array(inside)
    eff = np.sqrt(np.mean(norm**2, axis=0))
    bias = np.mean(norm, axis=0)
    print(
        f"compass efficiency, {n} trials (seeds {args.seed0}..{args.seed0 + n - 1}), {time.perf_counter() - t0:.1f} s"
    )
    print(f"{'param':>8} {'RMS/sqrt(CRLB)':>15} {'mean/sqrt(CRLB)':>16} {'|err|<1σ':>9}")
    for name, e, b, c in zip(NAMES, eff, bias, inside.mean(axis=0)):
        print(f"{name:>8} {e:15.3f} {b:16.3f} {100 * c:8.1f}%")
    se = 1.0 / np.sqrt(2 * n)  # standard error of an RMS ratio near 1
    print(
        f"max efficiency {eff.max():.3f} (target <= 1.1; Monte Carlo s.e. ≈ {se:.3f}); "
        f"mean {eff.mean():.3f}; 1σ coverage {100 * inside.mean():.1f}% (expect 68.3%)"
    )
    print(
        f"RLS (fixed linearisation, {C.RLS_PASSES} pass) vs batch: max {max(diffs):.2e} σ, "
        f"median {np.median(diffs):.2e} σ (target < 0.1)"
    )

    # running extended RLS (live form) on the last trial, and throughput
    y, cal = last
    P0_fix = C.RLS_P0_INFLATION * C.fisher_covariance(y, cal.W_ellipsoid, cal.h_ellipsoid, cal.noise_raw)
    P0 = C.RLS_RUNNING_P0_INFLATION * C.fisher_covariance(y, cal.W_ellipsoid, cal.h_ellipsoid, cal.noise_raw)
    reps = 5
    t = time.perf_counter()
    for _ in range(reps):
        run = C.MagRLS(cal.W_ellipsoid, cal.h_ellipsoid, cal.field_nT, P0, noise_raw=cal.noise_raw)
        run.process(y)
    rate_run = reps * len(y) / (time.perf_counter() - t)
    t = time.perf_counter()
    for _ in range(reps):
        fx = C.MagRLS(
            cal.W_ellipsoid, cal.h_ellipsoid, cal.field_nT, P0_fix, noise_raw=cal.noise_raw, linearise="fixed"
        )
        fx.process(y)
    rate_fix = reps * len(y) / (time.perf_counter() - t)
    t = time.perf_counter()
    for _ in range(reps):
        C.batch_fit(y, cal.W_ellipsoid, cal.h_ellipsoid, cal.field_nT, cal.noise_raw)
    rate_batch = reps * len(y) / (time.perf_counter() - t)
    print(
        f"running extended RLS (P0 = {C.RLS_RUNNING_P0_INFLATION:g} x Fisher cov.) vs batch, every 10th "
        f"trial ({len(run_diffs)}): max {max(run_diffs):.2e} σ, median {np.median(run_diffs):.2e} σ"
    )
    print(
        f"throughput ({len(y)} samples): RLS fixed {rate_fix:,.0f}/s, RLS running {rate_run:,.0f}/s "
        f"(target >= 10,000/s); baseline batch fit {rate_batch:,.0f}/s "
        f"(ratios {rate_fix / rate_batch:.2f}, {rate_run / rate_batch:.2f})"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
