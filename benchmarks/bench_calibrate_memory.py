"""Peak memory of `station calibrate` on a long P4 record, as the operator's command runs it.

    .venv/bin/python benchmarks/bench_calibrate_memory.py [--duration-s 21600] [--seed 400001] [--keep FILE]

Simulates a gyro-drift (mode B) capture of ``--duration-s`` seconds at 100 Hz (21600 s:
2,160,000 rows, 163 MB of file), then runs ``station calibrate FILE --json`` in a child process
and reports its peak resident set (``ru_maxrss`` of the child, as ``/usr/bin/time -v`` shows
it), its wall time, and the capture's numeric arrays for scale. ``--keep`` writes the capture
there (and reuses it when it exists) instead of a temporary folder.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STATION = [sys.executable, "-m", "station"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration-s", type=float, default=21600.0)
    ap.add_argument("--seed", type=int, default=400001)
    ap.add_argument("--keep", default=None, help="capture file to write (or reuse)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(args.keep) if args.keep else Path(tmp) / "long.csv"
        if not path.exists():
            subprocess.run(
                [*STATION, "simulate", "--procedure", "gyro-drift", "--out", str(path), "--seed", str(args.seed)]
                + ["--option", f"duration_s={args.duration_s:g}"],
                cwd=ROOT,
                check=True,
                stdout=subprocess.DEVNULL,
            )
        size_mb = os.path.getsize(path) / 1e6
        with open(path, "rb") as f:
            rows = sum(1 for line in f if not line.startswith(b"#")) - 1
        t0 = time.perf_counter()
        with open(Path(tmp) / "out.json", "w") as out, open(Path(tmp) / "err.txt", "w+") as err:
            proc = subprocess.Popen([*STATION, "calibrate", str(path), "--json"], cwd=ROOT, stdout=out, stderr=err)
            _, status, usage = os.wait4(proc.pid, 0)  # this child's own peak, not the simulator's
            proc.returncode = os.waitstatus_to_exitcode(status)
            wall = time.perf_counter() - t0
            if proc.returncode != 0:
                err.seek(0)
                print(err.read(), file=sys.stderr)
                return 1
        maxrss_mb = usage.ru_maxrss / 1024  # KiB on Linux
        arrays_mb = rows * 8 * 8 / 1e6  # t, ax..gz, temp_c as float64
    print(f"capture: {rows} rows, {size_mb:.0f} MB of file, {arrays_mb:.0f} MB of numeric arrays")
    print(
        f"station calibrate --json: peak RSS {maxrss_mb:.0f} MiB ({maxrss_mb * 1.048576 / arrays_mb:.1f}x the arrays), wall {wall:.1f} s"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
