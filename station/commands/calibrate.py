"""`station calibrate FILE [--json] [--method M] [--device ID] [--save]` (calibrate.md).

With `--save` the result is judged first (`station.procedures.review.assess`: the
device's tolerances against the calibration in use, its absolute limits, the fit's own
checks) and the exit status says what happened:

    0  saved as accepted (it passed, or had nothing to fail; or --override NOTE)
    1  FAIL, not saved: give --reject REASON or --override NOTE to decide
    2  bad input, or the capture is already saved (nothing saved)
    3  saved as rejected (--reject REASON): kept in the history, never the reference

Whatever is saved says so on stderr, one line, ``station: saved calibration N as DECISION``
(a result dated before the device's latest calibration adds one `station: note:` line saying where it
stands; stdout holds only the result: with --json, one JSON object, calibrate.md).
"""

from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    from station.importers.options import add_arguments

    p = sub.add_parser(
        "calibrate",
        help="calibrate a capture file (the procedure named in its metadata)",
        description="Compute the calibration the capture's procedure asks for and print it.",
    )
    p.add_argument(
        "file", help="capture file (station-capture CSV), or a log: .ulg, .bin, .tlog, ROS bag/MCAP, EuRoC/Kalibr CSV"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object (calibrate.md)")
    p.add_argument(
        "--method",
        default=None,
        help="estimator, where a procedure offers several "
        "(accel-tabletop: norm | upper-triangular | six-position | step8; accel-centrifuge: exact | "
        "exact-gamma | paper | paper-3rd, each also -all; compass: rls | batch | ellipsoid; "
        "gyro-drift: reference | static (mode A | B); ldv: force)",
    )
    p.add_argument("--device", default=None, help="device id (default: the capture's 'device')")
    p.add_argument("--save", action="store_true", help="store capture and result in the station database")
    p.add_argument("--operator", default=None, help="operator's name, stored with --save")
    decide = p.add_mutually_exclusive_group()
    decide.add_argument(
        "--reject",
        default=None,
        metavar="REASON",
        help="with --save: store the result as rejected, with this reason (exit 3)",
    )
    decide.add_argument(
        "--override",
        default=None,
        metavar="NOTE",
        help="with --save: accept a result that fails its tolerances, limits or fit checks, "
        "with this note saying why (exit 0)",
    )
    p.add_argument(
        "--accuracy",
        type=float,
        default=None,
        metavar="DEG_H",
        help="gyro-drift: the 1-sigma drift accuracy asked, °/h (sets metadata accuracy_deg_h)",
    )
    p.add_argument(
        "--reference",
        default=None,
        metavar="FILE",
        help="ldv: the reference velocity stream as a separate capture (sets reference_file)",
    )
    add_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import warnings

    from station.calibrate import calibrate_capture, to_json
    from station.importers.load import load_for_command

    if getattr(args, "accuracy", None) is not None and not 0 < args.accuracy < float("inf"):
        from station.errors import InputError

        raise InputError(None, None, f"--accuracy must be a positive number of °/h, got {args.accuracy:g}")
    capture = load_for_command(args)  # a capture, or a log / EuRoC file read through the importer
    if getattr(args, "accuracy", None) is not None:
        capture.meta["accuracy_deg_h"] = repr(float(args.accuracy))
    if getattr(args, "reference", None):
        import os

        capture.meta["reference_file"] = os.path.abspath(args.reference)
    with warnings.catch_warnings():  # numpy's RuntimeWarnings are not for the operator: one line or a result
        warnings.simplefilter("ignore", RuntimeWarning)
        result = calibrate_capture(capture, method=args.method)
    if args.device:
        result["device"] = args.device
    for flag in ("reject", "override"):
        note = getattr(args, flag, None)
        if note is not None and not args.save:
            from station.errors import InputError

            raise InputError(None, None, f"--{flag} decides what --save stores: give --save too")
        if note is not None and not note.strip():
            from station.errors import InputError

            raise InputError(None, None, f"--{flag} needs a non-empty text saying why")
    status = 0
    if args.save:
        status = _save(args, capture, result)
    if args.json:
        print(to_json(result))
    else:
        from station.textsafe import safe

        shown = dict(result, device=safe(result["device"]) if result.get("device") is not None else None)
        print(_text(shown))
    return status


def _text(result: dict) -> str:
    from station.calibrate import format_text
    from station.textsafe import safe

    text = format_text(result)
    review = result.get("review")
    if review:
        lines = [f"verdict    {review['verdict'].upper()}"]
        lines += [f"  - {safe(r)}" for r in review.get("reasons", [])]
        if result.get("calibration_id") is not None:
            note = f": {safe(review['note'])}" if review.get("note") else ""
            lines.append(f"saved      calibration #{result['calibration_id']} as {review['decision']}{note}")
        else:
            lines.append("saved      nothing (FAIL: --reject REASON or --override NOTE decides)")
        text += "\n" + "\n".join(lines)
    return text


def _save(args: argparse.Namespace, capture, result: dict) -> int:
    """Judge, then save as the rules say (module docstring); the exit status.

    The database's errors are one line and exit 2 (as the db commands do). The result is judged
    against the calibration in use at its own time (the capture's date: a back-dated capture is
    not judged against a later calibration), which is the one its save supersedes. The save keeps
    the judgement current: when another process saved a new reference for it between the
    judgement and the save, nothing is saved, a line says so, and the result is judged again."""
    from station.cli import db_path
    from station.errors import InputError

    if not (args.device or "").strip() and not str(result.get("device") or "").strip():
        # before the database is opened (or made): the store's own refusal names its argument
        raise InputError(
            args.file, None, "the capture names no device (no '# device:' line): give --device ID to save it"
        )
    path = db_path(args)
    for _ in range(REJUDGE_TRIES):
        status = _judge_and_save(args, capture, result, path)
        if status is not None:
            return status
    raise InputError(
        path,
        None,
        f"not saved: the device's reference changed {REJUDGE_TRIES} times while this result was judged "
        "(other saves of the same device and procedure); try again",
    )


# Saves of one device and procedure by other processes between a judgement and its save: each
# one means judging again; beyond this many, a one-line refusal instead of a loop.
REJUDGE_TRIES = 5


def _judge_and_save(args: argparse.Namespace, capture, result: dict, path: str) -> int | None:
    """One judgement against the reference in the database and its save; the exit status, or
    None when another process saved a new reference for the device in between (judge again)."""
    import sqlite3
    import sys

    from db.store import DuplicateCapture, ReferenceChanged
    from station.commands._dbutil import db_error_text
    from station.errors import InputError
    from station.procedures.review import review_record
    from station.store import judge, kind_added, later_line, save_result, save_time

    try:
        at = save_time(capture)  # judged against the calibration in use then, which the save supersedes
    except ValueError as exc:
        raise InputError(args.file, None, str(exc)) from None
    try:
        assessment, device, previous = judge(path, result, args.device, at=at)
    except (sqlite3.Error, OSError, ValueError) as exc:
        raise InputError(path, None, f"cannot read the station database: {exc}") from None
    if args.override is not None:
        decision, note = ("override" if assessment.failed else "accepted"), args.override
    elif args.reject is not None:
        decision, note = "rejected", args.reject
    elif assessment.failed:
        decision, note = None, ""
    else:
        decision, note = "accepted", ""
    review = {
        "verdict": assessment.verdict,
        "reasons": list(assessment.reasons),
        "decision": decision,
        "note": note.strip(),
        "previous_calibration_id": previous["id"] if previous else None,
    }
    result["review"] = review
    if decision is None:
        print(
            f"station: FAIL, not saved ({'; '.join(assessment.reasons)}); --reject REASON stores it as "
            "rejected, --override NOTE accepts it",
            file=sys.stderr,
        )
        return 1
    stored = dict(review_record(assessment, decision, note), previous_calibration_id=review["previous_calibration_id"])
    try:
        result["calibration_id"] = save_result(
            path,
            capture,
            {k: v for k, v in result.items() if k != "review"},
            device_id=args.device,
            operator=args.operator,
            accepted=decision != "rejected",
            review=stored,
            time=at,
            judged_reference=previous,
        )
    except ReferenceChanged as exc:
        print(f"station: {exc}: judged again", file=sys.stderr)
        return None
    except DuplicateCapture as exc:
        raise InputError(args.file, None, str(exc)) from None
    except (sqlite3.Error, OSError) as exc:
        raise InputError(path, None, f"cannot save to the station database: {db_error_text(exc)}") from None
    except ValueError as exc:  # the store's refusals (e.g. an empty device id)
        raise InputError(None, None, str(exc)) from None
    # stdout holds only the result (calibrate.md: with --json, one JSON object): the id on stderr
    print(f"station: saved calibration {result['calibration_id']} as {decision}", file=sys.stderr)
    try:
        back_dated = later_line(path, result["calibration_id"])
    except (sqlite3.Error, OSError, ValueError):
        back_dated = None  # saved: the note is not worth a failure
    if back_dated:
        from station.textsafe import safe

        print(f"station: note: {safe(back_dated)}", file=sys.stderr)
    added = kind_added(device, result)
    if added:
        from station.textsafe import safe

        named = "--device" if args.device else "the capture's device"
        print(
            f"station: warning: device {safe(device['id'])} was registered for "
            f"{safe(', '.join(device['sensor_kinds']))}, not {added}: {added} is now among its sensor kinds "
            f"(if this capture is of another unit, {named} names the wrong one)",
            file=sys.stderr,
        )
    return 3 if decision == "rejected" else 0
