"""The compass's slow effects at 3.5σ on captures whose hard iron is held still.

    python benchmarks/bench_compass_still.py [--trials 15] [--nulls 40] [--k 3.5] [--seed0 450000]

The independent generator's compass scenarios (benchmarks/diag_generator.py) with the hard
iron's wander set to zero (``gm_nT = 0``): per slow effect, how many of ``--trials`` captures
name it at ``--k`` σ, and how many of ``--nulls`` nulls name anything. It separates what the
compass's F (set by the nulls whose hard iron wanders most) costs on a device that does not
wander (docs/benchmarks.md, "Compass at 3.5σ: the wander measured on the residual before the
fit"). Trial seeds follow bench_diagnose_independent.py; null seeds are ``seed0 + 5000 + j``.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import warnings
import zlib
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import diag_generator as G  # noqa: E402

EFFECTS = ("temperature_bias", "time_drift", "time_varying_hard_iron")


def _verdict(rendered) -> list:
    from station.capture import read_capture
    from station.procedures.diagnose import analyse

    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "capture.csv")
        G.write_csv(path, rendered.meta, rendered.columns)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out, _, _ = analyse(read_capture(path))
    return out["verdict"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=15)
    ap.add_argument("--nulls", type=int, default=40)
    ap.add_argument("--k", type=float, default=3.5)
    ap.add_argument("--seed0", type=int, default=450000)
    a = ap.parse_args(argv)
    for eff in EFFECTS:
        hit = tot = 0
        for j in range(a.trials):
            seed = a.seed0 + 1000 * (1 + zlib.crc32(eff.encode()) % 97) + j
            sc = G.scenario_for("compass", np.random.default_rng(seed), eff)
            if sc is None:
                continue
            sc["gm_nT"] = 0.0
            size, _ = G.size_for(sc, eff, a.k)
            if not math.isfinite(size):
                continue
            tot += 1
            hit += eff in _verdict(G.RENDER["compass"](sc, eff, size))
        print(f"compass  {eff:24s} {a.k:g}σ, hard iron still: named {hit} of {tot}", flush=True)
    fa = 0
    for j in range(a.nulls):
        sc = G.SCENARIOS["compass"](np.random.default_rng(a.seed0 + 5000 + j))
        sc["gm_nT"] = 0.0
        fa += bool(_verdict(G.RENDER["compass"](sc)))
    print(f"compass  nulls, hard iron still: {fa} of {a.nulls} name anything")
    return 0


if __name__ == "__main__":
    sys.exit(main())
