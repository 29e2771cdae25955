"""P1 first-round scores on nulls and 3.5σ/10σ trials, to choose F (the threshold scale).

Time series only (tables of averages carry no slow-noise prior). Measured with it on branch
s30-p1-prior-experiment (docs/benchmarks.md, "P1 slow-noise prior (s30-p1)").

    nice -n 10 python benchmarks/bench_p1_scores.py --out FILE.json [--nulls 60] [--s27 DIR]
        [--trials 12] [--sizes 10,3.5] [--seed0 720000] [--trial-seed0 722000] [--jobs 2]

Per capture (benchmarks/diag_generator.py's P1 scenarios, and ``--s27 DIR``: the files of
``indep_s27_generator.py batch``), the same ``analyse`` as ``station diagnose`` is run and its
first round recorded: each candidate's score (the threshold scale F at which it would just pass
its deviance test) and whether it lowers the held-out RMS, plus the verdict. A null "passes at F"
when some candidate with a lower held-out RMS scores ≥ F; a trial's hidden effect passes at F
when its own candidate does. ``--table FILE [FILE ...]``: the ROC over c·F of each file.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_diagnose_independent as B  # noqa: E402
import diag_generator as G  # noqa: E402

PROC = "accel-tabletop"
SERIES_ONLY = True  # the prior is set on time series only: tables score the same before and after


FIRST: dict = {}


NO_PRIOR = False


def _no_prior() -> None:
    """The slow-noise prior left out (``set_slow_bias_prior`` sets the threshold only): the
    same F with the white rows alone."""
    from solvers.diagnose import problems as DP

    if getattr(DP, "_no_prior", False):
        return
    DP._no_prior = True

    def thr_only(prob, *a, **k):
        F = getattr(DP, "SLOW_PRIOR_THRESHOLDS", {}).get(prob.procedure)
        if F is not None:
            prob.generic_scale *= prob.threshold / F
            prob.threshold = F

    DP.set_slow_bias_prior = thr_only


def _paired() -> None:
    """Also score each first-round candidate without the slow-noise prior (``Problem.slow_cov``
    set aside for a second evaluation of the same candidate): the before/after of one run."""
    import solvers.diagnose.engine as E

    if getattr(E, "_paired", False):
        return
    E._paired = True
    orig_eval, orig_bound = E._evaluate, E._bound

    def ev_wrap(problem, cc, *a, **k):
        sc = problem.slow_cov
        infl0 = None
        if sc is not None:
            problem.slow_cov = None
            try:
                infl0 = orig_eval(problem, cc, *a, **k).infl
            finally:
                problem.slow_cov = sc
        ev = orig_eval(problem, cc, *a, **k)
        ev._infl0 = ev.infl if infl0 is None else infl0
        return ev

    def bound_wrap(problem, ev, m, n, rank_cur, scale=1.0):
        res = orig_bound(problem, ev, m, n, rank_cur, scale)
        name = ev.cc.cand.name
        if name not in FIRST and hasattr(ev, "_infl0"):
            infl = ev.infl
            ev.infl = ev._infl0
            try:
                FIRST[name] = orig_bound(problem, ev, m, n, rank_cur, scale)[1] / scale
            finally:
                ev.infl = infl
        return res

    E._evaluate, E._bound = ev_wrap, bound_wrap


def _first_round(out_diag):
    out, diag = out_diag
    dev = {
        k: {
            "score": float(v["score"]),
            "score0": float(FIRST.get(k, v["score"])),
            "cv_lower": bool(v["cv_lower"]),
            "F": float(v["F"]),
        }
        for k, v in diag.deviance.items()
    }
    return {"verdict": out["verdict"], "deviance": dev, "prior": bool(getattr(diag.problem, "slow_noise", {}))}


def _run_capture(path):
    import warnings

    from station.capture import read_capture
    from station.procedures.diagnose import analyse

    if NO_PRIOR:
        _no_prior()
    else:
        _paired()
    FIRST.clear()
    cap = read_capture(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out, diag, _ = analyse(cap)
    return _first_round((out, diag))


def _gen(meta, cols):
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "capture.csv")
        G.write_csv(path, meta, cols)
        return _run_capture(path)


def _null(seed):
    sc = G.SCENARIOS[PROC](np.random.default_rng(seed))
    r = G.RENDER[PROC](sc)
    try:
        return {"set": "nulls", "seed": seed, **_gen(r.meta, r.columns)}
    except Exception as exc:
        return {"set": "nulls", "seed": seed, "error": str(exc)[:200]}


def _s27(path):
    try:
        return {"set": "s27", "file": os.path.basename(path), **_run_capture(path)}
    except Exception as exc:
        return {"set": "s27", "file": os.path.basename(path), "error": str(exc)[:200]}


def sc_is_series(sc) -> bool:
    return sc["mode"] != "averages"


def _trial(args):
    effect, seed, k = args
    sc = G.scenario_for(PROC, np.random.default_rng(seed), effect)
    if sc is None:
        return None
    size, _ = G.size_for(sc, effect, k)
    r = G.RENDER[PROC](sc, effect, size)
    try:
        return {"set": f"{k:g}sigma", "effect": effect, "seed": seed, **_gen(r.meta, r.columns)}
    except Exception as exc:
        return {"set": f"{k:g}sigma", "effect": effect, "seed": seed, "error": str(exc)[:200]}


def table(files, cs=(1.0, 0.9, 0.8, 0.7, 0.6, 0.5, 0.4)) -> None:
    for f in files:
        rows = json.load(open(f)) if f.endswith(".json") else [json.loads(x) for x in open(f)]
        print(f"\n{f}")
        sets = sorted({r["set"] for r in rows})
        for s in sets:
            rs = [r for r in rows if r["set"] == s and "error" not in r]
            named = sum(bool(r["verdict"]) for r in rs)
            if s in ("nulls", "s27"):
                cells = []
                for c in cs:
                    n0 = sum(
                        any(v["cv_lower"] and v["score0"] >= c * v["F"] for v in r["deviance"].values()) for r in rs
                    )
                    n = sum(any(v["cv_lower"] and v["score"] >= c * v["F"] for v in r["deviance"].values()) for r in rs)
                    cells.append(f"c={c:g}: {n0}->{n}/{len(rs)}")
                print(f"  {s:<8} named {named}/{len(rs)}   first-round pass " + "  ".join(cells))
            else:
                for e in sorted({r["effect"] for r in rs}):
                    re_ = [r for r in rs if r["effect"] == e]
                    hit = sum(e in r["verdict"] for r in re_)
                    cells = []
                    for c in cs:
                        n0, n = (
                            sum(
                                e in r["deviance"]
                                and r["deviance"][e]["cv_lower"]
                                and r["deviance"][e][key] >= c * r["deviance"][e]["F"]
                                for r in re_
                            )
                            for key in ("score0", "score")
                        )
                        cells.append(f"c={c:g}: {n0}->{n}")
                    print(f"  {s:<8} {e:<18} named {hit}/{len(re_)}   hidden passes " + "  ".join(cells))


def _init(no_prior: bool) -> None:
    global NO_PRIOR
    NO_PRIOR = no_prior


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out")
    ap.add_argument("--nulls", type=int, default=60)
    ap.add_argument("--s27", default=None)
    ap.add_argument("--trials", type=int, default=12)
    ap.add_argument("--sizes", default="10,3.5")
    ap.add_argument("--seed0", type=int, default=720000)
    ap.add_argument("--trial-seed0", type=int, default=722000)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--table", nargs="*")
    ap.add_argument("--no-prior", action="store_true", help="the prior's F without the prior")
    a = ap.parse_args(argv)
    global NO_PRIOR
    NO_PRIOR = a.no_prior
    if a.table:
        table(a.table)
        return 0
    for s0 in (a.seed0, a.trial_seed0):
        if s0 + 100000 > B.FINAL_SEED0 and s0 < 700000:
            ap.error("tuning seeds only (700000+)")
    jobs = []
    s = a.seed0
    while len(jobs) < a.nulls:
        if not SERIES_ONLY or sc_is_series(G.SCENARIOS[PROC](np.random.default_rng(s))):
            jobs.append((_null, s))
        s += 1
    if a.s27:
        man = [json.loads(x) for x in open(os.path.join(a.s27, "manifest.jsonl"))]
        jobs += [(_s27, m["file"]) for m in man if m.get("series") or not SERIES_ONLY]
    for e in G.CANONICAL[PROC]:
        found = 0
        for j in range(10 * a.trials):
            seed = a.trial_seed0 + B._offset(e) + j
            sc = G.scenario_for(PROC, np.random.default_rng(seed), e)
            if sc is None or (SERIES_ONLY and not sc_is_series(sc)):
                continue
            for k in (float(x) for x in a.sizes.split(",") if x):
                jobs.append((_trial, (e, seed, k)))
            found += 1
            if found == a.trials:
                break
    with ProcessPoolExecutor(a.jobs, initializer=_init, initargs=(a.no_prior,)) as ex:
        futs = [ex.submit(f, x) for f, x in jobs]
        res = []
        with open(a.out + "l", "w") as part:  # each capture as it is done (FILE.jsonl)
            for fut in as_completed(futs):
                r = fut.result()
                if r is not None:
                    res.append(r)
                    part.write(json.dumps(r) + "\n")
                    part.flush()
    with open(a.out, "w") as fh:
        json.dump(res, fh, indent=0)
    table([a.out])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
