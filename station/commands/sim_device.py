"""`station sim-device`: the simulated device on a real pseudo-terminal.

Prints the pty's path (/dev/pts/N) as the first line of stdout, then streams the
simulator's samples in real time until SIGINT/SIGTERM (exit 0) or `--seconds`.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from station.errors import InputError
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


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sim-device",
        help="a simulated device on a pseudo-terminal (prints its path first)",
        description="Open a pseudo-terminal, print its path (/dev/pts/N) on the first line, and stream "
        "the simulator's samples in real time until interrupted. Accepts $STC commands on the same "
        "port (docs/protocol.md).",
    )
    p.add_argument(
        "--rate", type=float, default=None, metavar="HZ", help="sample rate (default 100; the LDV vehicle 10)"
    )
    p.add_argument(
        "--procedure",
        default=registry.DEFAULT,
        choices=registry.names() + ("gyro-reference",),
        help="the bench it simulates; gyro-reference: P4 mode A (the unit on a reference IMU, "
        "ref_gx..ref_gz); ldv: the vehicle (beams vl1..vl3, reference vx..vz, body rates as the gyro)",
    )
    p.add_argument("--protocol", default="station", choices=("station", "mavlink"))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--effect", action="append", metavar="NAME=VALUE", help="an effect of diagnose.md and its size")
    p.add_argument("--hold", type=float, default=8.0, metavar="S", help="scripted operator's hold per position (s)")
    p.add_argument("--auto", action="store_true", help="start with the scripted operator on")
    p.add_argument("--mavlink-scaled", action="store_true", help="with --protocol mavlink, also send SCALED_IMU")
    p.add_argument("--seconds", type=float, default=None, metavar="S", help="stop after S seconds")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from solvers.simulate import LiveImu, LiveVehicle
    from station.device.simdevice import SimDevice

    if args.rate is None:
        args.rate = 10.0 if args.procedure == "ldv" else 100.0
    if not (0.1 <= args.rate <= 100_000):
        raise InputError(None, None, f"--rate {args.rate:g}: must be 0.1..100000 Hz")
    if args.hold <= 0:
        raise InputError(None, None, "--hold must be positive")
    effects = _effects(args.effect)
    if args.procedure == "ldv":  # the same vehicle as the built-in device's P5 (station.sources)
        if effects or args.auto:
            raise InputError(None, None, "--procedure ldv: the vehicle takes no --effect or --auto (drive it)")
        imu = LiveVehicle(seed=args.seed, rate_hz=args.rate)
    else:
        try:
            imu = LiveImu(
                procedure="gyro-drift" if args.procedure == "gyro-reference" else args.procedure,
                seed=args.seed,
                rate_hz=args.rate,
                effects=effects,
                hold_s=args.hold,
                reference=args.procedure == "gyro-reference",
            )
        except ValueError as exc:  # SimulationError: unknown effect for the procedure, ...
            raise InputError(None, None, str(exc).splitlines()[0]) from None
    if args.auto:
        imu.set_auto(True)
    dev = SimDevice(imu, protocol=args.protocol, mavlink_scaled=args.mavlink_scaled)
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
