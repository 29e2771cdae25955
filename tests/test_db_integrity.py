"""Integrity on real files: concurrent writers, SIGKILL mid-save, tamper evidence."""

from __future__ import annotations

import multiprocessing
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from db_testdata import accel_result, small_capture

from db import Store

ROOT = Path(__file__).resolve().parents[1]
TESTS = Path(__file__).resolve().parent


def _writer(path: str, worker: int, n: int, shared: str) -> None:
    sys.path.insert(0, str(TESTS))
    from db_testdata import accel_result as res
    from db_testdata import small_capture as cap

    s = Store(path)
    for i in range(n):
        device = shared if i % 2 else f"W{worker}"
        meta, cols = cap(seed=worker * 1000 + i, device=device)
        s.save_calibration(res(device=device, tag=f"w{worker}-{i}"), meta=meta, columns=cols, allow_duplicate=True)
    s.close()


def test_two_processes_saving_at_once_lose_nothing(tmp_path):
    path = str(tmp_path / "fresh" / "station.db")  # both create and migrate it at once, too
    ctx = multiprocessing.get_context("spawn")
    procs = [ctx.Process(target=_writer, args=(path, w, 50, "SHARED")) for w in (1, 2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
        assert p.exitcode == 0
    with Store(path) as s:
        assert s.counts()["calibrations"] == 100 and s.counts()["captures"] == 100
        tags = sorted(c["extra"]["tag"] for d in ("W1", "W2", "SHARED") for c in s.history(d))
        assert tags == sorted(f"w{w}-{i}" for w in (1, 2) for i in range(50))
        assert len(s.history("SHARED")) == 50
        assert s.verify() == []  # the shared device's hash chain interleaves both writers intact
        assert s.integrity_check() == "ok"


KILL_SCRIPT = textwrap.dedent(
    """
    import sys, time
    sys.path.insert(0, {tests!r})
    from db import Store
    from db_testdata import accel_result, small_capture
    s = Store({path!r})
    i = 0
    while True:
        meta, cols = small_capture(seed=i, n=20000, device="K")
        print("start", i, time.monotonic(), flush=True)
        cid = s.save_calibration(accel_result(device="K", B=(i, 0, 0)), meta=meta, columns=cols, allow_duplicate=True)
        print("done", cid, i, time.monotonic(), flush=True)
        i += 1
    """
)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_kill_during_save_leaves_database_consistent(tmp_path, seed):
    path = str(tmp_path / "station.db")
    with Store(path) as s:  # some history from before
        meta, cols = small_capture(device="K")
        first = s.save_calibration(
            accel_result(device="K", B=(-1, 0, 0)), meta=meta, columns=cols, allow_duplicate=True
        )
    rng = np.random.default_rng(seed)
    proc = subprocess.Popen(
        [sys.executable, "-c", KILL_SCRIPT.format(tests=str(TESTS), path=path)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    committed, durations, started = [], [], None
    target = int(rng.integers(2, 5))
    while True:
        words = proc.stdout.readline().split()
        assert words, "writer died early"
        if words[0] == "start":
            started = float(words[2])
            if len(committed) == target:
                break
        else:
            committed.append((int(words[1]), int(words[2])))
            durations.append(float(words[3]) - started)
    # Kill somewhere inside this save: a random fraction of a typical save's duration.
    time.sleep(float(rng.uniform(0.1, 0.9)) * float(np.median(durations)))
    proc.send_signal(signal.SIGKILL)
    proc.wait(10)
    tail = proc.stdout.read().split("\n")
    proc.stdout.close()
    committed += [(int(w[1]), int(w[2])) for w in (line.split() for line in tail) if w and w[0] == "done"]

    raw = sqlite3.connect(path)
    assert raw.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    raw.close()
    with Store(path) as s:
        h = s.history("K")
        ids = [c["id"] for c in h]
        assert ids[0] == first
        for cid, i in committed:  # everything reported as saved is there, unchanged
            assert cid in ids
            assert s.calibration(cid)["params"]["B"][0] == i
        assert len(h) in (len(committed) + 1, len(committed) + 2)  # + the killed save only if it had committed
        assert s.counts()["captures"] == len(h)  # never a capture without its calibration
        assert s.verify() == []
        meta, cols = small_capture(device="K")  # and it still takes writes
        after = s.save_calibration(accel_result(device="K"), meta=meta, columns=cols, allow_duplicate=True)
        assert s.history("K")[-1]["id"] == after and s.verify() == []


# --- tamper evidence -------------------------------------------------------------------


@pytest.fixture
def filled(tmp_path):
    path = str(tmp_path / "station.db")
    with Store(path) as s:
        ids = []
        for k, date in enumerate(["2024-01-01", "2024-06-01", "2025-01-01", "2025-06-01"]):
            meta, cols = small_capture(seed=k, device="T", date=date)
            ids.append(
                s.save_calibration(accel_result(device="T", B=(k, 0, 0)), meta=meta, columns=cols, allow_duplicate=True)
            )
        meta, cols = small_capture(device="U")
        ids.append(s.save_calibration(accel_result(device="U"), meta=meta, columns=cols, allow_duplicate=True))
        assert s.verify() == []
    return path, ids


def _edit(path: str, sql: str, args=()) -> None:
    raw = sqlite3.connect(path)  # plain sqlite3, as someone editing the file would
    assert raw.execute(sql, args).rowcount == 1
    raw.commit()
    raw.close()


def test_verify_names_a_row_edited_with_sqlite3(filled):
    path, ids = filled
    _edit(path, "UPDATE calibrations SET params = replace(params, '\"B\":[1.0,', '\"B\":[1.5,') WHERE id = ?", [ids[1]])
    with Store(path) as s:
        assert s.calibration(ids[1])["params"]["B"][0] == 1.5
        problems = s.verify()
    assert [(p["kind"], p["calibration_id"]) for p in problems] == [("tampered", ids[1])]
    assert problems[0]["device_id"] == "T"


@pytest.mark.parametrize(
    "column,value",
    [
        ("accepted", 0),
        ("time", "2023-01-01T00:00:00Z"),
        ("residual_rms", 0.001),
        ("operator", "mallory"),
        ("software_version", "9.9"),
    ],
)
def test_verify_catches_any_field(filled, column, value):
    path, ids = filled
    _edit(path, f"UPDATE calibrations SET {column} = ? WHERE id = ?", [value, ids[2]])
    with Store(path) as s:
        assert [(p["kind"], p["calibration_id"]) for p in s.verify()] == [("tampered", ids[2])]


def test_verify_catches_rehashed_row_through_the_chain(filled):
    from db.integrity import record_hash

    path, ids = filled
    raw = sqlite3.connect(path)
    raw.row_factory = sqlite3.Row
    row = dict(raw.execute("SELECT * FROM calibrations WHERE id = ?", [ids[1]]).fetchone())
    assert '"B":[1.0,' in row["params"]
    row["params"] = row["params"].replace('"B":[1.0,', '"B":[7.0,')
    raw.execute("UPDATE calibrations SET params = ?, hash = ? WHERE id = ?", [row["params"], record_hash(row), ids[1]])
    raw.commit()
    raw.close()
    with Store(path) as s:
        assert [(p["kind"], p["calibration_id"]) for p in s.verify()] == [("chain broken", ids[2])]


def test_verify_catches_deleted_record(filled):
    path, ids = filled
    _edit(path, "DELETE FROM calibrations WHERE id = ?", [ids[1]])
    with Store(path) as s:
        problems = s.verify()
    # the chain names the record after the gap; the deleted record's capture is left behind
    assert [(p["kind"], p["calibration_id"]) for p in problems] == [
        ("chain broken", ids[2]),
        ("orphaned capture", None),
    ]


def test_verify_catches_changed_samples(filled):
    path, ids = filled
    with Store(path) as s:
        capture_id = s.calibration(ids[0])["capture_id"]
        meta, cols = s.load_capture(capture_id)
    import zlib

    cols["ax"][0] += 1e-9
    _edit(
        path,
        "UPDATE capture_columns SET data = ? WHERE capture_id = ? AND name = 'ax'",
        [zlib.compress(cols["ax"].tobytes()), capture_id],
    )
    with Store(path) as s:
        problems = s.verify()
    assert [(p["kind"], p["capture_id"], p["calibration_id"]) for p in problems] == [
        ("capture changed", capture_id, ids[0])
    ]


def test_verify_cli_exit_1_names_the_record(filled, capsys):
    from station.cli import main

    path, ids = filled
    assert main(["verify", "--db", path]) == 0
    assert "ok: 5 calibrations" in capsys.readouterr().out
    _edit(path, "UPDATE calibrations SET uncertainty = '{}' WHERE id = ?", [ids[3]])
    assert main(["verify", "--db", path]) == 1
    out = capsys.readouterr()
    assert f"tampered: calibration {ids[3]} (device T)" in out.out
    assert "1 problem" in out.err
