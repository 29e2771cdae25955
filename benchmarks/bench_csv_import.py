"""Plain CSV import (``station import FILE --map ... --unit ...``): peak memory and time on a
large generated file, for the reader of this tree and, to compare, of another checkout.

    .venv/bin/python benchmarks/bench_csv_import.py [--rows 1000000] [--other PATH]

Writes a bench logger's CSV of ``--rows`` rows (``time_ms,acc_x,acc_y,acc_z,gyr_x,gyr_y,
gyr_z,temp``; a few decimals, as loggers write them), then, each in a fresh interpreter,
reads it with ``station.importers.csvfiles.read_plain`` (the column map and units of the
README's bench example):

- wall and CPU time, ``ru_maxrss`` and VmHWM growth (peak RSS, Linux);
- peak traced memory (tracemalloc, a separate run: tracing slows Python);
- a digest of every array it returns, so two readers can be seen to give the same result.

``--other PATH``: a second source tree (e.g. an older commit unpacked with ``git archive``)
measured the same way on the same file. Printed figures only; nothing is asserted.
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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

_PRELUDE = """
import hashlib, json, resource, sys, time
sys.path.insert(0, {root!r})
import numpy as np
path = {path!r}
def maxrss():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
def hwm():
    try:
        with open("/proc/self/status") as f:
            return next(int(l.split()[1]) * 1024 for l in f if l.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return None
from station.importers.csvfiles import read_plain
MAP = {{"t": "time_ms", "ax": "acc_x", "ay": "acc_y", "az": "acc_z", "gx": "gyr_x", "gy": "gyr_y", "gz": "gyr_z",
        "temp_c": "temp"}}
UNITS = {{"accel": "g", "gyro": "deg/s", "t": "ms"}}
"""
_READ = (
    _PRELUDE
    + """
rss0, hwm0 = maxrss(), hwm()
t0, c0 = time.perf_counter(), time.process_time()
imp = read_plain(path, mapping=MAP, units=UNITS)
dt, cpu = time.perf_counter() - t0, time.process_time() - c0
h = hashlib.sha256()
n_bytes = 0
for kind in sorted(imp.streams):
    s = imp.streams[kind]
    for a in (s.t_s, s.xyz, s.temp_c):
        if a is not None:
            a = np.ascontiguousarray(a, dtype=np.float64)
            h.update(a.tobytes())
            n_bytes += a.nbytes
print(json.dumps({{"s": dt, "cpu": cpu, "rss": maxrss() - rss0, "hwm": None if hwm0 is None else hwm() - hwm0,
                  "rows": len(imp.streams["accel"].t_s), "digest": h.hexdigest()[:16], "result_bytes": n_bytes}}))
"""
)
_TRACE = (
    _PRELUDE
    + """
import tracemalloc
tracemalloc.start()
imp = read_plain(path, mapping=MAP, units=UNITS)
current, peak = tracemalloc.get_traced_memory()
print(json.dumps({{"peak": peak, "current": current}}))
"""
)


def make_csv(path: str, rows: int, seed: int = 0) -> int:
    """A bench logger's CSV: ms time, accel in g, gyro in °/s, temperature; its size in bytes."""
    rng = np.random.default_rng(seed)
    t_ms = np.arange(rows) * 10
    acc = np.round(rng.standard_normal((rows, 3)) * 0.002 + np.array([0.0, 0.0, 1.0]), 5)
    gyr = np.round(rng.standard_normal((rows, 3)) * 0.1, 4)
    temp = np.round(24.0 + np.cumsum(rng.standard_normal(rows)) * 1e-3, 3)
    with open(path, "w") as f:
        f.write("time_ms,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z,temp\n")
        step = 100_000
        for a in range(0, rows, step):
            b = min(rows, a + step)
            f.writelines(
                f"{t},{x:.5f},{y:.5f},{z:.5f},{p:.4f},{q:.4f},{r:.4f},{c:.3f}\n"
                for t, x, y, z, p, q, r, c in zip(
                    t_ms[a:b].tolist(), *acc[a:b].T.tolist(), *gyr[a:b].T.tolist(), temp[a:b].tolist()
                )
            )
    return os.path.getsize(path)


def _run(code: str, root: Path, path: str) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", code.format(root=str(root), path=path)], capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def _mib(x) -> str:
    return "n/a" if x is None else f"{x / 2**20:.1f} MiB"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--other", type=Path, help="another source tree, measured the same way")
    args = ap.parse_args(argv)
    trees = [("this tree", ROOT)] + ([("other tree", args.other.resolve())] if args.other else [])
    with tempfile.TemporaryDirectory(prefix="bench_csv_import_") as tmp:
        path = os.path.join(tmp, "bench.csv")
        t0 = time.perf_counter()
        size = make_csv(path, args.rows)
        print(f"plain CSV: {args.rows:,} rows x 8 columns, {_mib(size)}, written in {time.perf_counter() - t0:.1f} s")
        for name, root in trees:
            r = _run(_READ, root, path)
            tr = _run(_TRACE, root, path)
            ratio = tr["peak"] / r["result_bytes"]
            print(
                f"{name} ({root}):\n"
                f"  read_plain:   wall {r['s']:.2f} s, CPU {r['cpu']:.2f} s, {r['rows']:,} rows, digest {r['digest']}\n"
                f"  result:       {_mib(r['result_bytes'])} of float64 arrays\n"
                f"  peak traced:  {_mib(tr['peak'])} = {ratio:.2f}x the result (held after: {_mib(tr['current'])})\n"
                f"  peak RSS:     ru_maxrss +{_mib(r['rss'])}, VmHWM +{_mib(r['hwm'])}"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
