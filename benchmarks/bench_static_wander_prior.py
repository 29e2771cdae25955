"""Can the within-hold samples size the slow noise that makes P1/P2 nulls alarm? (QA s29)

The independent static generator (``indep_s27_generator.py``) draws, per axis, white noise plus a
Gauss–Markov bias of 0.2–1.2 × a 30 s hold mean's white noise with τ 60–600 s, plus a random walk.
Over a capture's span such a wander is a drift that ``time_drift``/``temperature_bias`` fit (P2
nulls 705035, 705051). A prior on its size would let a drift-like candidate be tested against
what the bias instability alone produces over the span; the only place a capture could give it
is the samples within holds, through the Allan noise model calibrate uses
(``solvers.allan.oadev`` and ``fit_noise_model``, pooled over the holds here).

Per null capture (time series only: a table of averages has no samples within holds) this
prints, per axis, what the generator drew and what the pooled Allan fit measures:

- ``excess_true``: the slow noise's Allan variance at the longest τ the holds allow (a third of
  the shortest hold) over the white noise's there, from the generator's own parameters (the
  Gauss–Markov wander seen within a hold as a random walk, K² = 2 σ_b²/τ_c, plus the walk);
- ``excess_meas``: the same ratio measured on the pooled Allan variance (its value at τ_max
  over the white level read at the shortest τ, minus 1);
- ``K2_true``, ``K2_fit``: the rate random walk (3 c2 of the fitted model) true and fitted;
- ``wander_true``, ``wander_fit``: the bias change over the capture's span each implies
  (√(K² · span)), in units of one hold mean's white standard error.

The generator's own hold boundaries are used (the best case for the Allan fit). Seeds 700000+.

    python benchmarks/bench_static_wander_prior.py --procedure P2 --seeds 708000 708019
    python benchmarks/bench_static_wander_prior.py --procedure P1 --seeds 708100 708119
    python benchmarks/bench_static_wander_prior.py --real    # B / N on the real static records

``--real``: the bias instability over the white noise density, B / N (s^-1/2), of the real static
accelerometer records in ../shared/data (the whole record's Allan deviation, ``solvers.allan``: N
from the fitted white term, B = the deviation's minimum / 0.664), the size
``solvers.diagnose.problems.SLOW_BIAS_PER_WHITE_DENSITY`` takes for a P2 diagnosis.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import indep_s27_generator as G  # noqa: E402

from solvers.allan import fit_noise_model, oadev, octave_taus  # noqa: E402
from station.capture import read_capture  # noqa: E402


def one(proc: str, seed: int, out: Path) -> list[dict] | None:
    drawn: list[dict] = []
    orig = G.noise_params

    def record(*a, **k):
        p = orig(*a, **k)
        drawn.append(p)
        return p

    G.noise_params = record
    try:
        rng = np.random.default_rng(seed)
        _, write, ctx, _ = G.BUILDERS[proc](rng, "none")  # as make_one draws a null
        write(0.0, str(out))
    finally:
        G.noise_params = orig
    if not ctx["series"]:
        return None
    cap = read_capture(str(out))
    a = np.column_stack([np.asarray(cap.column(c), float) for c in ("ax", "ay", "az")])
    hold, fs = np.asarray(ctx["hold_idx"]), float(ctx["fs"])
    dt = 1.0 / fs
    segs = [a[hold == j] for j in range(ctx["k"])]
    segs = [s for s in segs if len(s) >= 16]
    nmin = min(len(s) for s in segs)
    taus = octave_taus(nmin, dt, 1.0 / 3.0, per_octave=2)
    av, terms = 0.0, 0.0
    for s in segs:
        tt, ad, te = oadev(s, dt, taus)
        av = av + ad**2 * te[:, None]
        terms = terms + te
    adev = np.sqrt(av / terms[:, None])
    c = fit_noise_model(tt, adev, terms, dt)
    span = float(ctx["tnoise"][-1])
    rows = []
    for ax, p in enumerate(drawn):
        k2_true = 2.0 * p["sb"] ** 2 / p["tau"] + p["q"] ** 2 * fs
        white = p["sw"] ** 2 * dt  # c0 of white noise
        tmax = float(tt[-1])
        se_hold = p["sw"] / np.sqrt(np.median([len(s) for s in segs]))
        rows.append(
            {
                "seed": seed,
                "axis": "xyz"[ax],
                "holds": len(segs),
                "hold_s": float(np.median([len(s) for s in segs]) * dt),
                "tau_max_s": tmax,
                "excess_true": k2_true * tmax**2 / (3.0 * white),
                "excess_meas": float(adev[-1, ax] ** 2 * tmax / (adev[0, ax] ** 2 * tt[0]) - 1.0),
                "K2_true": k2_true,
                "K2_fit": 3.0 * c[ax, 2],
                "wander_true": float(np.sqrt(k2_true * span) / se_hold),
                "wander_fit": float(np.sqrt(3.0 * c[ax, 2] * span) / se_hold),
                "gm_sb": float(p["sb"] / se_hold),
            }
        )
    return rows


REAL_RECORDS = (
    "mpu6050_unc/mpu6050_unc_tinit_static.capture.csv",
    "sunsided_marg/sunsided_unmoved_x_forward_10min.capture.csv",
    "mpu6050_unc/mpu6050_unc_static_test.capture.csv",
)


def real_ratios(shared: Path) -> None:
    print("| record | span s | N per axis (unit·√s) | B / N per axis (s^-1/2) | τ of the minimum s |")
    print("|---|---|---|---|---|")
    for rel in REAL_RECORDS:
        cap = read_capture(str(shared / "data" / rel))
        a = np.column_stack([np.asarray(cap.column(c), float) for c in ("ax", "ay", "az")])
        t = np.asarray(cap.column("t"), float)
        ok = np.all(np.isfinite(a), axis=1)
        a, t = a[ok], t[ok]
        dt = float(np.median(np.diff(t)))
        taus, adev, terms = oadev(a, dt, octave_taus(len(a), dt, 0.25, per_octave=2))
        n_white = np.sqrt(fit_noise_model(taus, adev, terms, dt)[:, 0])
        i = np.argmin(adev, axis=0)
        ratio = adev[i, range(3)] / 0.664 / n_white
        print(
            f"| {Path(rel).name} | {t[-1] - t[0]:.0f} | {', '.join(f'{x:.3g}' for x in n_white)} | "
            f"{', '.join(f'{x:.2f}' for x in ratio)} | {', '.join(f'{x:.0f}' for x in taus[i])} |"
        )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--procedure", choices=["P1", "P2"], default="P2")
    ap.add_argument("--seeds", type=int, nargs=2, default=[708000, 708019], metavar=("FIRST", "LAST"))
    ap.add_argument("--dir", default="/tmp/bench_static_wander_prior")
    ap.add_argument("--real", action="store_true", help="B / N of the real static records instead")
    args = ap.parse_args(argv)
    if args.real:
        real_ratios(Path(os.environ.get("STATION_SHARED", Path(__file__).resolve().parents[2] / "shared")))
        return 0
    if args.seeds[0] < 700000:
        raise SystemExit("seeds 700000 and up only")
    d = Path(args.dir)
    d.mkdir(parents=True, exist_ok=True)
    allrows, tables = [], 0
    print(
        "| seed | axis | holds | hold s | τ_max s | excess true | excess measured | K² true | K² fit | "
        "wander/span true | fit (hold-mean σ) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for seed in range(args.seeds[0], args.seeds[1] + 1):
        rows = one(args.procedure, seed, d / f"{args.procedure}_{seed}.csv")
        if rows is None:
            tables += 1
            continue
        for r in rows:
            allrows.append(r)
            print(
                f"| {r['seed']} | {r['axis']} | {r['holds']} | {r['hold_s']:.0f} | {r['tau_max_s']:.1f} | "
                f"{r['excess_true']:.4f} | {r['excess_meas']:+.3f} | {r['K2_true']:.2g} | {r['K2_fit']:.2g} | "
                f"{r['wander_true']:.2f} | {r['wander_fit']:.2f} |"
            )
    et = np.array([r["excess_true"] for r in allrows])
    em = np.array([r["excess_meas"] for r in allrows])
    wt = np.array([r["wander_true"] for r in allrows])
    wf = np.array([r["wander_fit"] for r in allrows])
    print()
    print(f"{len(allrows) // 3} time series ({tables} tables of averages skipped: no samples within holds)")
    print(f"excess true: median {np.median(et):.4f}, 90th percentile {np.percentile(et, 90):.4f}")
    print(f"excess measured: median {np.median(em):+.4f}, spread (std) {np.std(em):.4f}")
    print(f"corr(excess measured, true) = {np.corrcoef(em, et)[0, 1]:+.2f}")
    print(
        f"wander over the span / hold-mean σ: true median {np.median(wt):.2f}; fitted median {np.median(wf):.2f}, "
        f"fitted 0 on {np.mean(wf == 0):.0%} of axes, fitted > 3× true on {np.mean(wf > 3 * wt):.0%}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
