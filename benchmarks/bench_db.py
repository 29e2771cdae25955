"""Database speed: history and due on 10,000 devices x 50 calibrations; saving a 5-minute 100 Hz capture.

Targets (issue 5): `station history ID` and `station due` under 200 ms; saving a
30,000-row x 10-column capture under 500 ms.

The big database is built here with bulk inserts (valid rows: same JSON, hash chain and
schedule as `Store.save_calibration` writes; captures omitted) and cached in /tmp keyed
by the schema version, so later runs start at once. Figures are medians over repeats;
baselines measured in the same run: a bare `python -c pass`, and `station --version`
(the CLI's own start-up: it imports every command module).

    python3 dev.py bench bench_db          # or: .venv/bin/python benchmarks/bench_db.py [--rebuild]
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from db import Store  # noqa: E402
from db import params as P  # noqa: E402
from db.integrity import record_hash  # noqa: E402
from db.schema import RECORD_VERSION, SCHEMA_VERSION  # noqa: E402

N_DEVICES = 10_000
N_CALS = 50
NOW = datetime(2026, 11, 1, tzinfo=UTC)
CACHE = Path(tempfile.gettempdir()) / f"station-bench-{SCHEMA_VERSION}-{N_DEVICES}x{N_CALS}.db"
PY = sys.executable


def device_id(k: int) -> str:
    return f"IMU-{k:05d}"


def build(path: Path) -> None:
    """10,000 devices x 50 accel-tabletop calibrations, bulk-inserted, then the schedule."""
    rng = np.random.default_rng(42)
    tmp = path.with_suffix(".building")
    for p in (tmp, Path(str(tmp) + "-wal"), Path(str(tmp) + "-shm")):
        p.unlink(missing_ok=True)
    store = Store(str(tmp))
    conn = store.conn
    conn.execute("PRAGMA synchronous = OFF")
    created = P.iso(NOW)
    t0 = time.perf_counter()
    conn.execute("BEGIN")
    devices = []
    for k in range(N_DEVICES):
        tol = json.dumps({"B": 0.05}) if k % 10 == 0 else "{}"  # one device in ten has tolerances
        devices.append((device_id(k), "ADXL355", '["accel"]', None, 365.0, tol, created))
    conn.executemany(
        "INSERT INTO devices (id, model, sensor_kinds, notes, interval_days, tolerances, created) VALUES (?,?,?,?,?,?,?)",
        devices,
    )
    cal_id = 0
    batch = []
    for k in range(N_DEVICES):
        dev = device_id(k)
        last = NOW - timedelta(days=float(rng.uniform(0, 400)))  # ~9 % past a 365-day interval
        gaps = rng.uniform(50, 90, N_CALS - 1)
        days_back = np.concatenate([[0.0], np.cumsum(gaps)])[::-1]
        rates = rng.normal(0, 0.01, 3)  # bias drift per year
        prev_hash = None
        prev_id = None
        for j in range(N_CALS):
            cal_id += 1
            when = last - timedelta(days=float(days_back[j]))
            years = (when - NOW).days / 365.25
            B = (0.1 + rates * years + rng.normal(0, 0.002, 3)).tolist()
            M = (np.eye(3) + rng.normal(0, 1e-4, (3, 3))).tolist()
            row = {
                "id": cal_id,
                "device_id": dev,
                "procedure": "accel-tabletop",
                "time": P.iso(when),
                "model": "A = B + M V",
                "params": P.dumps({"B": B, "M": M}),
                "uncertainty": P.dumps({"B": [0.002] * 3, "M": [[1e-4] * 3] * 3}),
                "residual_rms": 0.004,
                "n_positions": 12,
                "warnings": "[]",
                "result_extra": "{}",
                "software_version": "0.1.0",
                "capture_id": None,
                "capture_sha256": None,
                "operator": "bench",
                "host": "bench",
                "accepted": 1,
                "supersedes": prev_id,
                "saved_at": P.iso(when)[:-1] + ".000000Z",
                "record_version": RECORD_VERSION,
                "prev_hash": prev_hash,
            }
            row["hash"] = record_hash(row)
            prev_hash, prev_id = row["hash"], cal_id
            batch.append(tuple(row.values()))
        if len(batch) >= 50_000:
            _insert(conn, batch)
            batch = []
    _insert(conn, batch)
    conn.execute("COMMIT")
    t_insert = time.perf_counter() - t0
    t0 = time.perf_counter()
    store.rebuild_schedule()
    t_sched = time.perf_counter() - t0
    conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    conn.execute("ANALYZE")
    store.close()
    os.replace(tmp, path)
    print(f"built {path} ({path.stat().st_size / 1e6:.0f} MB): inserts {t_insert:.1f} s, schedule {t_sched:.1f} s")


def _insert(conn, batch) -> None:
    cols = (
        "id, device_id, procedure, time, model, params, uncertainty, residual_rms, n_positions, warnings, "
        "result_extra, software_version, capture_id, capture_sha256, operator, host, accepted, supersedes, "
        "saved_at, record_version, prev_hash, hash"
    )
    conn.executemany(f"INSERT INTO calibrations ({cols}) VALUES ({','.join('?' * 22)})", batch)


def timed(fn, repeat: int) -> tuple[float, float, float, object]:
    """(median wall ms, max wall ms, median CPU ms of this process, last result)."""
    walls, cpus, out = [], [], None
    for _ in range(repeat):
        c0, t0 = time.process_time(), time.perf_counter()
        out = fn()
        walls.append((time.perf_counter() - t0) * 1e3)
        cpus.append((time.process_time() - c0) * 1e3)
    return statistics.median(walls), max(walls), statistics.median(cpus), out


def proc(args: list[str], repeat: int = 7) -> tuple[float, float, int]:
    """(median wall ms, median CPU ms user+sys, exit status) of a fresh process."""
    walls, cpus, code = [], [], None
    for _ in range(repeat):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        r = subprocess.run(args, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        walls.append((time.perf_counter() - t0) * 1e3)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append((r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime) * 1e3)
        code = r.returncode
    return statistics.median(walls), statistics.median(cpus), code


def capture_5min() -> tuple[dict, dict]:
    """5 minutes at 100 Hz, 10 columns: t, accel/gyro/mag (quantized like a 16-bit part), temp_c."""
    rng = np.random.default_rng(7)
    n = 30_000
    t = np.arange(n) / 100.0
    cols = {"t": t}
    for name, scale, lsb in (
        ("ax", 9.81, 1 / 16384),
        ("ay", 0, 1 / 16384),
        ("az", 0, 1 / 16384),
        ("gx", 0, 1 / 131),
        ("gy", 0, 1 / 131),
        ("gz", 0, 1 / 131),
        ("mx", 200, 0.15),
        ("my", -50, 0.15),
        ("mz", 400, 0.15),
    ):
        cols[name] = np.round((scale + rng.normal(0, 40 * lsb, n)) / lsb) * lsb
    cols["temp_c"] = np.round(25 + np.cumsum(rng.normal(0, 0.001, n)), 2)
    meta = {
        "station-capture": "1",
        "procedure": "accel-tabletop",
        "device": "BENCH-SAVE",
        "accel_unit": "m/s^2",
        "sample_rate_hz": "100",
        "date": "2026-11-01T10:00:00Z",
    }
    return meta, cols


def result_for(device: str) -> dict:
    return {
        "procedure": "accel-tabletop",
        "device": device,
        "model": "A = B + M V",
        "params": {"B": [0.1, 0.2, 0.3], "M": np.eye(3).tolist()},
        "uncertainty": {"B": [1e-3] * 3, "M": [[1e-4] * 3] * 3},
        "residual_rms": 0.004,
        "n_positions": 12,
        "warnings": [],
    }


def main() -> int:
    if "--rebuild" in sys.argv or not CACHE.exists():
        build(CACHE)
    else:
        print(f"using cached {CACHE} ({CACHE.stat().st_size / 1e6:.0f} MB)")
    rng = np.random.default_rng(1)
    ids = [device_id(int(k)) for k in rng.integers(0, N_DEVICES, 20)]

    print(
        f"\n{N_DEVICES} devices x {N_CALS} calibrations (schema {SCHEMA_VERSION}); "
        f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs; ms = median wall (CPU)"
    )
    it = iter(ids * 10)
    open_ms, _, open_cpu, _ = timed(lambda: Store(str(CACHE)).close(), 10)
    with Store(str(CACHE)) as s:
        counts = s.counts()
        hist_ms, hist_max, hist_cpu, h = timed(lambda: s.history(next(it)), 20)
        due_ms, due_max, due_cpu, d = timed(lambda: s.due(now=NOW), 10)
        drift_ms, _, drift_cpu, _ = timed(lambda: s.drift(next(it)), 10)
    assert counts["calibrations"] == N_DEVICES * N_CALS and len(h) == N_CALS
    print(
        f"library: open {open_ms:.1f} ({open_cpu:.1f}); history(ID) {hist_ms:.1f} ({hist_cpu:.1f}), {len(h)} records; "
        f"due() {due_ms:.1f} ({due_cpu:.1f}), {len(d)} devices due; drift(ID) {drift_ms:.1f} ({drift_cpu:.1f})"
    )

    base_py = proc([PY, "-c", "pass"])
    base_cli = proc([PY, "-m", "station", "--version"])
    hist_cli = proc([PY, "-m", "station", "history", ids[0], "--db", str(CACHE)])
    histj_cli = proc([PY, "-m", "station", "history", ids[1], "--json", "--db", str(CACHE)])
    due_cli = proc([PY, "-m", "station", "due", "--now", P.iso(NOW), "--db", str(CACHE)])
    direct = (
        "import sys, argparse; from station.commands import {m}; sys.exit({m}.run(argparse.Namespace(db={db!r}, {a})))"
    )
    hist_direct = proc(
        [PY, "-c", direct.format(m="history", db=str(CACHE), a=f"id={ids[2]!r}, procedure=None, json=False")]
    )
    due_direct = proc(
        [PY, "-c", direct.format(m="due", db=str(CACHE), a=f"within=0.0, now={P.iso(NOW)!r}, json=False")]
    )
    assert hist_cli[2] == 0 and due_cli[2] == 1 and hist_direct[2] == 0 and due_direct[2] == 1

    def fmt(r):
        return f"{r[0]:.0f} ({r[1]:.0f})"

    print("processes, median of 7:")
    print(f"  baseline python -c pass            {fmt(base_py)}")
    print(f"  baseline station --version         {fmt(base_cli)}   CLI start-up: imports every command module")
    print(
        f"  station history ID                 {fmt(hist_cli)}   --json {fmt(histj_cli)}; "
        f"start-up + {hist_cli[0] - base_cli[0]:.0f} ({hist_cli[1] - base_cli[1]:.0f})"
    )
    print(
        f"  station due                        {fmt(due_cli)}   start-up + {due_cli[0] - base_cli[0]:.0f} "
        f"({due_cli[1] - base_cli[1]:.0f})"
    )
    print(f"  history handler, no other commands {fmt(hist_direct)}")
    print(f"  due handler, no other commands     {fmt(due_direct)}")

    meta, cols = capture_5min()
    raw = sum(a.nbytes for a in cols.values())
    import zlib

    from db.codec import ZLIB_LEVEL

    with tempfile.TemporaryDirectory() as tmp:
        fresh = Store(os.path.join(tmp, "fresh.db"))
        k = iter(range(100))
        save = timed(lambda: fresh.save_calibration(result_for(f"S{next(k)}"), meta=meta, columns=cols), 5)
        info = fresh.capture_info(1)
        load = timed(lambda: fresh.load_capture(1), 5)
        assert all(np.array_equal(load[3][1][c], cols[c]) for c in cols)
        fresh.close()
        zl = timed(lambda: [zlib.compress(a.tobytes(), ZLIB_LEVEL) for a in cols.values()], 5)
        big = os.path.join(tmp, "big.db")
        shutil.copyfile(CACHE, big)
        with Store(big) as s:
            into_big = timed(lambda: s.save_calibration(result_for(device_id(5)), meta=meta, columns=cols), 3)
    print(
        f"\nsave a 5-min 100 Hz capture (30,000 x 10, {raw / 1e6:.1f} MB raw -> {info['stored_bytes'] / 1e6:.2f} MB, "
        f"{raw / info['stored_bytes']:.1f}x, zlib level {ZLIB_LEVEL}):"
    )
    print(f"  save_calibration, fresh DB         {save[0]:.0f} ({save[2]:.0f}), max {save[1]:.0f}")
    print(f"  save_calibration, the big DB       {into_big[0]:.0f} ({into_big[2]:.0f})")
    print(f"  baseline zlib of the columns alone {zl[0]:.0f} ({zl[2]:.0f}); save/zlib CPU = {save[2] / zl[2]:.1f}")
    print(f"  load_capture                       {load[0]:.0f} ({load[2]:.0f})")

    verdict = {
        "history library < 200 ms": hist_ms < 200,
        "due library < 200 ms": due_ms < 200,
        "history CLI < 200 ms": hist_cli[0] < 200,
        "due CLI < 200 ms": due_cli[0] < 200,
        "save < 500 ms": save[0] < 500 and into_big[0] < 500,
    }
    print("\nwall-clock targets: " + "; ".join(f"{k}: {'yes' if v else 'NO'}" for k, v in verdict.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
