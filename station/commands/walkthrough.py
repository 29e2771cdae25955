"""`station walkthrough [--procedure P] [--seed N]`: simulate, calibrate, compare with the truth.

A headless end-to-end run of one procedure on the simulator: what a newcomer (or CI)
can run with no device and no screen.
"""

from __future__ import annotations

import argparse
import os
import tempfile

from station.commands.simulate import seed_arg
from station.procedures import registry


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("walkthrough", help="simulate a capture, calibrate it and compare with the truth")
    p.add_argument(
        "--procedure",
        default=registry.DEFAULT,
        choices=registry.names(),
        metavar="P",
        help=registry.one_of(registry.names()),
    )
    p.add_argument("--seed", type=seed_arg, default=1)
    p.set_defaults(func=run)


def _flat(prefix, v):
    import numpy as np

    a = np.asarray(v, dtype=float)
    if a.ndim == 0:
        return {prefix: float(a)}
    return {prefix + "".join(f"[{i}]" for i in idx): float(a[idx]) for idx in np.ndindex(*a.shape)}


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from solvers.simulate import simulate
    from station.calibrate import calibrate_capture, format_text, jsonable
    from station.capture import Capture, read_capture, write_capture

    sim = simulate(args.procedure, seed=args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, f"{args.procedure}.capture.csv")
        write_capture(path, Capture(meta=sim.meta, columns=sim.columns, path=path))
        capture = read_capture(path)
        print(
            f"1. simulated {args.procedure} (seed {args.seed}): {capture.n_rows} rows in a temporary capture "
            f"(station simulate --procedure {args.procedure} --seed {args.seed} --out FILE keeps one)"
        )
        result = calibrate_capture(capture)
    print("2. calibrated:\n")
    print(format_text(result))
    print("\n3. against the simulator's truth (estimate − truth, in σ):")
    params, unc, truth = jsonable(result.get("params", {})), jsonable(result.get("uncertainty", {})), sim.truth
    for j in (1, 2, 3):  # P5 reports per beam; the truth per quantity
        beam = params.pop(f"beam{j}", None)
        if isinstance(beam, dict):
            for key in ("dK", "alpha_deg", "beta_deg", "gamma_deg"):
                if key in beam and key in truth:
                    params[f"beam{j}.{key}"] = beam[key]
                    unc[f"beam{j}.{key}"] = unc.get(f"beam{j}", {}).get(key)
                    truth = {**truth, f"beam{j}.{key}": truth[key][j - 1]}
    for name, value in params.items():
        if name not in truth or not isinstance(value, (list, float, int)):
            continue
        sig_v = unc.get(name)
        if sig_v is None:
            continue
        sig_v = np.where(np.asarray(sig_v, dtype=object) == None, np.nan, sig_v).astype(float)  # noqa: E711
        est, sig, tru = _flat(name, value), _flat(name, sig_v), _flat(name, truth[name])
        zs = [
            (k, (est[k] - tru[k]) / sig[k])
            for k in est
            if k in tru and sig.get(k) and np.isfinite(sig[k]) and sig[k] > 0
        ]
        if zs:
            print("   " + name + ": " + ", ".join(f"{z:+.1f}" for _, z in zs))
    return 0
