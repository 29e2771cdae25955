"""Diagnose benchmark: false-alarm rate on null captures, detection rate against effect size
(in sigma of what the data resolve), runtime on a one-hour 100 Hz capture.

    python benchmarks/bench_diagnose.py [--trials N] [--null-only] [--procedures P,...]
                                        [--jobs J] [--sizes 3,5,8] [--skip-runtime]

Null captures: ``solvers.simulate`` with no effect, a new device and noise per seed; a
false alarm is a non-empty verdict. The score printed per procedure is, for each null, the
largest ``deviance / χ²_k(1 − α/m)`` among candidates that also lower the held-out RMS
(the engine's test, solvers/diagnose/engine.py::selection_threshold); its 95th
percentile is the scale F giving a 5 % false-alarm rate — the THRESHOLDS of
``solvers/diagnose/problems.py`` come from this command with --null-only --trials 200
(seeds from 1000); check them on other seeds with --null-seed0.

Effect size in sigma, per capture: the seed's capture with a reference size gives the
deviance of fitting the effect (≈ (size/σ_size)² for that pattern and design); the same
seed is then simulated at ``size_ref · k / sqrt(deviance)`` (``_trial``). Detection = the
hidden name in the verdict (named itself or as confused with the chosen one). The 1σ
printed is the median over the captures (``sigma_sizes`` gives a quick 3-seed estimate).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")  # two worker processes on two cores: no BLAS threads on top

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from solvers.simulate import simulate  # noqa: E402
from station.capture import Capture  # noqa: E402

# Options that keep the capture's structure independent of the hidden effect (and give
# the effects something to be seen against): several orientations for gyro-drift, extra
# positions on the table for P1 (12 positions leave 3 degrees of freedom).
OPTIONS = {
    "accel-tabletop": {"extra_positions": 12},
    "gyro-drift": {"headings_deg": [0.0, 90.0, 180.0, 270.0]},
    "accel-centrifuge": {},
    "compass": {},
    "ldv": {},
}
# Reference sizes (units of solvers.models.*.effect_blocks) used to measure σ per effect.
REF_SIZES = {
    "accel-tabletop": {"temperature_bias": 5e-3, "time_drift": 0.05, "quadratic": 5e-4, "scale_asymmetry": 5e-3},
    "gyro-drift": {"temperature_bias": 3e-4, "time_drift": 3e-2, "g_sensitivity": 1e-4},
    "accel-centrifuge": {
        "temperature_bias": 1e-4,
        "time_drift": 1e-4,
        "misalignment": 1e-4,
        "cubic": 1e-8,
        "lever_arm": 1e-3,
    },
    "compass": {
        "temperature_bias": 2.0,
        "time_drift": 20.0,
        "mag_accel_misalignment": 0.02,
        "field_anomaly": 0.02,
        "time_varying_hard_iron": 1.0,
    },
    "ldv": {"temperature_bias": 2e-3, "time_drift": 0.02, "time_delay": 0.01, "lever_arm": 0.1, "offset": 0.01},
}
# effects a simulation cannot hide: earth_rate is always in the simulated gyro input
NOT_HIDEABLE = {"earth_rate"}


def run_one(procedure: str, seed: int, effects: dict | None = None) -> dict:
    from station.procedures.diagnose import analyse

    sim = simulate(procedure, seed=seed, effects=effects or {}, **OPTIONS[procedure])
    cap = Capture(meta=sim.meta, columns=sim.columns, path=f"sim-{procedure}-{seed}.csv")
    t0 = time.perf_counter()
    out, diag, _ = analyse(cap)
    dt = time.perf_counter() - t0
    cv0 = out["baseline"]["cv_rms"]  # noqa: F841
    # in units of the procedure's F (a candidate tested on one row kind alone: its own F rescaled)
    F = diag.problem.threshold
    score = max([d["score"] * F / d["F"] for d in diag.deviance.values() if d["cv_lower"] and d["k"] > 0] + [0.0])
    n = len(diag.problem.sigma)
    dchi = {}
    for c in out["candidates"]:
        if c.get("delta_bic") is not None:
            dchi[c["name"]] = c["delta_bic"]
    dev = {k: v["D"] for k, v in diag.deviance.items()}
    return {
        "verdict": out["verdict"],
        "score": score,
        "seconds": dt,
        "delta_bic": dchi,
        "n": n,
        "deviance": dev,
        "confused": {e["name"]: [x["name"] for x in e["confused_with"]] for e in out["effects"]},
    }


def _job(args):
    try:
        return run_one(*args)
    except Exception as exc:  # a refused capture counts as its own outcome
        return {"error": f"{type(exc).__name__}: {exc}"}


def null_rates(procedures, trials, jobs, seed0=1000):
    from solvers.diagnose.problems import THRESHOLDS

    print(f"# null captures: {trials} per procedure")
    print(
        f"{'procedure':<18} {'false alarms':>13} {'rate':>7} {'95% score':>10} {'99% score':>10} {'threshold':>10} {'s/capture':>10} errors"
    )
    for p in procedures:
        with ProcessPoolExecutor(jobs) as ex:
            res = list(ex.map(_job, [(p, seed0 + k) for k in range(trials)]))
        ok = [r for r in res if "error" not in r]
        fa = sum(1 for r in ok if r["verdict"])
        scores = np.array([r["score"] for r in ok])
        q95 = float(np.percentile(scores, 95)) if len(scores) else math.nan
        q99 = float(np.percentile(scores, 99)) if len(scores) else math.nan
        secs = np.mean([r["seconds"] for r in ok]) if ok else math.nan
        print(
            f"{p:<18} {fa:>6}/{len(ok):<6} {100 * fa / max(len(ok), 1):6.1f}% {q95:10.1f} {q99:10.1f} {THRESHOLDS[p]:10.2f} "
            f"{secs:10.2f} {len(res) - len(ok)}",
            flush=True,
        )


def sigma_sizes(procedure: str) -> dict:
    """Size of each effect at 1 sigma of what this capture design resolves."""
    out = {}
    for name, ref in REF_SIZES[procedure].items():
        vals = []
        for seed in (1, 2, 3):
            r = _job((procedure, 500 + seed, {name: ref}))
            if "error" in r or name not in r["delta_bic"]:
                continue
            k = 3 if name not in ("field_anomaly", "time_delay") else 1
            dchi2 = -r["delta_bic"][name] + k * math.log(r["n"])
            if dchi2 > 0:
                vals.append(ref / math.sqrt(dchi2))
        out[name] = float(np.median(vals)) if vals else math.nan
    return out


def _trial(args):
    """One capture's pattern at k sigma for each k: the reference size gives this seed's
    deviance D_ref (≈ (size/σ)² when the effect dominates the noise), then the same seed
    (same pattern, same noise) is simulated at ``ref · k / sqrt(D_ref)``."""
    p, name, seed, ref, ks = args
    r = _job((p, seed, {name: ref}))
    if "error" in r or not r.get("deviance", {}).get(name):
        return None
    s1 = ref / math.sqrt(max(r["deviance"][name], 1e-12))
    out = []
    for k in ks:
        rk = _job((p, seed, {name: k * s1}))
        out.append(None if "error" in rk else (name in rk["verdict"]))
    return s1, out


def detection(procedures, trials, jobs, ks):
    print(f"\n# detection rate against size (k sigma of what each capture resolves), {trials} captures per cell")
    for p in procedures:
        for name, ref in REF_SIZES[p].items():
            if name in NOT_HIDEABLE:
                continue
            with ProcessPoolExecutor(jobs) as ex:
                res = list(ex.map(_trial, [(p, name, 2000 + j, ref, ks) for j in range(trials)]))
            res = [r for r in res if r is not None]
            if not res:
                print(f"{p:<18} {name:<24} unresolvable in this design (no σ)", flush=True)
                continue
            s1 = float(np.median([r[0] for r in res]))
            row = []
            for i, k in enumerate(ks):
                hits = [r[1][i] for r in res if r[1][i] is not None]
                row.append(f"{k:g}σ {100 * sum(hits) / max(len(hits), 1):5.1f}%")
            print(f"{p:<18} {name:<24} 1σ ≈ {s1:.3g}   " + "   ".join(row), flush=True)


def runtime():
    """A one-hour 100 Hz static gyro capture (P4 mode B, 360,000 rows) and a one-hour 100 Hz LDV."""
    from station.procedures.diagnose import analyse

    print("\n# runtime, one-hour 100 Hz captures (analyse(), capture in memory)")
    for p, opts in (
        ("gyro-drift", {"duration_s": 3600.0, "rate_hz": 100.0}),
        ("ldv", {"duration_s": 3600.0, "rate_hz": 100.0}),
    ):
        sim = simulate(p, seed=7, **opts)
        cap = Capture(meta=sim.meta, columns=sim.columns, path="hour.csv")
        n = len(next(iter(sim.columns.values())))
        t0 = time.perf_counter()
        from station.calibrate import calibrate_capture

        calibrate_capture(cap)
        t_cal = time.perf_counter() - t0
        t0 = time.perf_counter()
        analyse(cap)
        t_diag = time.perf_counter() - t0
        print(
            f"{p:<12} rows {n:>8}  diagnose {t_diag:6.2f} s   (calibrate alone {t_cal:5.2f} s, "
            f"ratio {t_diag / max(t_cal, 1e-9):.1f})  target < 5 s",
            flush=True,
        )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--det-trials", type=int, default=None, help="captures per detection cell (default trials/4)")
    ap.add_argument("--null-only", action="store_true")
    ap.add_argument("--skip-null", action="store_true")
    ap.add_argument("--skip-runtime", action="store_true")
    ap.add_argument("--procedures", default=",".join(OPTIONS))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument(
        "--null-seed0",
        type=int,
        default=1000,
        help="first seed of the null captures (1000: the set the thresholds were calibrated on; "
        "use another for an independent check)",
    )
    ap.add_argument("--sizes", default="3,5,8")
    a = ap.parse_args(argv)
    procs = [p for p in a.procedures.split(",") if p]
    if not a.skip_null:
        null_rates(procs, a.trials, a.jobs, a.null_seed0)
    if not a.null_only:
        detection(procs, a.det_trials or max(a.trials // 4, 10), a.jobs, [float(x) for x in a.sizes.split(",")])
        if not a.skip_runtime:
            runtime()
    return 0


if __name__ == "__main__":
    sys.exit(main())
