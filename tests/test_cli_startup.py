"""The CLI starts without the numerics: building the parser loads no numpy, scipy or textual
(start-up time is what `station due` from cron and every command pays)."""

from __future__ import annotations

import subprocess
import sys


def test_parser_builds_without_heavy_imports():
    code = (
        "import sys\nfrom station.cli import build_parser\nbuild_parser()\n"
        "heavy = sorted(m for m in ('numpy', 'scipy', 'textual', 'sqlite_utils', 'pandas') if m in sys.modules)\n"
        "print(','.join(heavy))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_every_command_is_documented_in_help():
    out = subprocess.run([sys.executable, "-m", "station", "--help"], capture_output=True, text=True, check=True)
    for name in ("calibrate", "simulate", "inspect", "walkthrough"):
        assert name in out.stdout


def test_every_command_is_in_the_readme():
    """A command nobody can find is a command nobody uses: each one is named in README.md."""
    from pathlib import Path

    from station.cli import build_parser

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    sub = build_parser()._subparsers._group_actions[0]
    missing = [name for name in sub.choices if f"`station {name}" not in readme and f"`{name}`" not in readme]
    assert missing == []


def test_walkthrough_names_no_file_it_did_not_keep(tmp_path):
    """`station walkthrough` said "5275 rows → compass.capture.csv": a file written in a
    temporary folder and removed, which the operator then looked for in vain. Every file its
    output names exists; it says how to keep one."""
    import os
    import re
    import subprocess
    import sys

    from tests.station_run import ROOT

    res = subprocess.run(
        [sys.executable, "-m", "station", "walkthrough", "--procedure", "accel-centrifuge", "--db", tmp_path / "s.db"],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    named = re.findall(r"[\w.-]+\.csv\b", res.stdout)
    assert all((tmp_path / n).exists() for n in named), (named, res.stdout.splitlines()[0])
    assert "station simulate" in res.stdout.splitlines()[0]
