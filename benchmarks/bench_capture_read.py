"""Capture reader speed and memory on a large time series, against baselines from the same run.

    .venv/bin/python benchmarks/bench_capture_read.py [--rows 1000000] [--repeat 3] [--update-docs]

Writes a capture of ``--rows`` rows (t, position, ax, ay, az, gx, gy, gz, temp_c; values with
the few decimals real loggers write) with ``write_capture``, then, each in a fresh interpreter:

- ``read_capture`` wall time (best and median of ``--repeat``) and ``ru_maxrss`` growth;
- ``read_capture`` peak traced memory (tracemalloc, a separate run: tracing slows Python);
- baselines on the same file: ``numpy.loadtxt`` (numeric columns only, no checks) and the
  ``csv`` module into float arrays (with the ``position`` column kept as str), and
  ``pandas.read_csv`` when pandas happens to be installed (it is not a dependency).

Targets: read in under 3 s; peak traced memory within 3x the numeric arrays' size.
``--update-docs`` writes the figures into docs/benchmarks.md under "## Capture reader".
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


TARGET_S = 3.0
TARGET_RATIO = 3.0
NUMERIC = ["t", "ax", "ay", "az", "gx", "gy", "gz", "temp_c"]

# Each snippet runs in a fresh interpreter and prints one JSON line.
_PRELUDE = """
import json, resource, sys, time
sys.path.insert(0, {root!r})
import numpy as np
path = {path!r}
def maxrss_bytes():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
def hwm_bytes():  # peak RSS of this process image (Linux); None elsewhere
    try:
        with open("/proc/self/status") as f:
            return next(int(l.split()[1]) * 1024 for l in f if l.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return None
"""
_READ = (
    _PRELUDE
    + """
from station.capture import read_capture
rss0, hwm0 = maxrss_bytes(), hwm_bytes()
t0, c0 = time.perf_counter(), time.process_time()
c = read_capture(path)
dt, cpu = time.perf_counter() - t0, time.process_time() - c0
numeric = sum(a.nbytes for a in c.columns.values() if a.dtype != object)
hwm = None if hwm0 is None else hwm_bytes() - hwm0
print(json.dumps({{"s": dt, "cpu": cpu, "rss_delta": maxrss_bytes() - rss0, "hwm_delta": hwm, "rows": c.n_rows, "numeric_bytes": numeric,
                  "position_bytes": c.columns["position"].nbytes}}))
"""
)
_TRACE = (
    _PRELUDE
    + """
import tracemalloc
from station.capture import read_capture
tracemalloc.start()
c = read_capture(path)
current, peak = tracemalloc.get_traced_memory()
print(json.dumps({{"peak": peak, "current": current}}))
"""
)
_LOADTXT = (
    _PRELUDE
    + """
rss0 = maxrss_bytes()
t0, c0 = time.perf_counter(), time.process_time()
a = np.loadtxt(path, delimiter=",", comments=None, skiprows={skip}, usecols={usecols}, dtype=float)
dt, cpu = time.perf_counter() - t0, time.process_time() - c0
print(json.dumps({{"s": dt, "cpu": cpu, "rss_delta": maxrss_bytes() - rss0, "rows": len(a)}}))
"""
)
_CSV = (
    _PRELUDE
    + """
import csv
rss0 = maxrss_bytes()
t0, c0 = time.perf_counter(), time.process_time()
with open(path, newline="") as f:
    reader = csv.reader(line for line in f if not line.startswith("#"))
    names = next(reader)
    cols = [[] for _ in names]
    for row in reader:
        for j, v in enumerate(row):
            cols[j].append(v)
out = {{n: (np.array(c, dtype=object) if n == "position" else np.array([float(v) if v else np.nan for v in c]))
        for n, c in zip(names, cols)}}
dt, cpu = time.perf_counter() - t0, time.process_time() - c0
print(json.dumps({{"s": dt, "cpu": cpu, "rss_delta": maxrss_bytes() - rss0, "rows": len(out["t"])}}))
"""
)
_PANDAS = (
    _PRELUDE
    + """
import pandas as pd
rss0 = maxrss_bytes()
t0, c0 = time.perf_counter(), time.process_time()
df = pd.read_csv(path, comment="#", dtype={{"position": str}})
dt, cpu = time.perf_counter() - t0, time.process_time() - c0
print(json.dumps({{"s": dt, "cpu": cpu, "rss_delta": maxrss_bytes() - rss0, "rows": len(df)}}))
"""
)


def _run(code: str, path: str, **fmt) -> dict:
    src = code.format(root=str(ROOT), path=path, **fmt)
    out = subprocess.run([sys.executable, "-c", src], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


_MAKE = (
    _PRELUDE
    + """
from benchmarks.bench_capture_read import make_capture
from station.capture import write_capture
cap = make_capture({rows}, sparse={sparse})
t0 = time.perf_counter()
write_capture(path, cap)
print(json.dumps({{"write_s": time.perf_counter() - t0}}))
"""
)


def make_capture(rows: int, seed: int = 0, sparse: bool = False):
    """A synthetic 9-column time-series capture (station.capture.Capture); ``sparse``: temp_c
    only in one row in ten (empty fields elsewhere), like a slow temperature sensor."""
    from station.capture import Capture

    rng = np.random.default_rng(seed)
    t = np.round(np.arange(rows) / 100.0, 2)
    hold = 4000  # 40 s per position, 24 positions round and round
    position = np.array([str(p) for p in ((np.arange(rows) // hold) % 24 + 1).tolist()], dtype=object)
    acc = np.round(1.65 + 0.8 * rng.standard_normal((rows, 3)) * 0.01 + rng.choice([-0.8, 0, 0.8], size=(1, 3)), 5)
    gyr = np.round(rng.standard_normal((rows, 3)) * 0.002, 6)
    temp = np.round(24.0 + np.cumsum(rng.standard_normal(rows)) * 1e-3, 3)
    if sparse:
        temp[np.arange(rows) % 10 != 0] = np.nan
    cols = {
        "t": t,
        "position": position,
        "ax": acc[:, 0],
        "ay": acc[:, 1],
        "az": acc[:, 2],
        "gx": gyr[:, 0],
        "gy": gyr[:, 1],
        "gz": gyr[:, 2],
        "temp_c": temp,
    }
    meta = {
        "station-capture": "1",
        "procedure": "accel-tabletop",
        "device": "BENCH-0001",
        "accel_unit": "V",
        "gyro_unit": "rad/s",
        "sample_rate_hz": "100",
    }
    return Capture(meta=meta, columns=cols)


def _head_lines(path: str) -> int:
    """Metadata lines plus the header row."""
    with open(path) as f:
        n = 0
        for line in f:
            n += 1
            if not line.startswith("#"):
                return n
    return n


def _mib(x: float) -> str:
    return f"{x / 2**20:.1f} MiB"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--update-docs", action="store_true", help="write the figures into docs/benchmarks.md")
    args = ap.parse_args(argv)

    with tempfile.TemporaryDirectory(prefix="bench_capture_") as tmp:
        path = os.path.join(tmp, "big.capture.csv")
        # Made in a child process: ru_maxrss carries over from parent to child, so this
        # process stays small for the children's figures to mean something.
        write_s = _run(_MAKE, path, rows=args.rows, sparse=False)["write_s"]
        size = os.path.getsize(path)
        print(f"file: {args.rows:,} rows x 9 columns, {_mib(size)}; written by write_capture in {write_s:.2f} s")

        reads = [_run(_READ, path) for _ in range(args.repeat)]
        trace = _run(_TRACE, path)
        usecols = [0] + list(range(2, 9))
        loadtxt = _run(_LOADTXT, path, usecols=usecols, skip=_head_lines(path))
        csvmod = _run(_CSV, path)
        sparse_path = os.path.join(tmp, "sparse.capture.csv")
        _run(_MAKE, sparse_path, rows=args.rows, sparse=True)
        sparse = _run(_READ, sparse_path)
        try:
            import pandas  # noqa: F401

            pandas_r = _run(_PANDAS, path)
        except (ImportError, subprocess.CalledProcessError):
            pandas_r = None

    assert all(r["rows"] == args.rows for r in reads + [loadtxt, csvmod])
    times = [r["s"] for r in reads]
    best, median = min(times), statistics.median(times)
    cpu = min(r["cpu"] for r in reads)
    numeric = reads[0]["numeric_bytes"]
    ratio = trace["peak"] / numeric
    rss = statistics.median(r["rss_delta"] for r in reads)
    hwm = None if reads[0]["hwm_delta"] is None else statistics.median(r["hwm_delta"] for r in reads)

    def vs(other: dict) -> str:
        return (
            f"wall {other['s']:.2f} s, CPU {other['cpu']:.2f} s, maxrss +{_mib(other['rss_delta'])}; "
            f"read_capture / this: wall {best / other['s']:.2f}, CPU {cpu / other['cpu']:.2f}"
        )

    lines = [
        f"read_capture:       wall best {best:.2f} s, median {median:.2f} s of {args.repeat}; CPU best {cpu:.2f} s "
        f"({args.rows / best / 1e6:.2f} M rows/s wall)",
        f"  target < {TARGET_S:.0f} s:     wall {'PASS' if best < TARGET_S else 'FAIL'}, CPU {'PASS' if cpu < TARGET_S else 'FAIL'}"
        " (CPU time is what a quiet machine would show as wall time)",
        f"  numeric arrays:   {_mib(numeric)} (8 float64 columns), position object array {_mib(reads[0]['position_bytes'])}",
        f"  peak traced:      {_mib(trace['peak'])} = {ratio:.2f}x the numeric arrays; target <= {TARGET_RATIO:.0f}x: "
        f"{'PASS' if ratio <= TARGET_RATIO else 'FAIL'} (held after the read: {_mib(trace['current'])})",
        f"  ru_maxrss growth: {_mib(rss)} = {rss / numeric:.2f}x the numeric arrays (median; VmHWM growth "
        f"{_mib(hwm) if hwm is not None else '?'}; RSS also counts memory freed but kept by the allocator)",
        f"  with missing values (temp_c empty in 9 rows of 10): wall {sparse['s']:.2f} s, CPU {sparse['cpu']:.2f} s",
        f"baseline numpy.loadtxt (numeric columns, no checks): {vs(loadtxt)}",
        f"baseline csv module -> arrays:                       {vs(csvmod)}",
    ]
    if pandas_r:
        lines.append(f"reference pandas.read_csv (not a dependency):        {vs(pandas_r)}")
    print("\n".join(lines))
    try:
        load = " / ".join(f"{x:.1f}" for x in os.getloadavg())
    except OSError:
        load = "?"
    machine = f"{platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, numpy {np.__version__}, load average {load}"
    print(f"machine: {machine}")
    if args.update_docs:
        _update_docs(lines, machine, args, write_s, size)
    return 0 if min(best, cpu) < TARGET_S and ratio <= TARGET_RATIO else 1


def _update_docs(lines: list[str], machine: str, args, write_s: float, size: int) -> None:
    doc = ROOT / "docs" / "benchmarks.md"
    text = doc.read_text() if doc.exists() else "# Benchmarks\n\nFigures printed by the scripts in `benchmarks/`.\n"
    section = (
        "## Capture reader\n\n"
        f"`.venv/bin/python benchmarks/bench_capture_read.py --rows {args.rows} --repeat {args.repeat}` "
        f"({time.strftime('%Y-%m-%d')}; {machine}).\n"
        f"A generated time series, {args.rows:,} rows x 9 columns (t, position, ax, ay, az, gx, gy, gz, temp_c), "
        f"{_mib(size)}, written by `write_capture` in {write_s:.2f} s. Each figure comes from a fresh interpreter. "
        "Wall times depend on what else the machine runs: with a load average above the CPU count, the CPU "
        "time is the figure to hold against the 3 s target (a quiet machine shows it as wall time).\n\n"
        "```\n" + "\n".join(lines) + "\n```\n"
    )
    start = text.find("## Capture reader")
    if start < 0:
        text = text.rstrip("\n") + "\n\n" + section
    else:
        end = text.find("\n## ", start + 1)
        text = text[:start] + section + ("" if end < 0 else "\n" + text[end + 1 :])
    tmp = doc.with_suffix(".md.tmp")
    tmp.write_text(text)
    os.replace(tmp, doc)
    print(f"wrote {doc.relative_to(ROOT)}")


if __name__ == "__main__":
    sys.exit(main())
