"""ArduPilot DataFlash (.bin) import speed: `station.importers.ardupilot.read_bin` on a long log.

    python benchmarks/bench_bin_import.py [--minutes M] [--rate HZ] [--imus K] [--repeat R] [--keep PATH] [--raw]

No real ArduPilot log is in ../shared, so the log is WRITTEN BY PYMAVLINK'S OWN DataFlash encoder
(``DFReader.DFFormat`` + ``make_format_msgbuf``/``make_msgbuf``, tests/test_import_ardupilot.py's
``DataFlashWriter``, ArduPilot's LogStructure formats): K IMU instances at HZ, a compass at 100 Hz,
attitude (ATT) at 50 Hz and GPS at 10 Hz as other traffic, and the INS_/COMPASS_ parameters.
``--raw``: the sensors as ACC and GYR (LogStructure.h ``QBQfff``, every sample) and no IMU records.
Printed: the file, the time pymavlink's own indexer takes (``DFReader_binary`` with
PYMAVLINK_FAST_INDEX=0, as the importer opens it), and the whole ``read_bin`` (median of R runs).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402


def write_log(path, minutes: float, rate_hz: float, imus: int, raw: bool = False) -> int:
    from pymavlink import DFReader

    from tests.test_import_ardupilot import PARAMS, DataFlashWriter
    from tests.test_import_ardupilot_raw import RawWriter

    w = RawWriter(path) if raw else DataFlashWriter(path)
    att = w.enc.add_format(
        DFReader.DFFormat(0, "ATT", 0, "QccccCCCCB", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw,AEKF")
    )
    w.f.write(w.enc.make_format_msgbuf(att))
    for name, value in PARAMS.items():
        w.param(1000, name, value)
    rng = np.random.default_rng(1)
    n = int(minutes * 60 * rate_hz)
    step_us = int(round(1e6 / rate_hz))
    gyro = rng.normal(0, 0.01, (n, 3))
    acc = rng.normal(0, 0.05, (n, 3)) + [0.1, -0.2, -9.8]
    count = 0
    for k in range(n):
        t = 500_000 + k * step_us
        for inst in range(imus):
            if raw:
                w.write("ACC", t + 50, inst, t, *(acc[k] + inst))
                w.write("GYR", t + 50, inst, t, *gyro[k])
                count += 2
            else:
                w.imu(t, inst, gyro[k], acc[k] + inst)
                count += 1
        if k % max(1, int(rate_hz // 100)) == 0:
            w.mag(t + 100, 0, (200 + k % 7, -150, 420))
            count += 1
        if k % max(1, int(rate_hz // 50)) == 0:
            w.f.write(w.enc.make_msgbuf(att, (t + 200, 0, 1, 0, 2, 0, 3, 0, 0, 0)))
            count += 1
        if k % max(1, int(rate_hz // 10)) == 0:
            w.gps(t + 300, 47.397742, 8.545594, 488.0)
            count += 1
    w.close()
    return count


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--rate", type=float, default=400.0)
    ap.add_argument("--imus", type=int, default=3)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--keep", default=None, help="write the log here (reused when it exists)")
    ap.add_argument("--raw", action="store_true", help="ACC/GYR instead of IMU records")
    a = ap.parse_args()
    from pymavlink import DFReader

    from station.importers.ardupilot import read_bin

    tmp = tempfile.TemporaryDirectory()
    path = a.keep or os.path.join(tmp.name, "bench.bin")
    if not os.path.exists(path):
        t0 = time.perf_counter()
        count = write_log(path, a.minutes, a.rate, a.imus, a.raw)
        print(f"wrote {count} messages, {os.path.getsize(path) / 1e6:.1f} MB in {time.perf_counter() - t0:.1f} s")
    print(
        f"{path}: {os.path.getsize(path) / 1e6:.1f} MB ({a.minutes:g} min, {a.imus} IMUs at {a.rate:g} Hz{', ACC/GYR' if a.raw else ''})"
    )
    os.environ["PYMAVLINK_FAST_INDEX"] = "0"
    t0 = time.perf_counter()
    DFReader.DFReader_binary(path, zero_time_base=True)
    print(f"pymavlink index alone: {time.perf_counter() - t0:.2f} s")
    times = []
    for _ in range(a.repeat):
        t0 = time.perf_counter()
        imported = read_bin(path)
        times.append(time.perf_counter() - t0)
    s = imported.streams
    print(
        f"read_bin: median {statistics.median(times):.2f} s over {a.repeat} (min {min(times):.2f}); "
        f"accel {len(s['accel'].t_s)} rows, mag {len(s['mag'].t_s)} rows, {sum(k.startswith('param.') for k in imported.meta)} params"
    )


if __name__ == "__main__":
    main()
