"""Helpers shared by test modules: a Simulation as a Capture, and the real CLI."""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys
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


def assert_one_line_refusal(res: subprocess.CompletedProcess, *needles: str) -> None:
    """Bad input as the station must refuse it: exit 2, nothing on stdout, one line on stderr
    starting ``station: `` (not the catch-all for an unexpected error), naming each needle."""
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    assert res.stdout == ""
    assert res.stderr.count("\n") == 1 and res.stderr.startswith("station: "), res.stderr
    assert "cannot process this input" not in res.stderr, res.stderr
    for n in needles:
        assert n in res.stderr, res.stderr
