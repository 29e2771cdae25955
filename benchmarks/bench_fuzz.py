"""Fuzz and extreme-value campaign: mutated and valid-but-extreme captures of all five
procedures through `calibrate` and `diagnose`, in-process, with a time limit per case.

    nice -n 10 .venv/bin/python benchmarks/bench_fuzz.py [--mutated 10000] [--extreme 1000]
        [--jobs 2] [--seed 16] [--timeout 60] [--out results.json] [--update-docs]
    nice -n 10 .venv/bin/python benchmarks/bench_fuzz.py --hostile 1000 [--jobs 2] [--seed 27]

``--hostile N``: the world's files and hostile ones (QA s27i): N captures mutated from the real
captures of ../shared/data (cut to their first rows) and the simulated bases, by more ways
(a header repeated, a metadata key twice, time run backwards, NUL runs, a 10 MB line, other
encodings), and the special paths (an empty file, a folder, a FIFO, /dev/zero, a 64 MiB hole),
through inspect, import --out, calibrate, calibrate --save --db (a real SQLite file) and
diagnose; what each writes is checked (``half-written``: an --out or a database left changed by
a refused run, a temporary left beside them).

``--world N``: N of the world's own files (../shared/data/*/original: the imucal session as
pandas wrote it, the MPU-6050 logger's CSV under its preamble, a PX4 ULog) mutated (their
text, or the log's bytes) and imported with their own options, ``--out`` checked; each
capture made is calibrated and diagnosed.

Targets (issue 16): 0 hangs, 0 last-resort errors, 0 stray stdout, 0 crashes, 0 bad exits.
The harness is `tests/fuzzkit.py` (its docstring says what each outcome means); the CI share
is `tests/test_fuzz.py`. Prints one line of progress per 100 captures, then the figures, and
each failure with the case that made it (reproducible: seed and case number).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests import fuzzkit as F  # noqa: E402


def _shard(args: tuple) -> list:
    job, n_mutated, n_extreme, seed, timeout_s, progress_path = args
    folder = tempfile.mkdtemp(prefix=f"fuzz{job}-")
    bases = F.make_bases(folder, seed=seed)
    t0 = time.monotonic()

    def progress(k, outcomes):
        if k % 100 == 0:
            bad = sum(1 for o in outcomes if o.kind in F.FAILURES)
            line = f"job {job}: {k}/{n_mutated + n_extreme} captures, {bad} failures, {time.monotonic() - t0:.0f} s"
            print(line, flush=True)
            if progress_path:
                with open(f"{progress_path}.{job}", "w") as f:
                    json.dump([o.__dict__ for o in outcomes], f)

    return F.run_campaign(
        folder, bases, n_mutated=n_mutated, n_extreme=n_extreme, seed=seed, timeout_s=timeout_s, progress=progress
    )


def _hostile_shard(args: tuple) -> list:
    job, n, seed, timeout_s, progress_path = args
    folder = tempfile.mkdtemp(prefix=f"hostile{job}-")
    bases = F.real_bases(folder)
    bases.update(F.make_bases(folder, seed=seed))
    t0 = time.monotonic()

    def progress(k, outcomes):
        if k % 50 == 0:
            bad = sum(1 for o in outcomes if o.kind in F.FAILURES)
            print(f"job {job}: {k}/{n} captures, {bad} failures, {time.monotonic() - t0:.0f} s", flush=True)
            if progress_path:
                with open(f"{progress_path}.{job}", "w") as f:
                    json.dump([o.__dict__ for o in outcomes], f)

    return F.run_hostile_campaign(
        folder, bases, n_mutated=n, seed=seed, timeout_s=timeout_s, specials=job == 0, progress=progress
    )


def _shard_to_file(job: tuple, path: str) -> None:
    outcomes = _hostile_shard(job) if len(job) == 5 else _shard(job)
    with open(path, "w") as f:
        json.dump([o.__dict__ for o in outcomes], f)


def _split(n: int, k: int) -> list[int]:
    return [n // k + (1 if i < n % k else 0) for i in range(k)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mutated", type=int, default=10000)
    ap.add_argument("--extreme", type=int, default=1000)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=16)
    ap.add_argument("--timeout", type=float, default=60.0)
    ap.add_argument("--out", default=None, help="write every outcome as JSON here")
    ap.add_argument("--update-docs", action="store_true", help="write the figures into docs/benchmarks.md")
    ap.add_argument("--hostile", type=int, default=0, help="run the world's and hostile files' campaign instead")
    ap.add_argument("--world", type=int, default=0, help="run the world's own files through import instead")
    a = ap.parse_args()
    t0 = time.monotonic()
    if a.world:
        return _world(a, t0)
    if a.hostile:
        jobs = [(j, n, a.seed + 1000 * j, a.timeout, a.out) for j, n in enumerate(_split(a.hostile, a.jobs))]
    else:
        jobs = [
            (j, m, e, a.seed + 1000 * j, a.timeout, a.out)
            for j, (m, e) in enumerate(zip(_split(a.mutated, a.jobs), _split(a.extreme, a.jobs)))
        ]
    if a.jobs == 1:
        outcomes = _hostile_shard(jobs[0]) if a.hostile else _shard(jobs[0])
    else:  # one process per job (each forks its own case worker), results through a file
        folder = tempfile.mkdtemp(prefix="fuzz-results-")
        ctx = mp.get_context("fork")
        procs = [ctx.Process(target=_shard_to_file, args=(job, os.path.join(folder, f"{job[0]}.json"))) for job in jobs]
        for p in procs:
            p.start()
        for p in procs:
            p.join()
        outcomes = []
        for job in jobs:
            path = os.path.join(folder, f"{job[0]}.json")
            if not os.path.exists(path):  # the job died: its last progress file, said plainly
                print(f"job {job[0]} ended early; counting its outcomes up to its last progress file")
                path = f"{a.out}.{job[0]}" if a.out else ""
                if not os.path.exists(path):
                    continue
            with open(path) as f:
                outcomes += [F.Outcome(**d) for d in json.load(f)]
    wall = time.monotonic() - t0
    s = F.summary(outcomes)
    if a.hostile:
        lines = _hostile_lines(s, outcomes, a, wall)
    else:
        lines = _lines(s, a, wall)
    status = _report(lines, s, outcomes, a)
    if a.update_docs:
        _update_docs(lines, a)
    return status


def _world(a, t0: float) -> int:
    folder = tempfile.mkdtemp(prefix="world-")
    bases = F.world_import_bases(folder)

    def progress(k, outcomes):
        if k % 50 == 0:
            bad = sum(1 for o in outcomes if o.kind in F.FAILURES)
            print(f"{k}/{a.world} files, {bad} failures, {time.monotonic() - t0:.0f} s", flush=True)

    outcomes = F.run_world_import_campaign(
        folder, bases, n_mutated=a.world, seed=a.seed, timeout_s=a.timeout, progress=progress
    )
    s = F.summary(outcomes)
    lines = _hostile_lines(s, outcomes, a, time.monotonic() - t0)
    lines[0] = f"files: {s['captures']} mutated from {', '.join(sorted(bases))}"
    return _report(lines, s, outcomes, a)


def _report(lines: list[str], s: dict, outcomes: list, a) -> int:
    """Print the summary and each failure, keep the outcomes (--out); 1 when anything failed."""
    print("\n".join(lines))
    for o in s["failures"]:
        print(f"FAILURE {o.kind} {o.command} {o.case}: {o.detail}")
    if a.out:
        with open(a.out, "w") as f:
            json.dump([o.__dict__ for o in outcomes], f)
    return 1 if s["failures"] else 0


def _hostile_lines(s: dict, outcomes: list, a, wall: float) -> list[str]:
    per = {}
    for o in outcomes:
        per.setdefault(o.command, {}).setdefault(o.kind, 0)
        per[o.command][o.kind] += 1
    return [
        f"captures: {s['captures']} ({sum(1 for c in {o.case for o in outcomes} if c.startswith('special'))} special "
        "paths, the rest mutated from the real and simulated bases)",
        "runs: "
        + "; ".join(f"{c} " + ", ".join(f"{k} {v}" for k, v in sorted(d.items())) for c, d in sorted(per.items())),
        "failures: " + ", ".join(f"{k} {s['counts'].get(k, 0)}" for k in F.FAILURES),
        f"time per run: median {s['median_s']:.3f} s, max {s['max_s']:.1f} s (limit {a.timeout:g} s); "
        f"wall {wall / 60:.1f} min with {a.jobs} jobs",
        f"seed {a.seed}, {platform.machine()}, Python {platform.python_version()}",
    ]


def _lines(s: dict, a, wall: float) -> list[str]:
    lines = [
        f"captures: {s['captures']} ({s['mutated']} mutated, {s['extreme']} valid-but-extreme; "
        f"{s['counts'].get('skipped', 0)} extreme edits the writer itself refused, not counted)",
        f"runs (calibrate + diagnose): {s['runs']}: "
        + ", ".join(f"{k} {v}" for k, v in sorted(s["counts"].items()) if k != "skipped"),
        "failures: " + ", ".join(f"{k} {s['counts'].get(k, 0)}" for k in F.FAILURES),
        f"time per run: median {s['median_s']:.3f} s, max {s['max_s']:.1f} s (limit {a.timeout:g} s); "
        f"wall {wall / 60:.1f} min with {a.jobs} jobs",
        f"seed {a.seed}, {platform.machine()}, Python {platform.python_version()}",
    ]
    return lines


def _update_docs(lines: list[str], a) -> None:
    path = ROOT / "docs" / "benchmarks.md"
    text = path.read_text(encoding="utf-8") if path.exists() else "# Benchmarks\n"
    head = "## Fuzz: the world's files and hostile ones" if a.hostile else "## Fuzz and extreme values"
    run = f"--hostile {a.hostile}" if a.hostile else f"--mutated {a.mutated} --extreme {a.extreme}"
    body = (
        f"{head}\n\n`nice -n 10 .venv/bin/python benchmarks/bench_fuzz.py {run} "
        f"--jobs {a.jobs} --seed {a.seed} --timeout {a.timeout:g}`\n\n"
        + "\n".join(f"- {line}" for line in lines)
        + "\n"
    )
    if head in text:
        start = text.index(head)
        nxt = text.find("\n## ", start + len(head))
        text = text[:start] + body + (text[nxt:] if nxt >= 0 else "")
    else:
        text = text.rstrip("\n") + "\n\n" + body
    path.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    raise SystemExit(main())
