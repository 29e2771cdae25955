"""Helpers shared by test modules: a Simulation as a Capture, and the real CLI."""

from __future__ import annotations

import contextlib
import io
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from station.capture import Capture

ROOT = Path(__file__).resolve().parents[1]


def capture_of(sim, path=None) -> Capture:
    """A simulator result as the Capture a file would give."""
    return Capture(dict(sim.meta), {k: np.asarray(v) for k, v in sim.columns.items()}, path)


def run_station(*args, subprocess_run: bool = False) -> subprocess.CompletedProcess:
    """The real CLI: in a subprocess, or (faster, same code path: argparse, StationError →
    one line on stderr, exit 2) through ``station.cli.main`` in this process."""
    if subprocess_run:
        return subprocess.run(
            [sys.executable, "-m", "station", *map(str, args)], cwd=ROOT, capture_output=True, text=True, timeout=120
        )
    from station.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main([str(a) for a in args])
    return subprocess.CompletedProcess(list(args), rc, out.getvalue(), err.getvalue())


def popen_station(*args) -> subprocess.Popen:
    """``station ARGS`` started in a subprocess (stdout and stderr text pipes), not waited for.
    The child gets SIGHUP's default action even where the tests run under ``nohup`` (an ignored
    signal is inherited: `record` then rightly goes on after a hang-up, and the tests that hang
    it up waited for it in vain)."""
    hup = signal.getsignal(signal.SIGHUP)
    if hup is signal.SIG_IGN:
        signal.signal(signal.SIGHUP, signal.SIG_DFL)
    try:
        return subprocess.Popen(
            [sys.executable, "-m", "station", *map(str, args)],
            cwd=ROOT,
            text=True,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
    finally:
        if hup is signal.SIG_IGN:
            signal.signal(signal.SIGHUP, signal.SIG_IGN)


def wait_for_rows(partial: Path, size_bytes: int, timeout_s: float = 30.0) -> None:
    """Until the recording's ``partial`` file holds more than ``size_bytes`` (waiting on the rows
    the device sends, not a pace); fails after ``timeout_s``."""
    end = time.monotonic() + timeout_s
    while not (partial.exists() and partial.stat().st_size > size_bytes):
        assert time.monotonic() < end, f"{partial}: no rows after {timeout_s:g} s"
        time.sleep(0.05)


class SimDevice:
    """A running ``station sim-device``: ``port`` (the pty it printed), ``proc``; once the
    context has ended, ``returncode`` and ``stderr`` (its summary line)."""

    def __init__(self, proc: subprocess.Popen):
        self.proc = proc
        self.port = ""
        self.returncode: int | None = None
        self.stderr = ""


@contextlib.contextmanager
def sim_device(*args: str):
    """``station sim-device ARGS`` in a subprocess for the length of the context: its pty read
    from the first line of stdout (asserted to be one), then stopped with SIGINT and waited for
    (20 s); its exit status and stderr are left on the :class:`SimDevice` for the caller to check."""
    proc = popen_station("sim-device", *args)
    sim = SimDevice(proc)
    try:
        sim.port = proc.stdout.readline().strip()
        assert sim.port.startswith("/dev/pts/"), (sim.port, proc.stderr.read() if proc.poll() is not None else "")
        yield sim
    finally:
        proc.send_signal(signal.SIGINT)
        _, sim.stderr = proc.communicate(timeout=20)
        sim.returncode = proc.returncode


def run_main(capsys, *argv) -> tuple[int, str, str]:
    """``station ARGS`` through ``station.cli.main`` in this process, its output taken by
    pytest's ``capsys``: (exit status, stdout, stderr)."""
    from station.cli import main

    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def station_json(*args) -> dict:
    """``station ARGS`` through ``run_station`` that must succeed (exit 0, stderr shown if not):
    its stdout, one JSON object."""
    res = run_station(*args)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def assert_one_line_refusal(res: subprocess.CompletedProcess, *needles: str) -> None:
    """Bad input as the station must refuse it: exit 2, nothing on stdout, one line on stderr
    starting ``station: `` (not the catch-all for an unexpected error), naming each needle."""
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    assert res.stdout == ""
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("station: "), res.stderr
    assert "cannot process this input" not in res.stderr, res.stderr
    for n in needles:
        assert n in res.stderr, res.stderr


def _generator():
    """benchmarks/diag_generator.py, the independent generator of diagnosis captures."""
    if str(ROOT / "benchmarks") not in sys.path:
        sys.path.insert(0, str(ROOT / "benchmarks"))
    import diag_generator

    return diag_generator


def redteam():
    """benchmarks/redteam_captures.py, the captures of shapes the diagnose generator never writes."""
    if str(ROOT / "benchmarks") not in sys.path:
        sys.path.insert(0, str(ROOT / "benchmarks"))
    import redteam_captures

    return redteam_captures


def redteam_capture(tmp_path, procedure, opts, effect=None, seed=4242, fmt=None):
    """(path, truth) of the capture the red-team generator writes for ``procedure`` with the case
    options ``opts`` and ``effect`` hidden (its name goes to the generator only), in the format
    ``fmt`` (plain when None); ``t`` written at the coarse tick ``opts["t_res"]`` where given."""
    R = redteam()
    meta, cols, truth = R.PROCS[procedure][0](np.random.default_rng(seed), opts, effect)
    if "t" in cols:
        cols["t"] = R.coarse(cols["t"], opts.get("t_res", 0.0))
    path = tmp_path / f"{procedure}.{effect or 'null'}.{seed}.capture.csv"
    R.write(path, meta, cols, fmt or {}, np.random.default_rng(seed + 1))
    return path, truth


def redteam_case(tmp_path, procedure, case, effect=None, seed=4242) -> Path:
    """The path of the capture :func:`redteam_capture` writes for the red-team case named ``case``."""
    return redteam_capture(tmp_path, procedure, redteam().CASES[procedure][case], effect, seed)[0]


def diagnose_rendered(tmp_path, capsys, rendered, meta_drop=()) -> dict:
    """``station diagnose FILE --json`` through the real CLI on a capture the generator rendered
    (written as its CSV, without the metadata keys ``meta_drop``); exit 0 is asserted."""
    from station.cli import main

    meta = {k: v for k, v in rendered.meta.items() if k not in meta_drop}
    path = tmp_path / "capture.csv"
    _generator().write_csv(str(path), meta, rendered.columns)
    rc = main(["diagnose", str(path), "--json"])
    out = capsys.readouterr().out
    assert rc == 0
    return json.loads(out)


def diagnose_generated(tmp_path, capsys, procedure, hidden, seed, k_sigma=10.0):
    """(diagnosis, size, rendered capture) of the capture the generator draws from ``seed`` with
    ``hidden`` at ``k_sigma`` of its detection σ; the name goes to the generator only."""
    G = _generator()
    sc = G.scenario_for(procedure, np.random.default_rng(seed), hidden)
    assert sc is not None, f"no scenario of {procedure} from seed {seed} where {hidden} applies"
    size, _ = G.size_for(sc, hidden, k_sigma)
    rendered = G.RENDER[procedure](sc, hidden, size)
    return diagnose_rendered(tmp_path, capsys, rendered), size, rendered
