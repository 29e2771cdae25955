"""`station noise FILE [--format kalibr] [--out imu.yaml]`: IMU noise figures from a still record."""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys

from station.errors import InputError
from station.fileio import atomic_write_text, cannot_write, check_output, same_file
from station.textsafe import safe


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "noise",
        help="Allan deviation, noise density, bias instability and random walk of a still IMU record",
        epilog="A record that moves (stillness detection) gets a warning and no figures, exit status 1.",
        description="Allan deviation of the gyro and accelerometer of a still time-series capture, with 68 % "
        "confidence intervals; white-noise density, bias instability and rate random walk per axis, each "
        "with its 1-sigma; a terminal plot. --format kalibr writes Kalibr's imu.yaml (rad/s/sqrt(Hz), "
        "rad/s^2/sqrt(Hz), m/s^2/sqrt(Hz), m/s^3/sqrt(Hz), update_rate).",
    )
    p.add_argument("file", help="capture file: a still recording with gx gy gz and/or ax ay az")
    p.add_argument(
        "--format",
        choices=("text", "kalibr"),
        default="text",
        help="kalibr: write imu.yaml (to --out, default imu.yaml) and print the figures",
    )
    p.add_argument("--out", metavar="FILE", help="where --format kalibr writes (default imu.yaml)")
    p.add_argument(
        "--rostopic",
        default="/imu0",
        type=_ros_name,
        help="the rostopic line of imu.yaml (default /imu0): a ROS name (letters, digits, _ and /)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the text")
    p.add_argument("--no-plot", action="store_true", help="no terminal plot")
    p.set_defaults(func=run)


def _ros_name(text: str) -> str:
    """A ROS graph resource name (wiki.ros.org/Names: a letter, / or ~ first, then letters, digits,
    _ and /): written unquoted into imu.yaml, anything else (a newline, ': ', '#') would change or
    break the YAML Kalibr reads."""
    if not re.fullmatch(r"[A-Za-z/~][A-Za-z0-9_/]*", text):
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a ROS topic name (a letter, / or ~ first, then letters, digits, _ and /)"
        )
    return text


def _write_atomic(path: str, text: str) -> None:
    with cannot_write(path):
        atomic_write_text(path, text)


def _g(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{x:.3g}"


def _text(result: dict) -> str:
    if result.get("withheld"):
        out = [f"{result.get('duration_s', 0):.0f} s at {result['sample_rate_hz']:g} Hz"]
        out.extend(f"warning: {w}" for w in result.get("warnings", []))
        out.append(result["withheld"])
        return "\n".join(out) + "\n"
    out = [
        (
            f"{result.get('duration_s', 0):.0f} s at {result['sample_rate_hz']:g} Hz (still record; Allan deviation, "
            "68 % intervals in --json)"
        )
    ]
    deg = 180.0 / math.pi
    for kind, f in result["sensors"].items():
        if kind == "gyro":
            out.append("gyro          noise density           bias instability         random walk")
            for i, a in enumerate("xyz"):
                out.append(
                    f"  {a}  {_g(f.white[i])} ± {_g(f.white_sigma[i])} rad/s/√Hz ({_g(f.white[i] * deg * 60)} °/√h)"
                    f"  {_g(f.bias_instability[i] * deg * 3600)} °/h at {_g(f.bias_instability_tau_s[i])} s"
                    f"  {_g(f.random_walk[i])} ± {_g(f.random_walk_sigma[i])} rad/s²/√Hz"
                )
        else:
            out.append("accelerometer noise density           bias instability         random walk")
            for i, a in enumerate("xyz"):
                out.append(
                    f"  {a}  {_g(f.white[i])} ± {_g(f.white_sigma[i])} m/s^2/√Hz"
                    f"  {_g(f.bias_instability[i])} m/s^2 at {_g(f.bias_instability_tau_s[i])} s"
                    f"  {_g(f.random_walk[i])} ± {_g(f.random_walk_sigma[i])} m/s³/√Hz"
                )
    from station.procedures.noise import random_walk_warning

    for kind, f in result["sensors"].items():
        w = random_walk_warning(f, kind)
        if w:
            out.append(f"warning: {w}")
    out.extend(f"warning: {w}" for w in result.get("warnings", []))
    out.extend(f"note: {n}" for n in result.get("notes", []))
    for kind, why in result.get("skipped", {}).items():
        out.append(f"{kind}: not analysed ({why})")
    return "\n".join(out) + "\n"


def _plot(result: dict) -> str:
    import plotext as plt

    from station.term import color_enabled

    color = color_enabled(sys.stdout)
    figs = []
    for kind, f in result["sensors"].items():
        plt.clear_figure()
        if not color:
            plt.theme("clear")
        plt.plotsize(78, 16)
        plt.xscale("log")
        plt.yscale("log")
        for i, a in enumerate("xyz"):
            plt.plot(f.taus_s.tolist(), f.adev[:, i].tolist(), label=a, marker="dot")
        plt.title(f"{kind} Allan deviation [{'rad/s' if kind == 'gyro' else 'm/s^2'}] against τ [s]")
        text = plt.build()
        figs.append(text if color else plt.uncolorize(text))
    return "\n".join(figs) + "\n"


def run(args: argparse.Namespace) -> int:
    from station.capture import read_capture
    from station.procedures.noise import imu_noise, kalibr_yaml, noise_json

    if args.out and args.format != "kalibr":
        raise InputError(None, None, "--out is for --format kalibr (the imu.yaml)")
    out_path = args.out or "imu.yaml"
    if args.format == "kalibr":
        check_output(out_path)
    if args.format == "kalibr" and os.path.isdir(out_path):
        raise InputError(out_path, None, "is a folder: give --out a file name")
    if args.format == "kalibr" and same_file(out_path, args.file):  # the yaml would replace the record
        raise InputError(out_path, None, "--out is the input file: choose another name")
    capture = read_capture(args.file)
    for note in capture.notes:  # said after the result (or inside its one error line)
        from station.errors import defer_warning

        defer_warning(args.file, note)
    result = imu_noise(capture)
    if result.get("withheld"):  # a record that moves: the warning, no figures, no imu.yaml; exit 1
        if args.json:
            print(json.dumps(noise_json(result), indent=2))
        else:
            sys.stdout.write(_text(result))
        return 1
    if args.format == "kalibr":
        _write_atomic(out_path, kalibr_yaml(result, args.rostopic))
    if args.json:
        print(json.dumps(noise_json(result), indent=2))
        return 0
    sys.stdout.write(_text(result))
    if not args.no_plot:  # the station's own figure: its colour codes go out as colour (drift's plot too)
        getattr(sys.stdout, "write_trusted", sys.stdout.write)(_plot(result))
    if args.format == "kalibr":
        sys.stdout.write(f"wrote {safe(out_path)}\n")
    return 0
