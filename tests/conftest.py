from __future__ import annotations

import os
from pathlib import Path

import pytest

import station  # noqa: F401  (one BLAS thread per process, set before any test module imports numpy)

ROOT = Path(__file__).resolve().parents[1]
# ../shared beside the clone; a git worktree elsewhere names it in $STATION_SHARED
SHARED = Path(os.environ.get("STATION_SHARED") or ROOT.parent / "shared")


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """`../shared/data`, or skip when this clone has no shared folder beside it."""
    path = SHARED / "data"
    if not path.is_dir():
        pytest.skip("../shared/data is not beside this clone")
    return path


@pytest.fixture
def db(tmp_path) -> str:
    """A database path in the test's own folder (not created: the command under test does that)."""
    return str(tmp_path / "station.db")
