"""A large effect, named alone: each canonical effect far above what the capture resolves, through
``station diagnose --json`` as a user runs it.

    nice -n 10 python benchmarks/bench_large_effects.py [--mults 30,300] [--seeds 3] [--realistic 8]

- ``--mults``: the station's own simulator (``station simulate``'s models), every canonical
  effect at k times its 1σ size (``SIGMA_1`` of tests/test_diagnose.py, what a default capture
  resolves), seeds 1..``--seeds``;
- ``--realistic N``: the independent generator (benchmarks/diag_generator.py) at sizes a real
  bench has, whatever σ they come to: a P2 lever arm of 1, 3 and 10 cm (each accelerometer at its
  own radius) and installation errors of 1e-3 and 5e-3 rad, N scenarios each (seeds 450200+,
  tuning seeds).

A capture is clean when the hidden name is in the verdict and every other name is tied with it
(``confused_with``: the data cannot tell them apart). Printed: each capture that is not clean,
then the count per part. Nothing tells the code which effect was hidden.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path[:0] = [HERE, os.path.join(ROOT, "tests")]

REALISTIC = {"accel-centrifuge": {"lever_arm": (0.01, 0.03, 0.1), "misalignment": (1e-3, 5e-3)}}


def _diagnose(path: str) -> dict | str:
    r = subprocess.run(
        [sys.executable, "-m", "station", "diagnose", path, "--json"], capture_output=True, text=True, cwd=ROOT
    )
    return json.loads(r.stdout) if r.returncode == 0 else f"exit {r.returncode}: {r.stderr.strip()[-160:]}"


def _clean(res: dict, effect: str) -> bool:
    tied = {effect}
    for e in res["effects"]:
        names = {e["name"]} | {c["name"] for c in e.get("confused_with", [])}
        if effect in names:
            tied |= names
    return effect in res["verdict"] and all(v in tied for v in res["verdict"])


def _check(label: str, effect: str, write) -> bool:
    """Write a capture with ``write(path)``, diagnose it and say whether it is clean (printed when not)."""
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "c.csv")
        write(path)
        res = _diagnose(path)
    if isinstance(res, str):
        print(f"  {label}: {res}", flush=True)
        return False
    if not _clean(res, effect):
        print(f"  {label}: {res['verdict']}", flush=True)
        return False
    return True


def own(mults: list[float], seeds: int) -> None:
    from test_diagnose import OPTIONS, SIGMA_1

    from solvers.simulate import simulate
    from station.capture import Capture, write_capture

    for k in mults:
        bad = tot = 0
        for proc, effects in SIGMA_1.items():
            for effect, s1 in effects.items():
                for seed in range(1, seeds + 1):
                    sim = simulate(proc, seed=seed, effects={effect: s1 * k}, **OPTIONS[proc])
                    cap = Capture(meta=dict(sim.meta), columns=dict(sim.columns))
                    tot += 1
                    bad += not _check(
                        f"{proc} {effect} {k:g}σ seed {seed}", effect, lambda p, c=cap: write_capture(p, c)
                    )
        print(f"own simulator at {k:g}σ: {tot - bad} of {tot} clean", flush=True)


def realistic(n: int) -> None:
    import diag_generator as G

    for proc, effects in REALISTIC.items():
        for effect, sizes in effects.items():
            for size in sizes:
                bad = 0
                for j in range(n):
                    seed = 450200 + j
                    sc = G.scenario_for(proc, np.random.default_rng(seed), effect)
                    r = G.RENDER[proc](sc, effect, size)
                    label = f"{proc} {effect} {size:g} seed {seed}"
                    bad += not _check(label, effect, lambda p, r=r: G.write_csv(p, r.meta, r.columns))
                print(f"independent generator, {proc} {effect} = {size:g}: {n - bad} of {n} clean", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mults", default="30,300", help="k of k×σ on the station's simulator ('' for none)")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--realistic", type=int, default=8, help="scenarios per realistic size (0 for none)")
    a = ap.parse_args(argv)
    if a.mults:
        own([float(x) for x in a.mults.split(",")], a.seeds)
    if a.realistic:
        realistic(a.realistic)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
