"""`station demo`: a whole calibration on the simulated device (P1 by default; P2, P3,
P4 static or with a reference IMU, P5 with --procedure), the scripted operator following
the prompts, short averaging times, the result saved (in the TUI, or with --headless as
plain lines for P1, P3 and P5)."""

from __future__ import annotations

import argparse
import sys

from station.commands.simulate import seed_arg
from station.procedures import registry


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="watch a whole calibration (P1 by default, any of P1-P5) on the simulated device",
        description="The TUI on the simulated device with a scripted operator who follows "
        "the prompts; short averaging times; the result is saved to the database.",
    )
    p.add_argument("--seed", type=seed_arg, default=0, help="simulated device's seed")
    p.add_argument(
        "--procedure",
        choices=registry.demos(),
        default=registry.DEFAULT,
        metavar="P",
        help="P1 (default), P2 on the centrifuge (60 rows: try --speed 10), the P3 compass sweep, "
        "P4 on a static base or with a reference IMU (180 s: try --speed 6), P5 LDV on a vehicle "
        f"(about 2 min: try --speed 6): {registry.one_of(registry.demos())}",
    )
    p.add_argument("--average-s", type=float, default=3.0, help="averaging time per position (default 3 s)")
    p.add_argument("--speed", type=float, default=1.0, help="device seconds per wall second (default 1)")
    p.add_argument("--headless", action="store_true", help="no screen: run the same procedure, print lines")
    p.add_argument("--exit-when-saved", action="store_true", help="quit the TUI once the result is saved")
    p.add_argument("--no-save", action="store_true", help="do not store the result")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from station.cli import db_path
    from station.errors import InputError, require_positive

    require_positive("--average-s", args.average_s, "seconds")
    require_positive("--speed", args.speed)
    if not args.no_save:  # refused now, not after the whole run
        from station.commands._dbutil import require_writable

        require_writable(
            db_path(args), "the demo saves its result there: make it writable, give --db another file, or --no-save"
        )
    if args.headless:
        return headless(args, None if args.no_save else db_path(args))
    import sys

    if not (sys.stdin.isatty() and sys.stdout.isatty()):  # (without one Textual spins a core)
        raise InputError(
            None,
            None,
            "the demo on screen needs a terminal (stdin and stdout are not one); without one: station demo --headless",
        )
    from station.app import make_app
    from station.sources import SimSource

    device = SimSource(seed=args.seed, speed=args.speed, procedure=args.procedure)
    entry, _ = registry.device_of(args.procedure)
    average_s = max(args.average_s, getattr(entry.guide(), "DEMO_MIN_AVERAGE_S", 0.0))
    app = make_app(
        None if args.no_save else db_path(args),
        device=device,
        demo=True,
        average_s=average_s,
        exit_when_saved=args.exit_when_saved,
    )
    app.session.extra["compass_min_s"] = 30.0
    app.run()
    return 0


def headless(args, db: str | None, out=None, max_device_s: float = 900.0) -> int:
    """The demo without a screen, on a simulated clock (runs as fast as the CPU allows): the
    procedure's guide module drives it (``headless_demo``)."""
    from station.sources import SimSource

    out = out if out is not None else sys.stdout  # looked up now: stdout may have been replaced
    name = getattr(args, "procedure", registry.DEFAULT)
    entry = registry.get(name)
    guide_module = entry.guide() if entry is not None else None
    if not hasattr(guide_module, "headless_demo"):
        from station.errors import UnsupportedError

        have = [p for p in registry.PROCEDURES if p.screen and hasattr(p.guide(), "headless_demo")]
        said = [p.code if p.name == registry.DEFAULT else f"{p.code} ({p.name})" for p in have]
        listed = ", ".join(said[:-1]) + " and " + said[-1] if len(said) > 1 else "".join(said)
        raise UnsupportedError(f"demo --headless: {listed} only; run the others in the TUI")
    now = [0.0]
    src = SimSource(seed=args.seed, speed=1.0, clock=lambda: now[0], procedure=name).start()
    guide = guide_module.headless_demo(src, now, average_s=args.average_s, out=out, max_device_s=max_device_s)
    return _calibrate_and_save(guide, src.device_id, db, out)


def _calibrate_and_save(guide, device_id: str, db: str | None, out) -> int:
    """The headless demos' end: calibrate the guide's capture, print it, save it if asked."""
    from station.calibrate import calibrate_capture, format_text

    capture = guide.capture(extra_meta={"simulated": "yes"})
    result = calibrate_capture(capture)
    print(format_text(result), file=out)
    if db:
        from station.procedures.review import review_record
        from station.store import judge, save_result

        assessment, _, _ = judge(db, result, device_id)
        if assessment.failed:  # the scripted operator never decides for a person
            print("FAIL, not saved: " + "; ".join(assessment.reasons), file=out)
            return 1
        from db.store import DuplicateCapture

        try:
            cal_id = save_result(
                db,
                capture,
                result,
                device_id=device_id,
                review=review_record(assessment, "accepted"),
                time=getattr(guide, "started", None),
            )
        except DuplicateCapture as exc:  # the same seed runs the same demo, sample for sample
            held = (
                f"calibration #{exc.calibration_id}" if exc.calibration_id is not None else f"capture #{exc.capture_id}"
            )
            print(
                f"already saved as {held} in {db}: the same --seed runs the same demo (--seed N for another)",
                file=out,
            )
            return 0
        print(f"saved as calibration #{cal_id} in {db}", file=out)
    return 0
