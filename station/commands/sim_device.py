"""`station sim-device`: the simulated device on a real pseudo-terminal.

Prints the pty's path (/dev/pts/N) as the first line of stdout, then streams the
simulator's samples in real time until SIGINT/SIGTERM (exit 0) or `--seconds`.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from station.commands.simulate import seed_arg
from station.errors import InputError, require_positive
from station.procedures import registry


def _effects(items: list[str] | None) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise InputError(None, None, f"--effect {item!r}: expected NAME=VALUE")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise InputError(None, None, f"--effect {name.strip()}: {value.strip()!r} is not a number") from None
    return out


def benches() -> tuple[str, ...]:
    """What `--procedure` takes: every procedure, and the guided runs whose device carries a
    reference IMU (P4 mode A)."""
    return registry.names() + tuple(r.name for r in registry.GUIDED_RUNS if r.reference)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sim-device",
        help="a simulated device on a pseudo-terminal (prints its path first)",
        description="Open a pseudo-terminal, print its path (/dev/pts/N) on the first line, and stream "
        "the simulator's samples in real time until interrupted. Accepts $STC commands on the same "
        "port (docs/protocol.md).",
    )
    p.add_argument(
        "--rate", type=float, default=None, metavar="HZ", help="sample rate (default 100; a bench's own otherwise)"
    )
    p.add_argument(
        "--procedure",
        default=registry.DEFAULT,
        choices=benches(),
        metavar="P",
        help="the bench it simulates, as the TUI's built-in device (a guided run with a reference IMU "
        "adds its ref_gx..ref_gz; the LDV's vehicle sends its beams and reference velocity): "
        f"{registry.one_of(benches())}",
    )
    p.add_argument("--protocol", default="station", choices=("station", "mavlink"))
    p.add_argument("--seed", type=seed_arg, default=0)
    p.add_argument("--effect", action="append", metavar="NAME=VALUE", help="an effect of diagnose.md and its size")
    p.add_argument("--hold", type=float, default=8.0, metavar="S", help="scripted operator's hold per position (s)")
    p.add_argument("--auto", action="store_true", help="start with the scripted operator on")
    p.add_argument("--mavlink-scaled", action="store_true", help="with --protocol mavlink, also send SCALED_IMU")
    p.add_argument("--seconds", type=float, default=None, metavar="S", help="stop after S seconds")
    p.add_argument(
        "--buffer-s",
        type=float,
        default=0.5,
        metavar="S",
        help="seconds of output the simulated UART holds while the host does not read; beyond that "
        "everything waiting is discarded and the reader sees a gap (default 0.5)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from solvers.simulate import LiveImu
    from station.device.simdevice import SimDevice

    if args.rate is not None and not (0.1 <= args.rate <= 100_000):
        raise InputError(None, None, f"--rate {args.rate:g}: must be 0.1..100000 Hz")
    require_positive("--hold", args.hold, "seconds")
    require_positive("--seconds", args.seconds, "seconds")
    require_positive("--buffer-s", args.buffer_s, "seconds")
    effects = _effects(args.effect)
    # the bench the TUI's built-in device runs for this procedure (its guide module makes it)
    entry, reference = registry.device_of(args.procedure)
    bench = entry.guide().live_device(seed=args.seed, rate_hz=args.rate or 100.0, reference=reference)
    if isinstance(bench, LiveImu):  # the unit in the operator's hand: effects, hold, scripted operator
        try:
            imu = LiveImu(
                procedure=bench.procedure,
                seed=args.seed,
                rate_hz=args.rate or 100.0,
                effects=effects,
                hold_s=args.hold,
                reference=reference,
            )
        except ValueError as exc:  # SimulationError: unknown effect for the procedure, ...
            raise InputError(None, None, str(exc).splitlines()[0]) from None
    else:  # another bench (the centrifuge, the vehicle): driven by its own commands
        if effects or args.auto or args.protocol != "station":
            raise InputError(
                None,
                None,
                f"--procedure {args.procedure}: this bench takes no --effect or --auto and speaks the station "
                "protocol only (drive it with $STC,ORIENT)",
            )
        imu = bench
        if args.rate is not None:
            imu.rate_hz = float(args.rate)
    if args.auto:
        imu.set_auto(True)
    dev = SimDevice(imu, protocol=args.protocol, mavlink_scaled=args.mavlink_scaled, max_pending_s=args.buffer_s)
    stop = threading.Event()

    def _stop(signum, frame):  # noqa: ARG001
        stop.set()

    old = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with dev:
            print(dev.path, flush=True)
            stats = dev.run(stop, duration_s=args.seconds)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
    print(
        f"sim-device: {stats.samples} samples sent, {stats.dropped} dropped (host not reading), "
        f"{stats.commands} commands, max lag {stats.behind_s * 1e3:.1f} ms",
        file=sys.stderr,
    )
    return 0
