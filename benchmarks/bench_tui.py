"""TUI benchmark: start-up time to the first screen, refresh rate and CPU while streaming.

    python benchmarks/bench_tui.py [--runs 5] [--seconds 20] [--rate 1000]

1. Start-up: wall time from spawning a fresh `python` to the Connect screen's first frame
   displayed (Textual's Ready, when an auto-pilot starts; headless driver). Median and best of --runs. Baseline in the same run: a bare Textual App with
   one Static, spawned and timed the same way (the floor: interpreter + Textual).
   Target: < 1.5 s.
2. Streaming: `station sim-device --rate 1000` (a subprocess: its CPU is not counted)
   streams over a real pty into `station.sources.SerialSource`; the app shows the P1
   Procedure screen (headless, 80x24) for --seconds. Measured in this process: LiveUpdates
   drawn per second (the refresh rate), process CPU time per wall second (reader thread +
   guide worker + UI), samples received, dropped, parse errors. Baseline in the same run:
   the same reader alone (no app) for the same time. Targets: >= 10 Hz refresh, reader +
   UI < 30 % of a core.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import subprocess
import sys
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

STARTUP = textwrap.dedent("""
    import sys, time
    t_spawn = float(sys.argv[1])
    {make}
    async def auto(pilot):  # runs when Textual says Ready: the first frame is displayed
        print(f"{{time.time() - t_spawn:.4f}}", flush=True)
        pilot.app.exit()
    app.run(headless=True, size=(80, 24), auto_pilot=auto)
""")

MAKE_STATION = "from station.app import make_app\napp = make_app(None)"
MAKE_BARE = textwrap.dedent("""
    from textual.app import App
    from textual.widgets import Static
    class Bare(App):
        def compose(self):
            yield Static("hello")
    app = Bare()""")


def startup_s(make: str, runs: int) -> list[float]:
    out = []
    code = STARTUP.format(make=make)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    for _ in range(runs):
        t = time.time()
        p = subprocess.run(
            [sys.executable, "-c", code, repr(t)], capture_output=True, text=True, cwd=ROOT, env=env, timeout=120
        )
        if p.returncode != 0:
            raise SystemExit(f"start-up run failed: {p.stderr[-2000:]}")
        out.append(float(p.stdout.strip().splitlines()[-1]))
    return out


def stop_sim(p: subprocess.Popen) -> None:
    p.terminate()
    try:
        p.wait(5)
    except subprocess.TimeoutExpired:
        p.kill()


def reader_alone(path: str, seconds: float) -> dict:
    from station.sources import SerialSource

    src = SerialSource(path).start()
    time.sleep(1.0)
    src.drain()
    c0, w0, n0 = time.process_time(), time.monotonic(), src.stats().samples
    t_end = w0 + seconds
    while time.monotonic() < t_end:  # a consumer draining at the app's pace
        src.drain()
        time.sleep(0.01)
    c1, w1, st = time.process_time(), time.monotonic(), src.stats()
    src.stop()
    return {
        "cpu": (c1 - c0) / (w1 - w0),
        "rate": (st.samples - n0) / (w1 - w0),
        "dropped": st.dropped,
        "errors": st.parse_errors,
    }


def app_streaming(path: str, seconds: float) -> dict:
    from station.app import make_app
    from station.sources import SerialSource

    src = SerialSource(path)
    app = make_app(None, device=src, start="procedure", average_s=180.0)
    out = {}

    async def run():
        async with app.run_test(size=(80, 24)) as pilot:
            t_end = time.monotonic() + 20
            while type(app.screen).__name__ != "ProcedureScreen" or app.screen.updates < 5:
                if time.monotonic() > t_end:
                    raise SystemExit("the procedure screen never got data")
                await pilot.pause(0.05)
            await pilot.pause(1.0)
            scr = app.screen
            c0, w0, u0, n0 = time.process_time(), time.monotonic(), scr.updates, src.stats().samples
            await asyncio.sleep(seconds)
            c1, w1, u1, st = time.process_time(), time.monotonic(), scr.updates, src.stats()
            out.update(
                cpu=(c1 - c0) / (w1 - w0),
                refresh=(u1 - u0) / (w1 - w0),
                rate=(st.samples - n0) / (w1 - w0),
                dropped=st.dropped,
                errors=st.parse_errors,
                guide_t=scr.last_status.t_s,
            )
        src.stop()

    asyncio.run(run())
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--rate", type=float, default=1000.0)
    args = ap.parse_args()
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}")

    bare = startup_s(MAKE_BARE, args.runs)
    station = startup_s(MAKE_STATION, args.runs)
    print("\n1. start-up to the first screen (fresh process, headless, 80x24)")
    print(f"   bare Textual app : median {statistics.median(bare):.3f} s, best {min(bare):.3f} s")
    print(
        f"   station (Connect): median {statistics.median(station):.3f} s, best {min(station):.3f} s "
        f"(target < 1.5 s; ratio to bare {statistics.median(station) / statistics.median(bare):.2f})"
    )

    print(f"\n2. streaming {args.rate:g} Hz over a pty for {args.seconds:g} s")
    from bench_device import start_sim  # the device benchmark's: same command, same check

    sim, path = start_sim(args.rate, pin=False)
    try:
        base = reader_alone(path, args.seconds)
        ui = app_streaming(path, args.seconds)
    finally:
        stop_sim(sim)
    print(
        f"   reader alone      : {100 * base['cpu']:.1f} % of a core, {base['rate']:.0f} samples/s, "
        f"dropped {base['dropped']}, parse errors {base['errors']}"
    )
    print(
        f"   reader + guide + UI: {100 * ui['cpu']:.1f} % of a core (target < 30 %; ratio to reader alone "
        f"{ui['cpu'] / base['cpu']:.1f}), refresh {ui['refresh']:.1f} Hz (target >= 10), "
        f"{ui['rate']:.0f} samples/s, dropped {ui['dropped']}, parse errors {ui['errors']}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
