"""Fuzz and extreme-value harness: every command in-process, a time limit per case.

Two kinds of input, both built from captures the station's own simulator writes for all
five procedures (realistic noise, timing and layout):

- **mutated** captures: the file's bytes changed the way corrupt logs, careless edits and
  hostile files change them (:data:`MUTATORS`: flipped, inserted or deleted bytes, lines cut,
  repeated, swapped or truncated, fields emptied or replaced by extreme or malformed
  numbers, control characters, NUL, BOM, CR, very long lines, header and metadata edits).
- **extreme** captures: valid files (written by ``write_capture``) whose values are
  extreme (:data:`EXTREMES`: columns scaled by 1e-30..1e30, constant, zero, mostly empty,
  one spike, time offset by 1e9 s or frozen, two rows, metadata at the edge of its range).

Each case runs ``station.cli.main([command, file, '--json'])`` in a worker process (forked
once, reused), with file descriptor 1 redirected so that stray C-level output is caught.
The parent gives each case ``timeout_s`` of the worker's CPU time (or ten times that in wall
time); a worker that does not answer is killed and the case is a **hang**. Outcomes: ``ok`` (exit 0, stdout one JSON document), ``refused`` (exit 2,
stdout empty, one line on stderr with a reason), and the failures: ``hang``, ``last-resort``
(the CLI's ``cannot process this input``), ``stray-stdout`` (anything on fd 1 but the JSON),
``bad-exit`` (another status or a multi-line error), ``crash`` (an exception out of main).
"""

from __future__ import annotations

import contextlib
import io
import json
import multiprocessing as mp
import os
import random
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np

COMMANDS = ("calibrate", "diagnose")
FAILURES = ("hang", "last-resort", "stray-stdout", "bad-exit", "crash")

# Small but realistic bases: (name, procedure, simulator options). Sized so one calibrate plus
# one diagnose takes about a second on one core.
BASES = [
    ("p1-series", "accel-tabletop", {"hold_s": 2.0, "move_s": 1.0, "rate_hz": 25.0}),
    ("p1-table", "accel-tabletop", {"averages": True}),
    ("p2-table", "accel-centrifuge", {}),
    ("p3", "compass", {"n_orientations": 12, "hold_s": 1.0, "move_s": 1.0, "rate_hz": 20.0}),
    ("p4-static", "gyro-drift", {"mode": "static", "duration_s": 190.0, "rate_hz": 5.0}),
    ("p4-reference", "gyro-drift", {"mode": "reference", "duration_s": 190.0, "rate_hz": 5.0}),
    ("p5-body", "ldv", {"duration_s": 40.0, "rate_hz": 5.0}),
    ("p5-nav", "ldv", {"duration_s": 40.0, "rate_hz": 5.0, "reference": "nav"}),
]


def make_bases(folder: str, seed: int = 0, names: tuple[str, ...] | None = None) -> dict[str, str]:
    """Write the simulated base captures into ``folder``; {name: path}."""
    from solvers.simulate import simulate
    from station.capture import Capture, write_capture

    out = {}
    for name, procedure, options in BASES:
        if names is not None and name not in names:
            continue
        sim = simulate(procedure, seed=seed, **options)
        path = os.path.join(folder, f"{name}.csv")
        write_capture(path, Capture(dict(sim.meta), {k: np.asarray(v) for k, v in sim.columns.items()}))
        out[name] = path
    return out


# ------------------------------------------------------------------------------ mutations

_EXTREME_TEXT = [
    "1e308",
    "-1e308",
    "1e-320",
    "4.9e-324",
    "1e400",
    "-0",
    "0",
    "nan",
    "inf",
    "-inf",
    "NaN",
    "1" * 400,
    "0x10",
    "1_000",
    "１２",
    "1e",
    "--1",
    ".",
    "+",
    "1,5",
    '"3"',
    " ",
    "\t7",
    "9" * 20,
    "1e200",
    "-1e200",
    "1e20",
    "2e20",
    "3.4e38",
    "1.7976931348623157e308",
]
_CONTROL = ["\x00", "\x1b[31m", "\x07", "\r", "\x9b", "\u202e", "\ufeff", "\x7f", "\x0b", "\x0c", "\u2028"]
_META_EDITS = [
    ("procedure", ["", "accel-tabletop", "compass", "ldv", "gyro-drift", "accel-centrifuge", "nope", "P1"]),
    ("accel_unit", ["", "V", "g", "m/s^2", "counts", "furlongs", "deg/s"]),
    ("gyro_unit", ["", "rad/s", "deg/s", "V", "g"]),
    ("mag_unit", ["", "uT", "nT", "gauss", "counts", "V"]),
    ("latitude_deg", ["90", "-90", "91", "1e308", "nan", "", "abc", "0"]),
    ("longitude_deg", ["360", "-180", "361", "1e308", ""]),
    ("altitude_m", ["1e308", "-12000", "1000000", "1000001", "-1e6", "nan"]),
    (
        "date",
        [
            "1850-01-01",
            "1897-06-01",
            "2031-06-01",
            "2099-01-01",
            "2026-02-30",
            "0001-01-01",
            "9999-12-31",
            "yesterday",
            "",
        ],
    ),
    ("radius_m", ["0", "-1", "1e-300", "10000", "1e308", "abc"]),
    ("g_mps2", ["0", "1e-300", "1000", "1e308", "-9.8"]),
    ("gyro_mode", ["reference", "static", "other", ""]),
    ("heading_deg", ["720", "-360", "1e308", "nan"]),
    ("sample_rate_hz", ["0", "1e-300", "1e9", "1e308"]),
    ("device", ["\x1b]0;x\x07", "a\u202eb", "", "X" * 5000]),
]


def _lines(text: str) -> list[str]:
    return text.split("\n")


def _data_start(lines: list[str]) -> int:
    for i, line in enumerate(lines):
        if line and not line.startswith("#"):
            return i + 1
    return len(lines)


def m_flip_bytes(text, rng):
    b = bytearray(text.encode("utf-8", "surrogatepass"))
    for _ in range(rng.randint(1, 8)):
        i = rng.randrange(len(b))
        b[i] = rng.randrange(256)
    return bytes(b)


def m_insert_bytes(text, rng):
    b = bytearray(text.encode())
    i = rng.randrange(len(b))
    b[i:i] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
    return bytes(b)


def m_delete_span(text, rng):
    i = rng.randrange(len(text))
    return text[:i] + text[i + rng.randint(1, 200) :]


def m_truncate(text, rng):
    return text[: rng.randrange(len(text))]


def m_field(text, rng):
    lines = _lines(text)
    start = _data_start(lines)
    for _ in range(rng.randint(1, 4)):
        i = rng.randrange(start, max(start + 1, len(lines) - 1))
        if i >= len(lines) or not lines[i]:
            continue
        cells = lines[i].split(",")
        j = rng.randrange(len(cells))
        cells[j] = rng.choice(_EXTREME_TEXT)
        lines[i] = ",".join(cells)
    return "\n".join(lines)


def m_column(text, rng):
    """One whole column emptied, made constant or extreme."""
    lines = _lines(text)
    start = _data_start(lines)
    if start >= len(lines):
        return text
    j = rng.randrange(len(lines[start - 1].split(",")))
    value = rng.choice(["", "0", "1e200", "-1e15", "7", "1e-300"])
    for i in range(start, len(lines)):
        cells = lines[i].split(",")
        if len(cells) > j and lines[i]:
            cells[j] = value
            lines[i] = ",".join(cells)
    return "\n".join(lines)


def m_lines(text, rng):
    lines = _lines(text)
    start = _data_start(lines)
    op = rng.choice(["dup", "del", "swap", "blank", "comment", "reverse", "shuffle"])
    i = rng.randrange(max(1, len(lines)))
    k = rng.randrange(max(1, len(lines)))
    if op == "dup":
        lines[i:i] = [lines[i]] * rng.randint(1, 50)
    elif op == "del":
        del lines[i : i + rng.randint(1, 100)]
    elif op == "swap":
        lines[i], lines[k] = lines[k], lines[i]
    elif op == "blank":
        lines.insert(i, "")
    elif op == "comment":
        lines.insert(i, "# injected: " + rng.choice(_CONTROL))
    elif op == "reverse" and start < len(lines):
        lines[start:] = lines[start:][::-1]
    elif op == "shuffle" and start < len(lines):
        data = lines[start:]
        rng.shuffle(data)
        lines[start:] = data
    return "\n".join(lines)


def m_control(text, rng):
    i = rng.randrange(len(text))
    return text[:i] + rng.choice(_CONTROL) + text[i:]


def m_header(text, rng):
    lines = _lines(text)
    h = _data_start(lines) - 1
    if h < 0 or h >= len(lines):
        return text
    names = lines[h].split(",")
    op = rng.choice(["drop", "dup", "rename", "swap", "empty", "extra"])
    j = rng.randrange(len(names))
    if op == "drop":
        del names[j]
    elif op == "dup":
        names.append(names[j])
    elif op == "rename":
        names[j] = rng.choice(["t", "ax", "mx", "vl1", "ref_gx", "position", "speed_rad_s", "n", "ax_std", "x"])
    elif op == "swap":
        k = rng.randrange(len(names))
        names[j], names[k] = names[k], names[j]
    elif op == "empty":
        names[j] = ""
    else:
        names.append("extra")
    lines[h] = ",".join(names)
    return "\n".join(lines)


def m_meta(text, rng):
    key, values = rng.choice(_META_EDITS)
    value = rng.choice(values)
    lines = _lines(text)
    for i, line in enumerate(lines):
        if line.startswith(f"# {key}:"):
            if rng.random() < 0.2:
                del lines[i]
            else:
                lines[i] = f"# {key}: {value}"
            return "\n".join(lines)
    lines.insert(1, f"# {key}: {value}")
    return "\n".join(lines)


def m_long_line(text, rng):
    lines = _lines(text)
    i = rng.randrange(max(1, _data_start(lines)), max(2, len(lines)))
    if i < len(lines):
        lines[i] = lines[i] + rng.choice([" ", "0", ",1"]) * rng.choice([1000, 70_000, 300_000])
    return "\n".join(lines)


def m_line_endings(text, rng):
    return rng.choice(
        [
            text.replace("\n", "\r\n"),
            text.replace("\n", "\r"),
            "\ufeff" + text,
            text.replace("\n", "\r\n", rng.randint(1, 50)),
        ]
    )


MUTATORS = [
    m_flip_bytes,
    m_insert_bytes,
    m_delete_span,
    m_truncate,
    m_field,
    m_field,
    m_column,
    m_lines,
    m_control,
    m_header,
    m_meta,
    m_meta,
    m_long_line,
    m_line_endings,
]


def mutate(text: str, rng: random.Random) -> tuple[str, bytes]:
    """(names of the mutators applied, the mutated file's bytes): one to three mutations."""
    names, data = [], text
    for _ in range(rng.choice([1, 1, 1, 2, 3])):
        for _attempt in range(20):  # a mutator with nothing to act on (no data line left) gives way to another
            m = rng.choice(MUTATORS)
            try:
                out = m(data if isinstance(data, str) else data.decode("utf-8", "replace"), rng)
            except (ValueError, IndexError):
                continue
            names.append(m.__name__[2:])
            data = out
            break
    return "+".join(names) or "none", (data if isinstance(data, bytes) else data.encode("utf-8", "surrogatepass"))


# ------------------------------------------------------------------------------ extreme but valid

_MEASURED = {
    "ax",
    "ay",
    "az",
    "gx",
    "gy",
    "gz",
    "mx",
    "my",
    "mz",
    "vl1",
    "vl2",
    "vl3",
    "vx",
    "vy",
    "vz",
    "vn",
    "ve",
    "vd",
    "ref_gx",
    "ref_gy",
    "ref_gz",
    "speed_rad_s",
    "temp_c",
    "roll_deg",
    "pitch_deg",
    "yaw_deg",
    "wx",
    "wy",
    "wz",
}


def _numeric(cap):
    return [k for k, v in cap.columns.items() if np.asarray(v).dtype.kind == "f" and k != "t"]


def x_scale(cap, rng):
    name = rng.choice(_numeric(cap))
    k = rng.choice([1e-30, 1e-15, 1e-9, 1e-3, -1.0, 1e3, 1e9, 1e15, 1e19, 1e25, 1e30])
    cap.columns[name] = np.asarray(cap.columns[name]) * k
    return f"scale {name} x{k:g}"


def x_all_scale(cap, rng):
    k = rng.choice([1e-12, 1e6, 1e12, 1e18])
    for name in _numeric(cap):
        cap.columns[name] = np.asarray(cap.columns[name]) * k
    return f"scale all x{k:g}"


def x_constant(cap, rng):
    name = rng.choice(_numeric(cap))
    v = rng.choice([0.0, 1.0, -3.3, 1e19])
    cap.columns[name] = np.full(cap.n_rows, v)
    return f"{name} constant {v:g}"


def x_sparse(cap, rng):
    name = rng.choice(_numeric(cap))
    col = np.array(cap.columns[name], dtype=float)
    keep = rng.choice([0.0, 0.001, 0.01, 0.5])
    mask = np.random.default_rng(rng.randrange(1 << 30)).random(len(col)) >= keep
    col[mask] = np.nan
    cap.columns[name] = col
    return f"{name} {keep:g} kept"


def x_spike(cap, rng):
    name = rng.choice(_numeric(cap))
    col = np.array(cap.columns[name], dtype=float)
    col[rng.randrange(len(col))] = rng.choice([1e19, -1e19, 1e300, 1e-300, 0.0])
    cap.columns[name] = col
    return f"{name} spike"


def x_time(cap, rng):
    if "t" not in cap.columns:
        return x_scale(cap, rng)
    t = np.asarray(cap.columns["t"], dtype=float)
    op = rng.choice(["offset", "tiny", "huge", "frozen", "steps", "dup"])
    if op == "offset":
        t = t + rng.choice([1e9, 1.7e9, 1e15])
    elif op == "tiny":
        t = t * 1e-9
    elif op == "huge":
        t = t * 1e9
    elif op == "frozen":
        t = np.zeros_like(t)
    elif op == "steps":
        t = np.floor(t)
    else:
        t = np.repeat(t[::2], 2)[: len(t)]
    cap.columns["t"] = t
    return f"time {op}"


def x_rows(cap, rng):
    n = rng.choice([1, 2, 3, 5])
    start = rng.randrange(max(1, cap.n_rows - n))
    for k in list(cap.columns):
        cap.columns[k] = np.asarray(cap.columns[k])[start : start + n]
    return f"{n} rows"


def x_meta(cap, rng):
    key, value = rng.choice(
        [
            ("latitude_deg", "90"),
            ("latitude_deg", "-90"),
            ("longitude_deg", "360"),
            ("altitude_m", "-12000"),
            ("altitude_m", "1000000"),
            ("date", "1896-01-01"),
            ("date", "2034-12-31"),
            ("g_mps2", "1000"),
            ("radius_m", "0.000001"),
            ("radius_m", "10000"),
            ("heading_deg", "720"),
            ("sample_rate_hz", "1e9"),
        ]
    )
    cap.meta[key] = value
    return f"{key}={value}"


EXTREMES = [x_scale, x_scale, x_all_scale, x_constant, x_sparse, x_spike, x_time, x_rows, x_meta]


def extreme(path: str, rng: random.Random) -> tuple[str, object]:
    """(description, a Capture) with one or two extreme-value edits, still a valid file."""
    from station.capture import read_capture

    cap = read_capture(path)
    cap.path = None
    names = [rng.choice(EXTREMES)(cap, rng) for _ in range(rng.choice([1, 1, 2]))]
    return "; ".join(names), cap


# ------------------------------------------------------------------------------ running


@dataclass
class Outcome:
    kind: str  # ok, refused, or one of FAILURES
    command: str
    case: str
    seconds: float
    detail: str = ""


def _run_main(command: str, path: str) -> tuple[int | None, str, str, bytes, str]:
    """main([command, path, --json]) with Python stdout/stderr captured and fd 1 redirected."""
    from station.cli import main

    out, err = io.StringIO(), io.StringIO()
    sink = tempfile.TemporaryFile()
    saved = os.dup(1)
    os.dup2(sink.fileno(), 1)
    crash = ""
    rc = None
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                rc = main([command, path, "--json"])
            except SystemExit as exc:  # argparse
                rc = exc.code if isinstance(exc.code, int) else 2
            except BaseException as exc:  # noqa: BLE001 - the harness records it
                crash = f"{type(exc).__name__}: {exc}"
    finally:
        try:
            import ctypes

            ctypes.CDLL(None).fflush(None)
        except Exception:  # noqa: BLE001
            pass
        os.dup2(saved, 1)
        os.close(saved)
    sink.seek(0)
    stray = sink.read(4096)
    sink.close()
    return rc, out.getvalue(), err.getvalue(), stray, crash


def classify(
    command: str, case: str, rc, stdout: str, stderr: str, stray: bytes, crash: str, seconds: float
) -> Outcome:
    if crash:
        return Outcome("crash", command, case, seconds, crash[:300])
    if stray:
        return Outcome("stray-stdout", command, case, seconds, stray[:200].decode("utf-8", "replace"))
    if "cannot process this input" in stderr:
        return Outcome("last-resort", command, case, seconds, stderr.strip()[:300])
    if rc == 0:
        try:
            json.loads(stdout)
        except ValueError:
            return Outcome("stray-stdout", command, case, seconds, stdout[:200])
        return Outcome("ok", command, case, seconds)
    if rc == 2 and stdout == "" and stderr.count("\n") == 1 and stderr.startswith("station: "):
        return Outcome("refused", command, case, seconds, stderr.strip()[:200])
    return Outcome("bad-exit", command, case, seconds, f"exit {rc}: {(stdout + stderr)[:300]!r}")


def _worker(conn) -> None:
    import warnings

    warnings.simplefilter("ignore")
    while True:
        job = conn.recv()
        if job is None:
            return
        command, path, case = job
        t0 = time.monotonic()
        rc, out, err, stray, crash = _run_main(command, path)
        conn.send(classify(command, case, rc, out, err, stray, crash, time.monotonic() - t0))


# A case is a hang when its worker spends more than the limit in CPU time (a machine shared
# with other work stretches wall time, not CPU time), or ten times the limit in wall time.
WALL_FACTOR = 10.0


def _cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` (Linux /proc; wall-clock fallback elsewhere)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return time.monotonic()


@dataclass
class Runner:
    """A forked worker that runs cases one by one; killed and replaced after a hang."""

    timeout_s: float = 60.0
    _proc: object = None
    _conn: object = None
    outcomes: list = field(default_factory=list)

    def _start(self) -> None:
        ctx = mp.get_context("fork")
        parent, child = ctx.Pipe()
        self._proc = ctx.Process(target=_worker, args=(child,), daemon=True)
        self._proc.start()
        self._conn = parent

    def run(self, command: str, path: str, case: str) -> Outcome:
        if self._proc is None or not self._proc.is_alive():
            self._start()
        t0 = time.monotonic()
        cpu0 = _cpu_s(self._proc.pid)
        self._conn.send((command, path, case))
        while True:
            if self._conn.poll(0.25):
                try:
                    outcome = self._conn.recv()
                except EOFError:
                    outcome = Outcome("crash", command, case, time.monotonic() - t0, "the worker died")
                    self._proc = None
                break
            cpu = _cpu_s(self._proc.pid) - cpu0
            wall = time.monotonic() - t0
            if cpu > self.timeout_s or wall > WALL_FACTOR * self.timeout_s:
                self._proc.kill()
                self._proc.join(10)
                self._proc = None
                outcome = Outcome(
                    "hang",
                    command,
                    case,
                    wall,
                    f"no answer after {cpu:.0f} s of CPU ({wall:.0f} s wall); limit {self.timeout_s:g} s CPU",
                )
                break
        self.outcomes.append(outcome)
        return outcome

    def close(self) -> None:
        if self._proc is not None and self._proc.is_alive():
            self._conn.send(None)
            self._proc.join(10)
            if self._proc.is_alive():
                self._proc.kill()


def run_campaign(
    folder: str,
    bases: dict[str, str],
    *,
    n_mutated: int,
    n_extreme: int,
    seed: int,
    timeout_s: float,
    commands=COMMANDS,
    progress=None,
) -> list[Outcome]:
    """``n_mutated`` mutated and ``n_extreme`` extreme captures, each through every command."""
    from station.capture import write_capture

    rng = random.Random(seed)
    texts = {name: open(p, encoding="utf-8").read() for name, p in bases.items()}
    names = sorted(bases)
    runner = Runner(timeout_s=timeout_s)
    path = os.path.join(folder, "case.csv")
    try:
        for k in range(n_mutated + n_extreme):
            base = names[k % len(names)]
            if k < n_mutated:
                what, data = mutate(texts[base], rng)
                with open(path, "wb") as f:
                    f.write(data)
                case = f"mutated#{seed}.{k} {base}: {what}"
            else:
                what, cap = extreme(bases[base], rng)
                try:
                    write_capture(path, cap)
                except Exception as exc:  # noqa: BLE001 - the writer refused: not a valid file, skip
                    runner.outcomes.append(
                        Outcome("skipped", "write", f"extreme#{seed}.{k} {base}: {what}", 0.0, str(exc))
                    )
                    continue
                case = f"extreme#{seed}.{k} {base}: {what}"
            for command in commands:
                runner.run(command, path, case)
            if progress is not None:
                progress(k + 1, runner.outcomes)
    finally:
        runner.close()
    return runner.outcomes


def summary(outcomes: list[Outcome]) -> dict:
    """Counts per kind and the failures, for printing and asserting."""
    cases = {o.case for o in outcomes if o.kind != "skipped"}
    counts: dict[str, int] = {}
    for o in outcomes:
        counts[o.kind] = counts.get(o.kind, 0) + 1
    times = [o.seconds for o in outcomes if o.kind in ("ok", "refused")]
    return {
        "captures": len(cases),
        "mutated": len({c for c in cases if c.startswith("mutated")}),
        "extreme": len({c for c in cases if c.startswith("extreme")}),
        "runs": sum(v for k, v in counts.items() if k != "skipped"),
        "counts": counts,
        "failures": [o for o in outcomes if o.kind in FAILURES],
        "max_s": max(times, default=0.0),
        "median_s": float(np.median(times)) if times else 0.0,
    }
