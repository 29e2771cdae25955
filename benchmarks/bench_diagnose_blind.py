"""`station diagnose` on captures of the blind generator (benchmarks/blind_generator.py), through the real CLI.

    nice -n 10 python benchmarks/bench_diagnose_blind.py --effects-n 5 --nulls 10 --seed0 540000 \
        [--procedures accel-tabletop,compass,gyro-drift] [--jsonl results.jsonl] [--keep DIR]

Seeds: capture seed = seed0 + 10000 * procedure index + 100 * effect index + i (effect index 0 = null),
so one capture is regenerated with `python benchmarks/blind_generator.py --procedure P --effect E --seed S`.
Prints per procedure and effect: named %, captures with a wrong extra name (one not tied to the hidden
effect by `confused_with`), nulls named, refusals (exit 2, with the message); then every miss,
wrong extra and false alarm with its scenario and what the JSON said.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import blind_generator as bg  # noqa: E402

PROCS = ["accel-tabletop", "compass", "gyro-drift", "accel-centrifuge", "ldv"]
STATION = Path(sys.executable).with_name("station")


def tied(eff_entries, a, b):
    """True when effects a and b are tied by `confused_with`, directly or through other tied names."""
    edges = {}
    for e in eff_entries:
        for c in e.get("confused_with", []):
            n = c.get("name") if isinstance(c, dict) else c
            edges.setdefault(e.get("name"), set()).add(n)
            edges.setdefault(n, set()).add(e.get("name"))
    seen, todo = {a}, [a]
    while todo:
        for n in edges.get(todo.pop(), ()):
            if n not in seen:
                seen.add(n)
                todo.append(n)
    return b in seen


def summarise_json(d):
    cands = [c for c in d.get("candidates", []) if c.get("delta_bic") is not None]
    cands.sort(key=lambda c: c["delta_bic"])
    top = [{"name": c["name"], "dBIC": round(c["delta_bic"], 1), "sel": bool(c.get("selected"))} for c in cands[:3]]
    unres = [c["name"] for c in d.get("candidates", []) if c.get("resolvable") is False]
    qual = {}
    resid = []
    for q in d.get("quality", []):
        qual[q["kind"]] = qual.get(q["kind"], 0) + 1
        if q["kind"] == "residuals_not_white":
            resid.append({k: q.get(k) for k in ("test", "p_value", "drivers") if k in q})
    effs = []
    for e in d.get("effects", []):
        effs.append(
            {
                "name": e.get("name"),
                "gain": round(e.get("gain") or 0, 3),
                "shape": e.get("shape"),
                "confused_with": [c.get("name") if isinstance(c, dict) else c for c in e.get("confused_with", [])],
            }
        )
    return {
        "verdict": d.get("verdict"),
        "top": top,
        "unresolvable": unres,
        "quality": qual,
        "residuals_not_white": resid,
        "effects": effs,
    }


def run_one(proc, effect, seed, tmp, timeout, opts=None):
    path = Path(tmp) / f"{proc}_{effect or 'none'}_{seed}.csv"
    sc = bg.generate(proc, effect, seed, str(path), **(opts or {}))
    t0 = time.time()
    try:
        r = subprocess.run(
            [str(STATION), "diagnose", str(path), "--json"],
            capture_output=True,
            text=True,
            timeout=timeout,
            env={**os.environ, "OPENBLAS_NUM_THREADS": "1"},
        )
        rc, out, err = r.returncode, r.stdout, r.stderr
    except subprocess.TimeoutExpired:
        rc, out, err = -9, "", f"timeout after {timeout} s"
    res = {
        "procedure": proc,
        "effect": effect or "none",
        "seed": seed,
        "rc": rc,
        "seconds": round(time.time() - t0, 1),
        "scenario": sc,
    }
    if rc == 0:
        d = json.loads(out)
        res.update(summarise_json(d))
        v = d.get("verdict") or []
        if effect:
            res["named"] = effect in v
            extras = [x for x in v if x != effect]
            res["tied_extras"] = [x for x in extras if res["named"] and tied(d.get("effects", []), effect, x)]
            res["wrong_extras"] = [x for x in extras if x not in res["tied_extras"]]
        else:
            res["named"] = bool(v)
            res["wrong_extras"] = list(v)
    else:
        res["message"] = (err.strip().splitlines() or [""])[-1]
    if not os.environ.get("BLIND_KEEP"):
        path.unlink(missing_ok=True)
    return res


def scenario_line(sc):
    keys = [
        "fs_hz",
        "n_positions",
        "n_holds",
        "order",
        "labels",
        "table_of_averages",
        "hold_s",
        "unit",
        "mode",
        "motion_rows",
        "latitude_in_meta",
        "hand_accel_mps2",
        "gyro",
        "duration_s",
        "n_mountings",
        "n_speeds",
        "a_max_g",
        "radius_m",
        "g_metadata",
        "vibration",
        "rig",
        "frame",
        "rate_columns",
        "cond_HtH",
        "soft_iron",
    ]
    s = ", ".join(f"{k}={sc[k]}" for k in keys if k in sc)
    t = sc.get("temperature", {})
    s += f", temp={t.get('kind')}" + (f" lag {t['sensor_lag_s']} s" if t.get("sensor_lag_s") else "")
    if t.get("speed_heating_c"):
        s += f" + {t['speed_heating_c']} C heating at top speed"
    nz = sc.get("noise") or sc.get("noise_deg_h") or []
    if nz:
        unit = " deg/h" if "noise_deg_h" in sc else ""
        s += (
            ", GM tau_s="
            + "/".join(f"{x['gm_tau']:.0f}" for x in nz)
            + ", GM sigma="
            + "/".join(f"{x['gm_sigma']:.2g}" for x in nz)
            + unit
            + ", white/sample="
            + "/".join(f"{x['white']:.2g}" for x in nz)
        )
    h = sc.get("hidden") or {}
    for k in ("angle_deg", "d_incl_deg", "magnitude_scale", "t_on_s", "noise_scaled_by"):
        if k in h:
            s += f", {k}={h[k]:.3g}"
    return s


def report(results):
    for r in results:  # ties recomputed from the stored effects (transitively)
        if r["rc"] == 0 and r["effect"] != "none":
            extras = [x for x in r["verdict"] if x != r["effect"]]
            r["wrong_extras"] = [x for x in extras if not (r["named"] and tied(r["effects"], r["effect"], x))]
    by = {}
    for r in results:
        by.setdefault((r["procedure"], r["effect"]), []).append(r)
    print("| procedure | effect | n | named | named, no wrong extra | wrong extra | refused | other errors |")
    print("|---|---|---|---|---|---|---|---|")
    for (proc, eff), rs in by.items():
        ok = [r for r in rs if r["rc"] == 0]
        ref = [r for r in rs if r["rc"] == 2]
        oth = [r for r in rs if r["rc"] not in (0, 2)]
        named = sum(r["named"] for r in ok)
        wrong = sum(bool(r["wrong_extras"]) for r in ok)
        clean = sum(r["named"] and not r["wrong_extras"] for r in ok)
        if eff == "none":
            print(f"| {proc} | (null) | {len(rs)} | {named} named (false alarms) | — | — | {len(ref)} | {len(oth)} |")
        else:
            pct = f"{100 * named / len(ok):.0f} %" if ok else "—"
            print(
                f"| {proc} | {eff} | {len(rs)} | {named}/{len(ok)} = {pct} | {clean} | {wrong} | {len(ref)} | "
                f"{len(oth)} |"
            )
    print()
    for r in results:
        bad = (
            r["rc"] != 0
            or (r["effect"] == "none" and r["named"])
            or (r["effect"] != "none" and (not r["named"] or r["wrong_extras"]))
        )
        if not bad:
            continue
        what = (
            "REFUSED"
            if r["rc"] == 2
            else (
                "ERROR"
                if r["rc"] != 0
                else ("FALSE ALARM" if r["effect"] == "none" else ("MISS" if not r["named"] else "WRONG EXTRA"))
            )
        )
        print(f"- {what} {r['procedure']} {r['effect']} seed {r['seed']}: {scenario_line(r['scenario'])}")
        if r["rc"] != 0:
            print(f"    message: {r.get('message')}")
            continue
        print(f"    verdict {r['verdict']}; top {r['top']}; effects {r['effects']}")
        print(f"    quality {r['quality']}; residuals_not_white {r['residuals_not_white']}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--procedures", default=",".join(PROCS))
    ap.add_argument("--effects", default="", help="comma list; default: every canonical effect of the procedure")
    ap.add_argument("--effects-n", type=int, default=5)
    ap.add_argument("--nulls", type=int, default=10)
    ap.add_argument("--seed0", type=int, default=540000)
    ap.add_argument("--timeout", type=float, default=900)
    ap.add_argument("--jsonl", default="")
    ap.add_argument("--report-only", default="", help="comma list of JSONL files of earlier runs: print their report")
    ap.add_argument("--keep", default="", help="keep the captures in this folder")
    ap.add_argument(
        "--gen-opt",
        action="append",
        default=[],
        help="generator option NAME=VALUE (e.g. averages=1, "
        "soft_iron=symmetric); given, it applies to every procedure listed",
    )
    a = ap.parse_args(argv)
    if a.report_only:
        rs = [json.loads(line) for f in a.report_only.split(",") for line in open(f) if line.strip()]
        report(rs)
        return
    opts = {}
    for kv in a.gen_opt:
        k, v = kv.split("=", 1)
        try:
            opts[k] = float(v)
        except ValueError:
            opts[k] = v
    results = []
    tmp_ctx = tempfile.TemporaryDirectory() if not a.keep else None
    tmp = a.keep or tmp_ctx.name
    if a.keep:
        os.makedirs(tmp, exist_ok=True)
        os.environ["BLIND_KEEP"] = "1"
    out = open(a.jsonl, "a") if a.jsonl else None
    for proc in a.procedures.split(","):
        pi = PROCS.index(proc)
        effs = [None] + bg.EFFECTS[proc]
        for ei, eff in enumerate(effs):
            if a.effects and (eff or "none") not in a.effects.split(","):
                continue
            n = a.nulls if eff is None else a.effects_n
            for i in range(n):
                seed = a.seed0 + 10000 * pi + 100 * ei + i
                r = run_one(proc, eff, seed, tmp, a.timeout, opts)
                results.append(r)
                if out:
                    out.write(json.dumps(r, default=float) + "\n")
                    out.flush()
                print(
                    f"{proc} {eff or 'none'} {seed}: rc {r['rc']} {r.get('verdict', r.get('message'))} "
                    f"({r['seconds']} s)",
                    file=sys.stderr,
                    flush=True,
                )
    report(results)


if __name__ == "__main__":
    main()
