"""`python3 dev.py`: the bootstrap script a new user runs first."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_unknown_command_is_refused_before_the_venv_is_made(tmp_path):
    """`dev.py bogus` made .venv and installed everything (about 45 s on a fresh clone) before it
    said the command was unknown. A copy of dev.py and pyproject.toml in an empty folder: the
    refusal, the usage, exit status 2, and no .venv."""
    shutil.copy(ROOT / "dev.py", tmp_path / "dev.py")
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    proc = subprocess.run(
        [sys.executable, str(tmp_path / "dev.py"), "bogus"], capture_output=True, text=True, timeout=600
    )
    assert proc.returncode == 2, proc.stderr
    assert "dev.py: unknown command 'bogus'" in proc.stderr
    assert "python3 dev.py test" in proc.stderr  # the usage
    assert proc.stdout == ""
    assert not (tmp_path / ".venv").exists()
