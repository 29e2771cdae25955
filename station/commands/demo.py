"""`station demo`: a whole calibration on the simulated device (P1 by default; P2, P3,
P4 static or with a reference IMU, P5 with --procedure), the scripted operator following
the prompts, short averaging times, the result saved (in the TUI, or with --headless as
plain lines for P1, P3 and P5)."""

from __future__ import annotations

import argparse
import sys

from station.procedures import registry

DEMOS = ("accel-tabletop", "accel-centrifuge", "compass", "gyro-drift", "gyro-reference", "ldv")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="watch a whole calibration (P1 by default, any of P1-P5) on the simulated device",
        description="The TUI on the simulated device with a scripted operator who follows "
        "the prompts; short averaging times; the result is saved to the database.",
    )
    p.add_argument("--seed", type=int, default=0, help="simulated device's seed")
    p.add_argument(
        "--procedure",
        choices=DEMOS,
        default=registry.DEFAULT,
        help="P1 (default), P2 on the centrifuge (60 rows: try --speed 10), the P3 compass sweep, "
        "P4 on a static base or with a reference IMU (180 s: try --speed 6), P5 LDV on a vehicle "
        "(about 2 min: try --speed 6)",
    )
    p.add_argument("--average-s", type=float, default=3.0, help="averaging time per position (default 3 s)")
    p.add_argument("--speed", type=float, default=1.0, help="device seconds per wall second (default 1)")
    p.add_argument("--headless", action="store_true", help="no screen: run the same procedure, print lines")
    p.add_argument("--exit-when-saved", action="store_true", help="quit the TUI once the result is saved")
    p.add_argument("--no-save", action="store_true", help="do not store the result")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from station.cli import db_path
    from station.errors import InputError

    if not args.average_s > 0 or not args.speed > 0:
        raise InputError(None, None, "--average-s and --speed must be positive")
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
    average_s = max(args.average_s, 180.0) if args.procedure in ("gyro-drift", "gyro-reference") else args.average_s
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
    """The demo without a screen, on a simulated clock (runs as fast as the CPU allows)."""
    out = out if out is not None else sys.stdout  # looked up now: stdout may have been replaced
    if getattr(args, "procedure", "accel-tabletop") == "compass":
        return headless_compass(args, db, out, max_device_s)
    if getattr(args, "procedure", "accel-tabletop") == "ldv":
        return headless_ldv(args, db, out, max_device_s)
    if getattr(args, "procedure", "accel-tabletop") != "accel-tabletop":
        from station.errors import UnsupportedError

        raise UnsupportedError("demo --headless: P1, P3 (compass) and P5 (ldv) only; run the others in the TUI")
    from station.procedures.tabletop_guide import GuideConfig, P1Guide, ScriptedOperator
    from station.sources import SimSource

    now = [0.0]
    src = SimSource(seed=args.seed, speed=1.0, clock=lambda: now[0]).start()
    guide = P1Guide(
        sample_rate_hz=src.rate_hz,
        accel_unit=src.units["accel_unit"],
        device_id=src.device_id,
        config=GuideConfig(average_s=args.average_s, settle_s=1.0),
        nominal=src.nominal,
        site=src.site,
    )
    operator = ScriptedOperator(src.place, reaction_s=1.0, mistakes={"y_down": "y_up"}, mistake_s=6.0)
    last_phase = None
    last_capture_t = 0.0
    while guide.phase not in ("done", "aborted") and now[0] < max_device_s:
        now[0] += 0.05
        b = src.drain()
        if b is None:
            continue
        st = guide.update(b.t_s, b.accel, b.gyro, b.temp_c)
        operator.step(guide, st.t_s)
        for kind, detail in guide.take_events():
            print(f"{st.t_s:7.1f} s  {kind:<9} {detail}", file=out)
            last_capture_t = st.t_s
        # the unit still sits at the previous position right after a capture: not a mistake
        if st.wrong_face and st.is_still and st.t_s - last_capture_t > 4.0 and last_phase != "wrong":
            print(f"{st.t_s:7.1f} s  wrong face up at {st.step_name} ({st.angle_deg:.0f}°)", file=out)
            last_phase = "wrong"
        elif not st.wrong_face and last_phase == "wrong":
            last_phase = None
    if guide.phase != "done":
        from station.errors import UnsupportedError

        raise UnsupportedError(f"demo did not finish within {max_device_s:g} s of device time")
    return _calibrate_and_save(guide, src.device_id, db, out)


def headless_compass(args, db: str | None, out=None, max_device_s: float = 900.0) -> int:
    """The P3 sweep without a screen: the scripted operator visits the sphere positions."""
    out = out if out is not None else sys.stdout
    from station.procedures.compass_guide import CompassConfig, CompassGuide, SweepOperator, sweep_positions
    from station.sources import SimSource

    now = [0.0]
    src = SimSource(seed=args.seed, clock=lambda: now[0], procedure="compass").start()
    guide = CompassGuide(
        sample_rate_hz=src.rate_hz,
        units=src.units,
        device_id=src.device_id,
        site=src.site,
        config=CompassConfig(min_s=30.0),
    )
    operator = SweepOperator(src.place, sweep_positions(src.positions), hold_s=1.0)
    shown = -1
    while guide.phase == "sweep" and now[0] < max_device_s:
        now[0] += 0.05
        b = src.drain()
        if b is None:
            continue
        st = guide.update(b.t_s, b.accel, b.gyro, b.mag, b.temp_c)
        operator.step(guide, st.t_s)
        if int(st.coverage * 10) != shown:
            shown = int(st.coverage * 10)
            print(f"{st.t_s:7.1f} s  coverage {100 * st.coverage:3.0f} %", file=out)
    return _calibrate_and_save(guide, src.device_id, db, out)


def headless_ldv(args, db: str | None, out=None, max_device_s: float = 900.0) -> int:
    """P5 without a screen: the demo driver sets off straight, then turns and climbs; the
    conditioning of the velocity set is printed as it builds."""
    import numpy as np

    out = out if out is not None else sys.stdout
    from station.procedures.ldv_guide import Driver, LdvGuide
    from station.sources import SimSource

    now = [0.0]
    src = SimSource(seed=args.seed, clock=lambda: now[0], procedure="ldv").start()
    guide = LdvGuide(sample_rate_hz=src.rate_hz, device_id=src.device_id, site=src.site)
    driver = Driver(src.place)
    verdict = None
    while guide.phase == "record" and now[0] < max_device_s:
        now[0] += 0.5
        b = src.drain()
        if b is None:
            continue
        e = b.extra
        st = guide.update(
            b.t_s,
            np.column_stack([e["vl1"], e["vl2"], e["vl3"]]),
            np.column_stack([e["vx"], e["vy"], e["vz"]]),
            b.gyro,
            b.temp_c,
        )
        said = driver.step(guide, st.t_s)
        if said:
            print(f"{st.t_s:7.1f} s  driver: {said}", file=out)
        if st.verdict != verdict:
            verdict = st.verdict
            print(f"{st.t_s:7.1f} s  conditioning {verdict} (κ {st.kappa:.3g}, {st.n_epochs} moving epochs)", file=out)
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
        cal_id = save_result(
            db,
            capture,
            result,
            device_id=device_id,
            review=review_record(assessment, "accepted"),
            time=getattr(guide, "started", None),
        )
        print(f"saved as calibration #{cal_id} in {db}", file=out)
    return 0
