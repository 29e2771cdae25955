"""`station record --recover` on a long partial file, against baselines measured in the same run.

    nice -n 10 .venv/bin/python benchmarks/bench_record_recover.py [--rows 800000] [--repeat 3]

Run it from another tree (``PYTHONPATH=TREE python TREE/benchmarks/...``, or this file with
``--tree TREE``) to compare a version before a change: the copy-only baseline of each run
makes the figures of two runs on a busy computer comparable.

Writes the partial file a killed `station record` leaves (its head as capture-format.md
writes it; rows as record writes them: `t` to the microsecond, then 10 device values of 7
significant digits, gyro-sized ones so that some are written `1.2e-05`; a row cut by the kill
last), then times, interleaved round by round so that a busy computer weighs on each alike:

- ``copy only``: the file's bytes copied (public `shutil.copyfile`: the cost of what
  `--recover` did before it read the rows it keeps, a copy under a new head; the QA's 0.7 s
  at 800k rows);
- ``recover``: `recover_partial`, which reads every row it keeps with the capture reader
  (`check_capture_upto`: the chunked reader's fast path, numpy's loadtxt on each block)
  before it copies them (the QA's 6.4 s);
- ``read_capture``: the station's reader on the recovered capture.

The figures are wall-clock seconds, best and median of ``--repeat``, and their ratios.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if "--tree" in sys.argv:  # the station of another tree (the version before a change)
    ROOT = Path(sys.argv[sys.argv.index("--tree") + 1]).resolve()
sys.path.insert(0, str(ROOT))

from station import capture  # noqa: E402
from station.device import record as rec  # noqa: E402

COLUMNS = ["t", "segment", "ax", "ay", "az", "gx", "gy", "gz", "mx", "my", "mz", "temp_c"]


def write_partial(path: str, rows: int, seed: int = 1) -> None:
    meta = {
        "station-capture": "1",
        "recorded_at": "2026-11-29T00:00:00Z",
        "source": "/dev/pts/1",
        "protocol": "station",
        "baud": "115200",
        "device": "SIM-ACC-0007",
        "accel_unit": "V",
        "gyro_unit": "rad/s",
        "mag_unit": "uT",
        "nominal_rate_hz": "500",
        "complete": "false",
    }
    rng = np.random.default_rng(seed)
    scale = np.array([1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3, 30.0, 30.0, 30.0, 0.1])
    seven = np.vectorize(lambda x: float(f"{x:.7g}"))
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write("".join(f"# {k}: {v}\n" for k, v in meta.items()) + ",".join(COLUMNS) + "\n")  # capture-format
        step = 50_000
        for start in range(0, rows, step):
            k = min(step, rows - start)
            v = seven(rng.normal(size=(k, 10)) * scale)
            v[:, 9] += 25.0
            t = (np.arange(start, start + k) * 0.002).tolist()
            f.write(
                "".join(
                    "%.6f,0,%s\n" % (t[i], ",".join(f"{x:.7g}" for x in row))  # noqa: UP031 - as record writes
                    for i, row in enumerate(v.tolist())
                )
            )
        f.write("%.6f,0,2.41" % (rows * 0.002))  # noqa: UP031 - the row the kill cut


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rows", type=int, default=800_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--tree", default=str(ROOT), help="the tree whose station is measured (default: this one)")
    args = ap.parse_args()
    tmp = tempfile.mkdtemp(prefix="bench_recover_")
    try:
        source = os.path.join(tmp, "source.partial")
        t0 = time.perf_counter()
        write_partial(source, args.rows)
        size_mb = os.path.getsize(source) / 1e6
        print(f"partial: {args.rows} rows, {size_mb:.1f} MB (written in {time.perf_counter() - t0:.1f} s)")
        out = os.path.join(tmp, "r.csv")
        partial = out + ".partial"

        def copy_only() -> None:  # the bytes alone (the copy under a new head costs the same)
            shutil.copyfile(source, out)

        def recover():
            shutil.copyfile(source, partial)
            if os.path.exists(out):
                os.unlink(out)
            t, c = time.perf_counter(), time.process_time()
            res = rec.recover_partial(partial)
            return time.perf_counter() - t, time.process_time() - c, res

        def read() -> None:
            c = capture.read_capture(out)
            assert c.n_rows == args.rows

        routes = {
            "copy only": copy_only,
            "recover": recover,
            "read_capture": read,
        }
        times: dict[str, list[float]] = {k: [] for k in routes}
        cpu: dict[str, list[float]] = {k: [] for k in routes}
        for _ in range(args.repeat):
            for name, fn in routes.items():
                if name == "recover":
                    dt, dc, res = fn()
                    assert res.rows == args.rows, res
                else:
                    t, c = time.perf_counter(), time.process_time()
                    fn()
                    dt, dc = time.perf_counter() - t, time.process_time() - c
                times[name].append(dt)
                cpu[name].append(dc)
        best = {k: min(v) for k, v in cpu.items()}
        # CPU seconds as well as wall-clock: on a shared computer the wall clock says the load
        print(f"{'route':14s} {'wall best s':>11s} {'wall median s':>13s} {'CPU best s':>10s}")
        for name, v in times.items():
            print(f"{name:14s} {min(v):11.2f} {statistics.median(v):13.2f} {min(cpu[name]):10.2f}")
        print(
            f"station from {ROOT}: CPU recover / copy only {best['recover'] / best['copy only']:.1f}x, "
            f"recover / read_capture {best['recover'] / best['read_capture']:.2f}"
        )
        print(f"load average at the end: {', '.join(f'{x:.1f}' for x in os.getloadavg())} on {os.cpu_count()} cores")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
