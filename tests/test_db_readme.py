"""The README's Database section stays true: its SQL runs and every database command is in it."""

from __future__ import annotations

import re
import sqlite3
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from db_testdata import accel_result, small_capture

from db import Store

README = Path(__file__).resolve().parents[1] / "README.md"


def _section() -> str:
    text = README.read_text(encoding="utf-8")
    start = text.index("\n## Database\n")
    end = text.find("\n## ", start + 5)
    return text[start:] if end < 0 else text[start:end]


def test_every_database_command_is_documented():
    from station.cli import build_parser

    section = _section()
    sub = build_parser()._subparsers._group_actions[0].choices
    for name in ("devices", "history", "drift", "due", "export", "recompute", "verify"):
        assert name in sub, f"command {name} is not registered"
        assert f"`station {name}" in section, f"station {name} is not in the README's Database section"
    for action in ("add", "list", "show"):
        assert f"station devices {action}" in section
    for fmt in ("json", "ardupilot", "px4", "c-header"):
        assert fmt in section


def test_readme_queries_run_and_answer(tmp_path):
    queries = re.findall(r"```sql\n(.*?)```", _section(), flags=re.S)
    assert len(queries) == 3
    path = str(tmp_path / "station.db")
    now = datetime.now(UTC)
    with Store(path) as s:
        s.add_device("SOON", interval_days=30)
        s.add_device("LATER", interval_days=365)
        meta, cols = small_capture()
        for device, ago in (("SOON", 20), ("LATER", 10)):
            for k in range(2):
                s.save_calibration(
                    accel_result(device=device, B=(0.1 * (k + 1), 0, 0)),
                    meta=meta,
                    columns=cols,
                    allow_duplicate=True,
                    time=now - timedelta(days=ago + 100 * (1 - k)),
                )
    raw = sqlite3.connect(path)
    in_use = raw.execute(queries[0]).fetchall()
    assert [(r[0], r[1]) for r in in_use] == [("LATER", "accel-tabletop"), ("SOON", "accel-tabletop")]
    assert all('"B":[0.2,' in r[4] for r in in_use)  # the newer one of each pair
    series = raw.execute(queries[1]).fetchall()
    assert [(r[0], r[2], r[3]) for r in series] == [
        ("LATER", 0.1, 0.01),
        ("LATER", 0.2, 0.01),
        ("SOON", 0.1, 0.01),
        ("SOON", 0.2, 0.01),
    ]
    due = raw.execute(queries[2]).fetchall()
    assert [r[0] for r in due] == ["SOON"]  # due in 10 days; LATER in 355
    raw.close()


@pytest.mark.parametrize("flag", ["--db", "STATION_DB", "XDG"])
def test_readme_names_the_locations(flag):
    section = _section()
    assert {"--db": "`--db PATH`", "STATION_DB": "`$STATION_DB`", "XDG": "XDG_DATA_HOME"}[flag] in section
