"""Gyro calibration from P1 rotations: the station against imu_tk, and simulated coverage.

Part 1, imu_tk's own Xsens recording (``../shared/data/imu_tk_xsens``):

- imu_tk's own output: its test app (``apps/test_imu_calib.cpp``, commit 7780270) built against
  Ceres 2.1 and run on ``xsens_acc.mat``/``xsens_gyro.mat`` printed the gyro parameters in
  ``IMU_TK_PRINTED`` below (misalignment T, scale s, bias b: ω = T diag(s) (y − b)).
- The figure of merit: the angle between each hold's measured gravity direction and the previous
  hold's direction carried across the motion by a gyro calibration, on the station's holds and
  accelerometer calibration (the same for every gyro calibration compared).
- Held out: leave poses out (5 folds: every 5th pose after the initial rest); a fold's fit uses
  neither the held-out holds nor the motions into or out of them; the held-out figure is the
  residual on those motions. imu_tk's estimator for the folds is re-implemented here from its
  source (bias = mean over the first 50 s, 9 parameters T·diag(s), unweighted 3-component
  residual ``Rᵀ u_k − u_{k+1}``); on all poses it is checked against the printed output.

Part 2, coverage: simulated tabletop sessions (``solvers.simulate``, 12 + 4 positions, 50 Hz,
4 s holds and 2 s turns, gyro
scale ±1 %, misalignment ±5 mrad, g-sensitivity ±2e-4 rad/s per m/s², white noise 3 mrad/s,
Earth rate at 40° N); fraction of the 21 gyro parameters within 1σ and 2σ of the truth (in the
accelerometer calibration's frame).

    nice -n 10 python benchmarks/bench_tabletop_gyro.py [--seeds 500] [--skip-coverage | --coverage-only]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from solvers import tabletop as T  # noqa: E402
from solvers import tabletop_gyro as TG  # noqa: E402
from solvers.models import gyro  # noqa: E402
from station.capture import Capture, read_capture  # noqa: E402
from station.procedures import tabletop  # noqa: E402
from station.procedures import tabletop_gyro as TGP  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "imu_tk_xsens" / "imu_tk_xsens.capture.csv"
IMU_TK_PRINTED = {
    "T": np.array([[1, 0.00593634, 0.00111101], [0.00808812, 1, -0.0535569], [0.0253067, -0.0025513, 1]]),
    "s": np.array([0.000209295, 0.000209899, 0.000209483]),
    "b": np.array([32777.1, 32459.8, 32511.8]),
    "final_cost": 1.506956e-03,  # Ceres ½ Σ |r|², 37 residual blocks of 3
}


def imu_tk_as_model(T_, s, b) -> dict:
    """imu_tk's ω = T diag(s) (y − b) as the station's forward model y = K ω + ε."""
    return {"K": np.linalg.inv(T_ * s[None, :]), "eps": np.asarray(b, dtype=float)}


def imu_tk_fit(holds, motions, bias) -> dict:
    """imu_tk's gyro estimator: fixed bias, 9 parameters (6 misalignments, 3 scales),
    unweighted residual ``Rᵀ u_k − u_{k+1}`` per motion (3 components)."""
    b = TG.Batch(motions)
    u0 = np.array([holds[m.k0].u for m in motions])
    u1 = np.array([holds[m.k1].u for m in motions])

    def model(x):
        T_ = np.array([[1, x[0], x[1]], [x[2], 1, x[3]], [x[4], x[5], 1]])
        return T_, x[6:9]

    def fun(x):
        T_, s = model(x)
        w = (b.y - bias) @ (T_ * s[None, :]).T
        R = gyro.integrate_rates(w, b.t)
        return (np.einsum("mji,mj->mi", R, u0) - u1).ravel()

    x0 = np.r_[np.zeros(6), np.full(3, 1 / 6258.0)]
    sol = least_squares(fun, x0, x_scale="jac", xtol=1e-12, ftol=1e-12)
    T_, s = model(sol.x)
    return {**imu_tk_as_model(T_, s, bias), "T": T_, "s": s, "cost": 0.5 * float(sol.fun @ sol.fun)}


def station_inputs():
    cap = read_capture(DATA)
    w: list[str] = []
    pos, _, nk = tabletop.static_positions(cap, w)
    g = cap.local_gravity_mps2(w)
    acc = T.calibrate(pos, g, noise_known=nk)
    holds, motions, noise, _ = TGP.inputs(cap, pos, acc.B, acc.M)
    t = np.asarray(cap.columns["t"], dtype=float)
    y = np.column_stack([np.asarray(cap.columns[c], dtype=float) for c in ("gx", "gy", "gz")])
    rest_bias = y[t < t[0] + 50.0].mean(axis=0)  # imu_tk: setInitStaticIntervalDuration(50)
    return holds, motions, noise, rest_bias


def subset(holds, motions, keep: set[int]):
    """Holds in ``keep`` (renumbered) and the motions between two kept consecutive holds."""
    idx = sorted(keep)
    new = {k: i for i, k in enumerate(idx)}
    hs = [holds[k] for k in idx]
    ms = [TG.Motion(new[m.k0], new[m.k1], m.t_s, m.y, m.f_mps2) for m in motions if m.k0 in keep and m.k1 in keep]
    return hs, ms


def rms_deg(a) -> float:
    return math.degrees(float(np.sqrt(np.mean(np.square(a)))))


def part1() -> None:
    holds, motions, noise, rest_bias = station_inputs()
    K0 = np.eye(3) / IMU_TK_PRINTED["s"].mean()
    t0 = time.perf_counter()
    st = TG.calibrate(holds, motions, K0, noise_raw=noise)
    t_station = time.perf_counter() - t0
    st_nog = TG.calibrate(holds, motions, K0, noise_raw=noise, fit_g=False)
    t0 = time.perf_counter()
    tk = imu_tk_fit(holds, motions, rest_bias)
    t_tk = time.perf_counter() - t0
    printed = imu_tk_as_model(IMU_TK_PRINTED["T"], IMU_TK_PRINTED["s"], IMU_TK_PRINTED["b"])
    print("== imu_tk's Xsens recording: gyro parameters (ω = A (y − b), A = K⁻¹ = T diag(s)) ==")
    print(f"{len(holds)} holds, {len(motions)} rotations")

    def row(name, p, sig=None):
        A = np.linalg.inv(p["K"])
        s = np.diag(A)
        Tm = A / s[None, :]
        out = (
            f"{name:28s} 1/s = {1 / s[0]:8.2f} {1 / s[1]:8.2f} {1 / s[2]:8.2f}  "
            f"T01 {Tm[0, 1]:+.5f} T02 {Tm[0, 2]:+.5f} T10 {Tm[1, 0]:+.5f} T12 {Tm[1, 2]:+.5f} "
            f"T20 {Tm[2, 0]:+.5f} T21 {Tm[2, 1]:+.5f}  b = {p['eps'][0]:.1f} {p['eps'][1]:.1f} {p['eps'][2]:.1f}"
        )
        print(out)
        if sig is not None:
            print(f"{'':28s} σ(K diag) = {sig[0]:.2f} {sig[1]:.2f} {sig[2]:.2f} counts per rad/s")

    row("imu_tk (printed, C++)", printed)
    row("imu_tk (re-implemented)", tk)
    row("station", st.params(), np.diag(st.sigma_K))
    print(
        f"station g-sensitivity fitted: {st.G is not None}; reduced χ² {st.fit.reduced_chi2:.2f}; "
        f"fit {t_station:.2f} s, imu_tk re-implementation {t_tk:.2f} s"
    )
    print("\n== gravity direction residual after each rotation, in sample (RMS over 37, degrees) ==")
    print(
        f"imu_tk printed parameters : {rms_deg(TG.direction_residuals(printed, holds, motions)):.4f}"
        f"   (imu_tk's own cost {IMU_TK_PRINTED['final_cost']:.3e} = "
        f"{math.degrees(math.sqrt(2 * IMU_TK_PRINTED['final_cost'] / 37)):.4f}° RMS on its own holds)"
    )
    print(f"imu_tk re-implemented     : {rms_deg(TG.direction_residuals(tk, holds, motions)):.4f}")
    print(f"station                   : {rms_deg(st.direction_residual_rad):.4f}")
    print(f"station without G         : {rms_deg(st_nog.direction_residual_rad):.4f}")
    print("\n== held out: leave poses out, 5 folds (RMS over the held-out rotations, degrees) ==")
    all_tk, all_st, all_ng = [], [], []
    for fold in range(5):
        out = {k for k in range(1, len(holds)) if k % 5 == fold}
        train_h, train_m = subset(holds, motions, set(range(len(holds))) - out)
        test_m = [m for m in motions if m.k0 in out or m.k1 in out]
        st_f = TG.calibrate(train_h, train_m, K0, noise_raw=noise)
        tk_f = imu_tk_fit(train_h, train_m, rest_bias)
        ng_f = TG.calibrate(train_h, train_m, K0, noise_raw=noise, fit_g=False)
        all_ng.append(TG.direction_residuals(ng_f.params(), holds, test_m))
        r_st = TG.direction_residuals(st_f.params(), holds, test_m)
        r_tk = TG.direction_residuals(tk_f, holds, test_m)
        all_st.append(r_st)
        all_tk.append(r_tk)
        print(
            f"fold {fold}: {len(out)} poses out, {len(train_m)} rotations fitted, {len(test_m)} held out: "
            f"imu_tk {rms_deg(r_tk):.4f}  station {rms_deg(r_st):.4f}  station without G {rms_deg(all_ng[-1]):.4f}"
        )
    print(
        f"all folds: imu_tk {rms_deg(np.concatenate(all_tk)):.4f}  station {rms_deg(np.concatenate(all_st)):.4f}"
        f"  station without G {rms_deg(np.concatenate(all_ng)):.4f}"
    )


def part2(seeds: int, rate_hz: float = 50.0, extra: int = 4) -> None:
    from solvers.simulate import simulate

    print(f"\n== coverage over {seeds} simulated sessions ({12 + extra} positions, {rate_hz:g} Hz) ==", flush=True)
    z = {"K": [], "eps": [], "G": []}
    t0 = time.perf_counter()
    for seed in range(seeds):
        if seed and seed % 50 == 0:
            a = np.abs(np.concatenate([np.concatenate(v) for v in z.values()]))
            print(f"  {seed} sessions: 1σ {np.mean(a < 1):.3f}  2σ {np.mean(a < 2):.3f}", flush=True)
        sim = simulate(
            "accel-tabletop",
            seed=10_000 + seed,
            extra_positions=extra,
            hold_s=4,
            move_s=2,
            init_rest_s=10,
            rate_hz=rate_hz,
            gyro_scale_sigma=0.01,
            gyro_misalignment_sigma_rad=0.005,
            gyro_g_sensitivity=2e-4,
        )
        out = tabletop.calibrate(Capture(dict(sim.meta), dict(sim.columns)))
        gb = out["gyro"]
        R = np.array(out["params"]["M"]) @ np.linalg.inv(np.array(sim.truth["M"]))
        u, _, vt = np.linalg.svd(R)
        R = u @ vt
        tr = sim.truth["gyro"]
        truth = {"K": np.array(tr["K"]) @ R.T, "eps": np.array(tr["eps"]), "G": np.array(tr["G"]) @ R.T}
        for k in z:
            z[k].append(((np.array(gb["params"][k]) - truth[k]) / np.array(gb["uncertainty"][k])).ravel())
    dt = time.perf_counter() - t0
    allz = np.abs(np.concatenate([np.concatenate(v) for v in z.values()]))
    n = allz.size
    se1, se2 = math.sqrt(0.6827 * 0.3173 / n), math.sqrt(0.9545 * 0.0455 / n)
    print(
        f"all {n} values: within 1σ {np.mean(allz < 1):.3f} (expect 0.683 ± {se1:.3f}), "
        f"within 2σ {np.mean(allz < 2):.3f} (expect 0.954 ± {se2:.3f})"
    )
    for k, v in z.items():
        a = np.abs(np.concatenate(v))
        print(f"  {k:4s} {a.size:6d} values: 1σ {np.mean(a < 1):.3f}  2σ {np.mean(a < 2):.3f}")
    print(f"{dt / seeds:.2f} s per session (simulate + accelerometer + gyro calibration)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=500)
    ap.add_argument("--skip-coverage", action="store_true")
    ap.add_argument("--coverage-only", action="store_true")
    a = ap.parse_args()
    if not a.coverage_only:
        part1()
    if not a.skip_coverage:
        part2(a.seeds)


if __name__ == "__main__":
    main()
