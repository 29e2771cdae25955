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
FAILURES = ("hang", "last-resort", "stray-stdout", "bad-exit", "crash", "half-written")

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
    return _mutate_with(text, rng, MUTATORS, [1, 1, 1, 2, 3], bytes_end=False)


def _mutate_with(text: str, rng: random.Random, mutators: list, counts: list[int], bytes_end: bool):
    """(names, bytes) of rng.choice(counts) mutations drawn from ``mutators``; ``bytes_end``: a
    mutation that made bytes is the last (else the next sees them decoded, bad bytes replaced)."""
    names, data = [], text
    for _ in range(rng.choice(counts)):
        if bytes_end and isinstance(data, bytes):
            break
        for _attempt in range(20):  # a mutator with nothing to act on (no data line left) gives way to another
            m = rng.choice(mutators)
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


def _run_main(argv: list[str]) -> tuple[int | None, str, str, bytes, str]:
    """main(argv) (``[command, path, --json]`` and the like) with Python stdout/stderr captured
    and fd 1 redirected."""
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
                rc = main(list(argv))
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
    command: str,
    case: str,
    rc,
    stdout: str,
    stderr: str,
    stray: bytes,
    crash: str,
    seconds: float,
    json_out: bool = True,
) -> Outcome:
    """The outcome of one run. ``json_out``: the result on stdout is one JSON document (the
    ``--json`` commands); otherwise (``inspect``, ``import``) any text, but not none."""
    if crash:
        return Outcome("crash", command, case, seconds, crash[:300])
    if stray:
        return Outcome("stray-stdout", command, case, seconds, stray[:200].decode("utf-8", "replace"))
    if "cannot process this input" in stderr:
        return Outcome("last-resort", command, case, seconds, stderr.strip()[:300])
    if rc == 0:
        try:
            json.loads(stdout) if json_out else None
        except ValueError:
            return Outcome("stray-stdout", command, case, seconds, stdout[:200])
        if not json_out and not stdout.strip():
            return Outcome("bad-exit", command, case, seconds, f"exit 0 and no result on stdout: {stderr[:200]!r}")
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
        command, argv, case = job
        t0 = time.monotonic()
        rc, out, err, stray, crash = _run_main(argv)
        conn.send(classify(command, case, rc, out, err, stray, crash, time.monotonic() - t0, "--json" in argv))


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

    def run(self, command: str, path: str, case: str, argv: list[str] | None = None) -> Outcome:
        """``station <command> <path> --json`` (or ``argv``, the whole command line; ``command``
        then names it in the outcome)."""
        if self._proc is None or not self._proc.is_alive():
            self._start()
        t0 = time.monotonic()
        cpu0 = _cpu_s(self._proc.pid)
        self._conn.send((command, list(argv) if argv is not None else [command, path, "--json"], case))
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


# ------------------------------------------------------------------ the world's files, hostile ones
#
# QA s27i: the same harness over real captures (../shared/data, cut to their first rows) as well
# as simulated ones, more ways a file is broken, the special files a path can name, and every
# command that reads a capture: ``inspect``, ``import`` (with ``--out``), ``calibrate`` (also with
# ``--save`` to a real SQLite file), ``diagnose``. What a command writes is checked too: a refused
# run leaves ``--out`` unwritten and the database byte for byte as it was, no temporary beside
# them; a run that succeeds leaves a capture the reader reads and a database SQLite finds whole.
# An outcome that breaks one of these is ``half-written``.

HOSTILE_COMMANDS = ("inspect", "import", "calibrate", "calibrate-save", "diagnose")
IMPORT_PROCEDURES = ("accel-tabletop", "compass", "gyro-drift")  # what `station import --procedure` takes
REAL_MAX_ROWS = 1500  # rows kept of each real capture: its own head and layout, a second to run


def real_bases(folder: str, shared: str | None = None, max_rows: int = REAL_MAX_ROWS) -> dict[str, str]:
    """The real captures of ``shared/data`` (``*.capture.csv``), each cut to its head and first
    ``max_rows`` data rows, copied into ``folder``; {name: path}. Empty when the data are absent."""
    import glob

    shared = shared or os.environ.get("STATION_SHARED") or os.path.join(os.path.dirname(__file__), "..", "..", "shared")
    out = {}
    for src in sorted(glob.glob(os.path.join(shared, "data", "*", "*.capture.csv"))):
        name = "real-" + os.path.basename(src).removesuffix(".capture.csv")
        with open(src, encoding="utf-8") as f:
            kept, data = [], 0
            for line in f:
                kept.append(line)
                if line.strip() and not line.startswith("#"):
                    data += 1
                    if data > max_rows:
                        break
        path = os.path.join(folder, f"{name}.csv")
        with open(path, "w", encoding="utf-8", newline="") as f:
            f.write("".join(kept))
        out[name] = path
    return out


def _lines_and_header(text: str) -> tuple[list[str], int]:
    """The text's lines and the index of its header row; ValueError (this mutation does not
    apply) when there is no header with a line after it."""
    lines = _lines(text)
    h = _data_start(lines) - 1
    if not 0 <= h < len(lines) - 1:
        raise ValueError
    return lines, h


def m_header_again(text, rng):
    """The header row repeated among the data (two captures pasted into one)."""
    lines, h = _lines_and_header(text)
    i = rng.randrange(h + 1, len(lines))
    lines.insert(i, lines[h])
    return "\n".join(lines)


def m_meta_twice(text, rng):
    """A metadata key written twice with different values (an edit that added, not replaced)."""
    lines = _lines(text)
    metas = [i for i, line in enumerate(lines) if line.startswith("# ") and ":" in line and i > 0]
    if not metas:
        raise ValueError
    i = rng.choice(metas)
    key, _, value = lines[i][2:].partition(":")
    other = rng.choice(["0", "1e308", "compass", "X", value.strip() + "0", "", value.strip().upper()])
    spelled = rng.choice([key, key.upper(), key.title()])
    lines.insert(rng.randrange(1, _data_start(lines)), f"# {spelled}: {other}")
    return "\n".join(lines)


def m_time(text, rng):
    """The time column duplicated, run backwards, frozen or jumped (a logger's clock)."""
    lines, h = _lines_and_header(text)
    if "t" not in lines[h].split(","):
        raise ValueError
    j = lines[h].split(",").index("t")
    rows = [i for i in range(h + 1, len(lines)) if lines[i]]
    if len(rows) < 3:
        raise ValueError
    a = rng.randrange(len(rows) - 2)
    b = min(len(rows), a + rng.randint(2, 200))
    span = rows[a:b]
    ts = [lines[i].split(",")[j] for i in span]
    op = rng.choice(["dup", "backwards", "frozen", "jump", "negative"])
    if op == "dup":
        new = [ts[0]] * len(ts)
    elif op == "backwards":
        new = ts[::-1]
    elif op == "frozen":
        new = [ts[0]] * len(ts)
    elif op == "jump":
        new = [rng.choice(["1e9", "1e15", "-1", "0"])] + ts[1:]
    else:
        new = ["-" + t.lstrip("-") for t in ts]
    for i, t in zip(span, new):
        cells = lines[i].split(",")
        if len(cells) > j:
            cells[j] = t
            lines[i] = ",".join(cells)
    return "\n".join(lines)


def m_nul_run(text, rng):
    """A run of NUL bytes where a copy stopped (a file system's hole), maybe with the rest after."""
    b = text.encode("utf-8", "surrogatepass")
    i = rng.randrange(len(b))
    return b[:i] + b"\0" * rng.choice([1, 512, 4096, 65536]) + (b[i:] if rng.random() < 0.5 else b"")


def m_huge_line(text, rng):
    """One line of 10 MB: a field that never ends, or a file of one line."""
    lines = _lines(text)
    i = rng.randrange(len(lines))
    filler = rng.choice(["9", "1,", " ", "a"]) * (10 * 1024 * 1024 // 2)
    lines[i] = lines[i] + filler[: 10 * 1024 * 1024]
    return "\n".join(lines)


def m_truncate_mid_line(text, rng):
    """Cut inside a data line (a copy stopped part-way): the last line without its end."""
    lines, h = _lines_and_header(text)
    i = rng.randrange(h + 1, len(lines))
    if not lines[i]:
        raise ValueError
    return "\n".join(lines[:i] + [lines[i][: rng.randrange(1, len(lines[i]) + 1)]])


def m_encoding(text, rng):
    """The file as Excel saves it elsewhere: Windows-1252 (with a line only it can say), UTF-16
    with or without its mark, a UTF-8 mark, or Latin-1 bytes no Windows-1252 has."""
    lines = _lines(text)
    lines.insert(1, "# operator: Jürgen Weiß, 23 °C ±0.5")
    t = "\n".join(lines)
    op = rng.choice(["cp1252", "utf-16", "utf-16-le", "utf-16-be", "bom", "bad"])
    if op == "bom":
        return b"\xef\xbb\xbf" + t.encode("cp1252")
    if op == "bad":
        return t.encode("cp1252").replace(b"\xfc", b"\x81")
    return t.encode(op)


MUTATORS_HOSTILE = MUTATORS + [
    m_header_again,
    m_meta_twice,
    m_time,
    m_time,
    m_nul_run,
    m_huge_line,
    m_truncate_mid_line,
    m_encoding,
    m_encoding,
]


def mutate_hostile(text: str, rng: random.Random) -> tuple[str, bytes]:
    """:func:`mutate` with :data:`MUTATORS_HOSTILE`: one to three mutations (a mutation that made
    bytes no UTF-8 text reads is the last: the next would see only its replacement characters)."""
    return _mutate_with(text, rng, MUTATORS_HOSTILE, [1, 1, 2, 3], bytes_end=True)


def special_inputs(folder: str) -> dict[str, str]:
    """Paths that are no capture file: an empty file, a folder, a named pipe (nothing ever
    writes to it: a reader that opens it waits for ever), /dev/zero (never ends), a file of
    one 10 MB line, a 64 MiB hole of zeros (sparse)."""
    out = {}
    empty = os.path.join(folder, "empty.csv")
    open(empty, "wb").close()
    out["empty file"] = empty
    d = os.path.join(folder, "a-folder.csv")
    os.makedirs(d, exist_ok=True)
    out["directory"] = d
    fifo = os.path.join(folder, "pipe.csv")
    if not os.path.exists(fifo) and hasattr(os, "mkfifo"):
        os.mkfifo(fifo)
    if os.path.exists(fifo):
        out["fifo"] = fifo
    if os.path.exists("/dev/zero"):
        out["/dev/zero"] = "/dev/zero"
    one = os.path.join(folder, "one-line.csv")
    with open(one, "wb") as f:
        f.write(b"# station-capture: 1" + b"," * (10 * 1024 * 1024))
    out["10 MB first line"] = one
    hole = os.path.join(folder, "hole.csv")
    with open(hole, "wb") as f:
        f.truncate(64 * 1024 * 1024)
    out["64 MiB of zeros"] = hole
    return out


def _procedure_of(data: bytes) -> str | None:
    for line in data[:4096].decode("utf-8", "replace").splitlines():
        if line.replace(" ", "").startswith("#procedure:"):
            return line.split(":", 1)[1].strip()
    return None


def _argv(command: str, path: str, work: str, procedure: str | None) -> list[str] | None:
    """The command line of one of :data:`HOSTILE_COMMANDS` on ``path``; None where it does not apply."""
    if command == "inspect":
        return ["inspect", path]
    if command == "calibrate":
        return ["calibrate", path, "--json"]
    if command == "diagnose":
        return ["diagnose", path, "--json"]
    if command == "calibrate-save":  # --override: a result that fails its checks is saved too
        return ["calibrate", path, "--json", "--save", "--override", "fuzz", "--db", os.path.join(work, "station.db")]
    if command == "import":  # read as a plain CSV: its '#' lines skipped, its header and rows read
        proc = procedure if procedure in IMPORT_PROCEDURES else "accel-tabletop"
        return [
            "import",
            path,
            "--format",
            "csv",
            "--procedure",
            proc,
            "--unit",
            "accel=m/s^2,gyro=rad/s,mag=uT",
            "--out",
            os.path.join(work, "out.capture.csv"),
        ]
    raise ValueError(command)


def _db_state(db: str) -> tuple[bytes | None, int]:
    """(the database file's bytes, its saved calibrations) or (None, 0) when there is none."""
    import sqlite3

    if not os.path.exists(db):
        return None, 0
    with open(db, "rb") as f:
        data = f.read()
    con = sqlite3.connect(f"file:{db}?mode=ro&immutable=1", uri=True)  # no -wal, -shm of its own
    try:
        n = con.execute("select count(*) from calibrations").fetchone()[0]
    except sqlite3.Error:
        n = 0
    finally:
        con.close()
    return data, n


def _leftovers(work: str) -> list[str]:
    return sorted(n for n in os.listdir(work) if n.endswith(".tmp") or n.endswith("-journal") or n.endswith("-wal"))


def check_writes(command: str, outcome: Outcome, work: str, before: tuple[bytes | None, int]) -> Outcome:
    """``outcome`` as it was, or ``half-written`` when what the command wrote (or left) breaks
    the rules: see the section's comment."""
    import sqlite3

    def bad(why: str) -> Outcome:
        return Outcome(
            "half-written", command, outcome.case, outcome.seconds, f"{why} ({outcome.kind}: {outcome.detail})"
        )

    left = _leftovers(work)
    if left:
        return bad(f"left beside its output: {', '.join(left)}")
    if command == "import":
        out = os.path.join(work, "out.capture.csv")
        if outcome.kind == "ok":
            from station.capture import read_capture
            from station.errors import InputError

            try:
                read_capture(out)
            except (InputError, OSError) as exc:
                return bad(f"--out written but not read back: {exc}")
        elif os.path.exists(out):
            return bad("--out written by a run that failed")
    if command == "calibrate-save":
        db = os.path.join(work, "station.db")
        after = _db_state(db)
        if outcome.kind != "ok" and after[0] != before[0]:
            return bad("the database changed in a run that failed")
        if outcome.kind == "ok":
            if after[1] != before[1] + 1:
                return bad(f"saved calibrations {before[1]} -> {after[1]} (one expected)")
            con = sqlite3.connect(f"file:{db}?mode=ro&immutable=1", uri=True)  # no -wal, -shm of its own
            try:
                check = con.execute("pragma integrity_check").fetchone()[0]
            finally:
                con.close()
            if check != "ok":
                return bad(f"integrity_check: {check}")
    return outcome


def run_hostile_campaign(
    folder: str,
    bases: dict[str, str],
    *,
    n_mutated: int,
    seed: int,
    timeout_s: float,
    commands=HOSTILE_COMMANDS,
    specials: bool = True,
    progress=None,
) -> list[Outcome]:
    """``n_mutated`` captures mutated by :data:`MUTATORS_HOSTILE` from ``bases`` (real and
    simulated), and with ``specials`` the :func:`special_inputs`, each through every one of
    ``commands``, what it writes checked (:func:`check_writes`)."""
    rng = random.Random(seed)
    texts = {name: open(p, encoding="utf-8").read() for name, p in bases.items()}
    names = sorted(bases)
    work = os.path.join(folder, "work")
    os.makedirs(work, exist_ok=True)
    os.environ["STATION_DB"] = os.path.join(work, "default.db")  # a command without --db: not the operator's
    runner = Runner(timeout_s=timeout_s)
    cases: list[tuple[str, str, bytes | None]] = []
    if specials:
        cases += [(f"special {what}", p, None) for what, p in special_inputs(folder).items()]
    path = os.path.join(folder, "case.csv")

    def one(case: str, p: str, procedure: str | None) -> None:
        for command in commands:
            out = os.path.join(work, "out.capture.csv")
            if os.path.exists(out):
                os.unlink(out)
            before = _db_state(os.path.join(work, "station.db")) if command == "calibrate-save" else (None, 0)
            outcome = runner.run(command, p, case, argv=_argv(command, p, work, procedure))
            checked = check_writes(command, outcome, work, before)
            if checked is not outcome:
                runner.outcomes[-1] = checked

    try:
        for case, p, _ in cases:
            one(case, p, None)
        for k in range(n_mutated):
            base = names[k % len(names)]
            what, data = mutate_hostile(texts[base], rng)
            with open(path, "wb") as f:
                f.write(data)
            one(f"hostile#{seed}.{k} {base}: {what}", path, _procedure_of(texts[base].encode()))
            if progress is not None:
                progress(k + 1, runner.outcomes)
    finally:
        runner.close()
    return runner.outcomes


# ------------------------------------------------------- the world's own files through `import`
#
# The files as their writers wrote them (../shared/data/*/original): the imucal session (pandas),
# the MPU-6050 logger's CSV under its preamble (`Fs,100`), a PX4 ULog; each mutated (text or
# bytes) and imported with the options its SOURCE.md gives, then the capture written, if any,
# calibrated and diagnosed (the whole files: cut short, the session holds too few positions).

WORLD_IMPORTS = {
    # name: (path under data/, import options, first bytes kept (None: first lines kept))
    "imucal-original": (
        "imucal_ferraris/original/example_ferraris_session.csv",
        [
            "--procedure",
            "accel-tabletop",
            "--map",
            "ax=acc_x,ay=acc_y,az=acc_z,gx=gyr_x,gy=gyr_y,gz=gyr_z",
            "--rate",
            "102.4",
            "--unit",
            "accel=m/s^2,gyro=deg/s",
        ],
        None,
    ),
    "mpu6050-original": (
        "mpu6050_unc/original/imu_static_test.csv",
        ["--procedure", "gyro-drift", "--unit", "accel=counts,gyro=counts"],
        None,
    ),
    "px4-ulog": ("px4_ulog/original/sample_log_small.ulg", ["--procedure", "accel-tabletop"], 1 << 24),
}


def world_import_bases(folder: str, shared: str | None = None, max_lines: int = 20_000) -> dict[str, tuple]:
    """{name: (path of the copy in ``folder``, import options, binary)} for :data:`WORLD_IMPORTS`
    present in ``shared``."""
    shared = shared or os.environ.get("STATION_SHARED") or os.path.join(os.path.dirname(__file__), "..", "..", "shared")
    out = {}
    for name, (rel, options, n_bytes) in WORLD_IMPORTS.items():
        src = os.path.join(shared, "data", rel)
        if not os.path.exists(src):
            continue
        with open(src, "rb") as f:
            data = f.read(n_bytes) if n_bytes else b"".join(line for _, line in zip(range(max_lines), f))
        path = os.path.join(folder, name + os.path.splitext(rel)[1])
        with open(path, "wb") as f:
            f.write(data)
        out[name] = (path, options, n_bytes is not None)
    return out


def mutate_bytes(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """A binary log's bytes changed as a corrupt copy changes them: flipped, inserted, deleted,
    zeroed, repeated, cut."""
    b = bytearray(data)
    op = rng.choice(["flip", "insert", "delete", "zeros", "repeat", "cut", "flip-head"])
    i = rng.randrange(len(b))
    n = rng.choice([1, 4, 64, 4096])
    if op == "flip":
        for _ in range(rng.randint(1, 16)):
            j = rng.randrange(len(b))
            b[j] = rng.randrange(256)
    elif op == "flip-head":  # the definitions and header, where a wrong byte counts most
        for _ in range(rng.randint(1, 4)):
            j = rng.randrange(min(len(b), 4096))
            b[j] = rng.randrange(256)
    elif op == "insert":
        b[i:i] = bytes(rng.randrange(256) for _ in range(n))
    elif op == "delete":
        del b[i : i + n]
    elif op == "zeros":
        b[i : i + n] = bytes(len(b[i : i + n]))
    elif op == "repeat":
        b[i:i] = b[i : i + n]
    else:
        del b[i:]
    return op, bytes(b)


def run_world_import_campaign(
    folder: str, bases: dict[str, tuple], *, n_mutated: int, seed: int, timeout_s: float, progress=None
) -> list[Outcome]:
    """``n_mutated`` of the world's files mutated, each imported (``--out`` checked as in
    :func:`check_writes`), and the capture it made, when it made one, calibrated and diagnosed."""
    rng = random.Random(seed)
    names = sorted(bases)
    work = os.path.join(folder, "work")
    os.makedirs(work, exist_ok=True)
    os.environ["STATION_DB"] = os.path.join(work, "default.db")
    runner = Runner(timeout_s=timeout_s)
    out = os.path.join(work, "out.capture.csv")
    try:
        for k in range(n_mutated):
            name = names[k % len(names)]
            path, options, binary = bases[name]
            with open(path, "rb") as f:
                data = f.read()
            if binary:
                what, data = mutate_bytes(data, rng)
            else:
                what, data = mutate_hostile(data.decode("utf-8"), rng)
            case_path = os.path.join(folder, "case" + os.path.splitext(path)[1])
            with open(case_path, "wb") as f:
                f.write(data)
            case = f"world#{seed}.{k} {name}: {what}"
            if os.path.exists(out):
                os.unlink(out)
            outcome = runner.run("import", case_path, case, argv=["import", case_path, *options, "--out", out])
            checked = check_writes("import", outcome, work, (None, 0))
            if checked is not outcome:
                runner.outcomes[-1] = checked
            if checked.kind == "ok":
                for command in ("calibrate", "diagnose"):
                    runner.run(command, out, case)
            if progress is not None:
                progress(k + 1, runner.outcomes)
    finally:
        runner.close()
    return runner.outcomes
