"""`station tui` (also `station` with no command): the operator console."""

from __future__ import annotations

import argparse

from station.commands.simulate import seed_arg


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tui",
        help="operator console: guided calibration, results, history (the default)",
        description="The operator TUI. Starts on the Connect screen with the built-in "
        "simulated device selected; --port pre-selects a serial device.",
    )
    p.add_argument("--port", default=None, help="serial port or pyserial URL of the device")
    p.add_argument("--protocol", choices=("station", "mavlink"), default="station", help="wire protocol of --port")
    p.add_argument("--sim", action="store_true", help="connect to the built-in simulated device and start P1 at once")
    p.add_argument("--seed", type=seed_arg, default=0, help="simulated device's seed (with --sim)")
    p.add_argument(
        "--speed", type=float, default=1.0, help="the built-in simulated device's seconds per wall second (default 1)"
    )
    p.add_argument(
        "--average-s",
        type=float,
        default=None,
        help="averaging time per position in seconds (default 180, the source's 3-5 minutes; on the "
        "built-in simulated device shorter, e.g. 10 s for P1, so a first run takes minutes)",
    )
    p.add_argument("--device-id", default=None, help="serial number of the device under test")
    p.add_argument("--model", default="", help="model of the device under test")
    p.add_argument(
        "--site",
        default=None,
        metavar="LAT,LON[,ALT_M]",
        help="where the bench is (WGS-84 degrees, metres), for a serial device: gravity (P1), Earth rate (P4), "
        "IGRF field (P3); remembered in the database (default: the one remembered)",
    )
    p.add_argument("--state-dir", default=None, help="folder of resume files (default: next to the database)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import sys

    from station.app import make_app
    from station.cli import db_path
    from station.commands._dbutil import require_writable
    from station.errors import InputError, require_positive

    path = db_path(args)  # a given --db in a missing folder is refused before the screen is drawn
    require_writable(
        path,
        "the console saves every calibration there: make it writable, or give --db another file "
        "(`station history` and `station devices` read it as it is)",
    )
    require_positive("--speed", args.speed)
    require_positive("--average-s", args.average_s, "seconds")
    site = None
    if args.site is not None:
        from station.sources import parse_site

        try:
            site = parse_site(args.site)
        except ValueError as exc:
            raise InputError(None, None, f"--site: {exc}") from None
        if args.sim:
            raise InputError(None, None, "--site is for a serial device: the simulated device has its own site")
    if not (sys.stdin.isatty() and sys.stdout.isatty()):  # (without one Textual spins a core)
        raise InputError(
            None,
            None,
            "the operator console needs a terminal (stdin and stdout are not one); "
            "for scripts: station demo --headless, station calibrate FILE",
        )

    device = None
    start = None
    if args.port:
        from station.sources import SerialSource

        device = SerialSource(args.port, protocol=args.protocol)
    elif args.sim:
        from station.sources import SimSource

        device = SimSource(seed=args.seed, speed=args.speed)
        start = "procedure"
        if args.average_s is None:  # the simulated device's default, as Connect offers it
            from station.procedures import registry

            args.average_s = registry.default_average_s(registry.DEFAULT, True)
    app = make_app(
        path,
        device=device,
        average_s=args.average_s,
        device_id=args.device_id,
        model=args.model,
        state_dir=args.state_dir,
        start=start,
    )
    app.session.extra["sim_speed"] = args.speed
    if site is not None:
        app.session.extra["site"] = site
    app.run()
    src = app.session.source
    if src is not None:
        src.stop()
    return 0
