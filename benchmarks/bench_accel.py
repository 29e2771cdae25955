"""Accelerometer calibration benchmark (P1 level table, P2 centrifuge): efficiency against the
Cramér–Rao bound, coverage of the reported σ, solve time.

    python benchmarks/bench_accel.py [--trials N] [--jobs J] [--only p1|p2]

P1. Each trial is a new simulated capture (``solvers.simulate`` 'accel-tabletop', the 12
source positions, 20 s each at 100 Hz, 0.01 m/s² white noise per axis, averaged to a table;
placement error up to 0.5° on the ±axis positions and up to 3° on the 45°/135° positions;
table tilt 0.5°; bias instability off, because a position average cannot tell it from the
signal and the per-position std/sqrt(n) does not contain it). The station's estimator
(step 8, then the norm fit in the table gauge) is compared with the truth; each error is
divided by sqrt(CRLB) of that trial, the CRLB being the inverse Fisher information ``JᵀWJ`` of
the same measurement model at the truth: one norm row per position (σ = noise/sqrt(n)) and
two perpendicular vector rows per labelled position (σ = g × the true placement spread per
component: max/3 for a uniform angle on a random axis, and τ/sqrt(2) for the table tilt τ
seen at a random heading). Efficiency = RMS over trials of that ratio (1 = efficient; target
<= 1.05). Beside it: step 8 alone (the source's linear solution) against the same bound.

P2. Each trial: 'accel-centrifuge' (20 orientations × 3 speeds, the paper's geometry, a truth
drawn near the paper's, 1e-5 g white output noise). Exact fit (``--method exact``) and the
paper's method (``--method paper``, and its consistent third-order variant) against the CRLB
of the norm model (``|f(N)| = ρ``, σ propagated from the output noise, at the truth).

Solve time: median per calibration, against a baseline measured in the same run (P1: step 8
alone, the source's method; P2: the paper's linear least squares). Targets: P1 with 12
positions < 20 ms; P2 with 60 rows < 100 ms.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from solvers import centrifuge as CF  # noqa: E402
from solvers import tabletop as T  # noqa: E402
from solvers.models import accel  # noqa: E402
from solvers.simulate import simulate  # noqa: E402

P1_OPTS = dict(
    averages=True,
    bias_instability_mps2=0.0,
    table_tilt_deg=0.5,
    placement_deg=0.5,
    tilted_placement_deg=3.0,
    noise_mps2=0.01,
    hold_s=20.0,
)
P1_NAMES = [f"B[{i}]" for i in range(3)] + [f"M[{i}][{j}]" for i in range(3) for j in range(3)]
P2_NAMES = [f"{k}[{i}]" for k in "SbD" for i in range(3)]


def p1_positions(sim) -> list[T.Position]:
    c = sim.columns
    out = []
    for k, lab in enumerate(c["position"]):
        d, s = T.known_direction(lab)
        out.append(
            T.Position(
                lab,
                np.array([c["ax"][k], c["ay"][k], c["az"][k]]),
                np.array([c["ax_std"][k], c["ay_std"][k], c["az_std"][k]]),
                int(c["n"][k]),
                direction=d,
                placement_sigma_rad=s,
            )
        )
    return out


def p1_crlb(pos, B, M, g, opts) -> np.ndarray:
    """Inverse Fisher information of (B, M) at the truth (see module docstring)."""
    V = np.array([p.mean for p in pos])
    n = np.array([p.n for p in pos], dtype=float)
    _, Jn = accel.p1_norm_jacobian(V, B, M)
    rows, w = [Jn], [n / opts["noise_mps2"] ** 2]
    tilt2 = math.radians(opts["table_tilt_deg"]) ** 2 / 2.0
    for k, p in enumerate(pos):
        if p.direction is None:
            continue
        big = p.label[:2] in ("xy", "yz", "xz")
        place = math.radians(opts["tilted_placement_deg"] if big else opts["placement_deg"]) / 3.0
        var = g * g * (place**2 + tilt2) + opts["noise_mps2"] ** 2 / n[k]
        E = T.perp_basis(p.direction)
        rows.append(np.hstack([E, (E[:, :, None] * V[k][None, None, :]).reshape(2, 9)]))
        w.append(np.full(2, 1.0 / var))
    J = np.vstack(rows)
    W = np.concatenate(w)
    return np.linalg.inv(J.T @ (J * W[:, None]))


UPPER = [0, 1, 2, 3, 4, 5, 7, 8, 11]
P1U_NAMES = [P1_NAMES[k] for k in UPPER]


def p1_crlb_upper(pos, Bu, Mu, opts) -> np.ndarray:
    """The same for the upper-triangular gauge: norm rows only, 9 parameters."""
    V = np.array([p.mean for p in pos])
    n = np.array([p.n for p in pos], dtype=float)
    J = accel.p1_norm_jacobian(V, Bu, Mu)[1][:, UPPER]
    W = n / opts["noise_mps2"] ** 2
    return np.linalg.inv(J.T @ (J * W[:, None]))


def p1_trial(seed: int):
    sim = simulate("accel-tabletop", seed=seed, **P1_OPTS)
    pos = p1_positions(sim)
    g = sim.truth["g_mps2"]
    B, M = np.array(sim.truth["B"]), np.array(sim.truth["M"])
    truth = np.r_[B, M.ravel()]
    crlb = np.sqrt(np.diag(p1_crlb(pos, B, M, g, P1_OPTS)))
    t0 = time.perf_counter()
    r = T.calibrate(pos, g)
    t1 = time.perf_counter()
    s8 = T.step8(pos, g)
    t2 = time.perf_counter()
    est = np.r_[r.B, r.M.ravel()]
    sig = np.r_[r.sigma_B, r.sigma_M.ravel()]
    e8 = np.r_[s8["B"], s8["M"].ravel()]
    ru = T.calibrate(pos, g, gauge="upper-triangular")
    Bu, Mu = T.to_upper(B, M)
    cu = np.sqrt(np.diag(p1_crlb_upper(pos, Bu, Mu, P1_OPTS)))
    zu = (np.r_[ru.B, ru.M.ravel()] - np.r_[Bu, Mu.ravel()])[UPPER] / cu
    return (est - truth) / crlb, (e8 - truth) / crlb, (est - truth) / sig, zu, t1 - t0, t2 - t1


def p2_trial(seed: int):
    sim = simulate("accel-centrifuge", seed=seed, noise_g=1e-5)
    N = np.column_stack([sim.columns[c] for c in ("ax", "ay", "az")])
    rho = CF.norm_target(sim.columns["speed_rad_s"], sim.truth["radius_m"], sim.truth["g_mps2"])
    truth_p = {k: np.array(sim.truth[k]) for k in "SbD"}
    truth = np.concatenate([truth_p[k] for k in "SbD"])
    _, J, _ = accel.p2_norm_jacobian(N, truth_p)
    sr = CF.row_sigma(N, truth_p, 1e-5)
    crlb = np.sqrt(np.diag(np.linalg.inv((J / sr[:, None]).T @ (J / sr[:, None]))))
    t0 = time.perf_counter()
    e = CF.exact_fit(N, rho)
    t1 = time.perf_counter()
    p = CF.paper_fit(N, rho)
    t2 = time.perf_counter()
    p3 = CF.paper_fit(N, rho, variant="third-order")
    t3 = time.perf_counter()
    CF.screen_rows(N, rho)
    t4 = time.perf_counter()

    def vec(r):
        return np.concatenate([r.params[k] for k in "SbD"])

    zs = np.concatenate([e.sigma[k] for k in "SbD"])
    return (
        (vec(e) - truth) / crlb,
        (vec(p) - truth) / crlb,
        (vec(p3) - truth) / crlb,
        (vec(e) - truth) / zs,
        t1 - t0,
        t2 - t1,
        t4 - t3,
    )


def run(fn, seeds, jobs):
    if jobs <= 1:
        return [fn(s) for s in seeds]
    with ProcessPoolExecutor(jobs) as ex:
        return list(ex.map(fn, seeds, chunksize=16))


def timing(fn, n: int) -> tuple[float, ...]:
    """Median solve times over ``n`` trials run in this process alone (no parallel load)."""
    fn(10_000)  # warm-up
    out = [fn(10_001 + k) for k in range(n)]
    k0 = 4 if fn is p1_trial else 4
    return tuple(float(np.median([o[k] for o in out])) for k in range(k0, len(out[0])))


def eff(z) -> np.ndarray:
    return np.sqrt(np.mean(np.asarray(z) ** 2, axis=0))


def table(names, cols: dict[str, np.ndarray]) -> str:
    head = f"{'parameter':<10}" + "".join(f"{k:>14}" for k in cols)
    lines = [head]
    for i, n in enumerate(names):
        lines.append(f"{n:<10}" + "".join(f"{v[i]:>14.3f}" for v in cols.values()))
    lines.append(f"{'max':<10}" + "".join(f"{np.max(v):>14.3f}" for v in cols.values()))
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=1000)
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--only", choices=("p1", "p2"), default=None)
    args = ap.parse_args(argv)
    seeds = list(range(args.trials))
    if args.only in (None, "p1"):
        t = time.perf_counter()
        out = run(p1_trial, seeds, args.jobs)
        z, z8, zs, zu, _, _ = (np.array(x) for x in zip(*out))
        print(
            f"P1 level table: {args.trials} trials ({time.perf_counter() - t:.0f} s), 12 positions, noise 0.01 "
            "m/s², placement 0.5°/3°, table tilt 0.5°"
        )
        print("efficiency = RMS(error / sqrt(CRLB)) (target <= 1.05 for the station's estimator)")
        print(table(P1_NAMES, {"station": eff(z), "mean err/CRLB": np.mean(z, axis=0), "step 8 only": eff(z8)}))
        print("upper-triangular gauge (the 9 parameters the norm condition determines), against its own CRLB:")
        print(table(P1U_NAMES, {"upper-tri": eff(zu)}))
        print(
            f"coverage of the reported σ: {100 * np.mean(np.abs(zs) < 1):.1f} % within 1σ, "
            f"{100 * np.mean(np.abs(zs) < 2):.1f} % within 2σ (expect 68.3, 95.4)"
        )
        ts, t8 = timing(p1_trial, 40)
        print(
            f"solve time, 12 positions (one process, 40 calibrations): median {1e3 * ts:.1f} ms (target < 20 ms); "
            f"baseline step 8 alone {1e3 * t8:.2f} ms; ratio {ts / t8:.1f}"
        )
        print()
    if args.only in (None, "p2"):
        t = time.perf_counter()
        out = run(p2_trial, seeds, args.jobs)
        ze, zp, zp3, zs, te, tp, tsc = (np.array(x) for x in zip(*out))
        print(f"P2 centrifuge: {args.trials} trials ({time.perf_counter() - t:.0f} s), 60 rows, noise 1e-5 g")
        print("efficiency = RMS(error / sqrt(CRLB)) (target <= 1.05 for exact)")
        print(table(P2_NAMES, {"exact": eff(ze), "paper": eff(zp), "paper 3rd ord": eff(zp3)}))
        print(
            f"coverage of the exact fit's σ (noise estimated from residuals): {100 * np.mean(np.abs(zs) < 1):.1f} % "
            f"within 1σ, {100 * np.mean(np.abs(zs) < 2):.1f} % within 2σ"
        )
        te, tp, tsc = timing(p2_trial, 40)
        print(
            f"solve time, 60 rows (one process, 40 calibrations): exact {1e3 * te:.1f} ms (target < 100 ms), row "
            f"screening {1e3 * tsc:.1f} ms; baseline paper's method {1e3 * tp:.1f} ms; ratio exact/paper "
            f"{te / tp:.1f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
