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
