#!/usr/bin/env python3
"""Bootstrap and run the calibration station with nothing but Python 3.11.

    python3 dev.py station [ARGS...]   run the station (no ARGS: the TUI on the simulated device)
    python3 dev.py test [PYTEST ARGS]  run the whole test suite
    python3 dev.py bench [NAME]        run the benchmarks in benchmarks/
    python3 dev.py lint [PATHS]        ruff check and ruff format --check (configured in pyproject.toml)
    python3 dev.py setup               make (or update) .venv and nothing else

The first call makes `.venv/` beside this file and installs the project into it
(editable, with its test extra). Later calls reuse it; it is reinstalled only when
`pyproject.toml` changes (a hash is kept in `.venv/.station-stamp`).
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import venv
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
STAMP = VENV / ".station-stamp"
# The editable install is path-based (pyproject.toml: package-dir = {"" = "."}), so
# `station` resolves to this tree from any working folder, even one that holds a folder
# named `station`. Part of the stamp: a change of install method reinstalls.
INSTALL_MODE = "path-based editable (package-dir)"


def _venv_python() -> Path:
    return VENV / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


def ensure_venv() -> Path:
    want = hashlib.sha256((ROOT / "pyproject.toml").read_bytes() + INSTALL_MODE.encode()).hexdigest()
    py = _venv_python()
    if py.exists() and STAMP.exists() and STAMP.read_text().strip() == want:
        return py
    if not py.exists():
        print("dev.py: creating .venv (first run only)", file=sys.stderr)
        venv.EnvBuilder(with_pip=True).create(VENV)
    print("dev.py: installing the station and its dependencies into .venv", file=sys.stderr)
    subprocess.run([str(py), "-m", "pip", "install", "-q", "--upgrade", "pip"], check=True)
    subprocess.run([str(py), "-m", "pip", "install", "-q", "-e", f"{ROOT}[test]"], check=True)
    STAMP.write_text(want)
    return py


COMMANDS = ("station", "test", "bench", "lint", "setup")


def main(argv: list[str]) -> int:
    if not argv or argv[0] in {"-h", "--help", "help"}:
        print(__doc__)
        return 0
    cmd, rest = argv[0], argv[1:]
    if cmd not in COMMANDS:  # said before the .venv is made: that takes about 45 s on a fresh clone
        print(f"dev.py: unknown command {cmd!r} ({', '.join(COMMANDS)})", file=sys.stderr)
        print(__doc__.split("\n\n")[1], file=sys.stderr)
        return 2
    py = ensure_venv()
    env = dict(os.environ)
    if cmd == "station":
        return subprocess.call([str(py), "-m", "station", *rest], env=env)
    if cmd == "test":
        # worksteal: a worker that runs out of tests takes the others' queued ones (with "load"
        # the last minute ran on one core while the other waited on a long test). Three workers
        # on two cores: the terminal, pseudo-terminal and TUI tests wait on the clock about half
        # their time (user+sys 264 s of 502 s wall), and a third worker uses the core they
        # leave; the whole suite 1218 s with two, 1066 s with three (2026-12-01, this machine)
        args = rest or ["-q", "-n", "3", "--dist", "worksteal"]
        # one BLAS thread per worker: workers on two cores, each with OpenBLAS's default
        # threads, spin for each other's cores (station/__init__.py sets the same for the station)
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            env.setdefault(var, "1")
        rc = subprocess.call([str(py), "-m", "pytest", *args], cwd=ROOT, env=env)
        return rc
    if cmd == "bench":
        names = rest or sorted(p.stem for p in (ROOT / "benchmarks").glob("bench_*.py"))
        rc = 0
        for name in names:
            path = ROOT / "benchmarks" / (name if name.endswith(".py") else f"{name}.py")
            print(f"== {path.name}", flush=True)
            rc |= subprocess.call([str(py), str(path)], cwd=ROOT, env=env)
        return rc
    if cmd == "lint":
        paths = rest or ["."]
        rc = subprocess.call([str(py), "-m", "ruff", "check", *paths], cwd=ROOT, env=env)
        rc |= subprocess.call([str(py), "-m", "ruff", "format", "--check", *paths], cwd=ROOT, env=env)
        return rc
    return 0  # setup: the .venv alone


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
