"""What k σ allows: the best detection rate a test that does not know an effect's direction can have.

The generator (``diag_generator.size_for``) sizes a hidden effect by the amplitude SNR of its
*true* signature, a matched filter that knows the pattern. Diagnose does not know it: a
candidate with k free parameters is tested by its deviance against ``χ²_k(1 − α/m)`` (one of
m candidates, α = 5 % per procedure). With the noise known exactly and white, and no held-out
test, a k σ effect passes with probability ``P(χ²_k(λ = k_σ²) > χ²_k(1 − α/m))``: no test of
that level does better in all directions. This prints it per procedure and canonical effect,
with k and m counted from the problems diagnose builds on the generator's own captures.

    python benchmarks/diagnose_ceiling.py [--sigma 3.5] [--captures 8] [--seed0 530000]
"""

from __future__ import annotations

import argparse
import collections
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.stats import chi2, ncx2

sys.path.insert(0, str(Path(__file__).resolve().parent))
import diag_generator as G  # noqa: E402

from solvers.diagnose.engine import ALPHA  # noqa: E402
from station.calibrate import calibrate_capture, procedure_module  # noqa: E402
from station.capture import read_capture  # noqa: E402


def _problem(proc: str, seed: int):
    sc = G.SCENARIOS[proc](np.random.default_rng(seed))
    r = G.RENDER[proc](sc)
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "capture.csv")
        G.write_csv(path, r.meta, r.columns)
        cap = read_capture(path)
        mod = procedure_module(cap.procedure, cap.path)
        prep = mod.prepare(cap)
        base = calibrate_capture(cap, prepared=prep) if mod.DIAGNOSIS_BASELINE else None
        return mod.diagnosis_input(cap, base, prep).problem


def _k(c) -> int:
    free = c.free if c.free is not None else {b: True for b in c.blocks}
    n = sum(
        int(np.sum(np.broadcast_to(np.asarray(f), np.shape(c.blocks[b])))) for b, f in free.items() if b in c.blocks
    )
    return n + (1 if c.scan is not None else 0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sigma", type=float, default=3.5)
    ap.add_argument("--captures", type=int, default=8)
    ap.add_argument("--seed0", type=int, default=530000)
    a = ap.parse_args(argv)
    lam = a.sigma**2
    print(f"| procedure | effect | k | m | ceiling at {a.sigma:g}σ |")
    print("|---|---|---|---|---|")
    for proc in G.PROCEDURES:
        ks, ms = collections.defaultdict(list), []
        for j in range(a.captures):
            try:
                prob = _problem(proc, a.seed0 + j)
            except Exception:  # noqa: BLE001 - a capture the procedure refuses tells nothing here
                continue
            live = [c for c in prob.candidates if c.reason is None and c.blocks]
            ms.append(len(live))
            for c in live:
                ks[c.name].append(_k(c))
        m = int(np.median(ms))
        for eff in G.CANONICAL[proc]:
            if not ks.get(eff):
                print(f"| {proc} | {eff} | — | {m} | — |")
                continue
            k = int(np.median(ks[eff]))
            p = ncx2.sf(chi2.isf(ALPHA / m, k), k, lam)
            print(f"| {proc} | {eff} | {k} | {m} | {100 * p:.0f} % |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
