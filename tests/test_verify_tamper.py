"""`station verify` sees every change made to the record with ordinary tools (issue 16):
the newest calibration deleted (or all of a device's), a device's tolerances, interval or
notes changed, a due date moved in `schedule`, a capture left without its calibration, a
damaged schema. Each tamper is made with the `sqlite3` module on the real file, then the
real CLI is run: exit 1 and the problem named, never a traceback or a KeyError."""

from __future__ import annotations

import json
import os
import sqlite3
from datetime import UTC, datetime, timedelta

import pytest
from db_testdata import accel_result, compass_result, database_before, small_capture

from db import Store
from station.cli import main


def _cli(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def _edit(path, sql, args=()):
    raw = sqlite3.connect(path)
    raw.execute(sql, args)
    raw.commit()
    raw.close()


@pytest.fixture
def record(tmp_path):
    """A database as the station writes it: two devices, settings, four calibrations, a schedule."""
    path = str(tmp_path / "station.db")
    now = datetime.now(UTC)
    with Store(path) as s:
        s.add_device(
            "IMU-7", model="ADXL", interval_days=30, notes="bench 2", tolerances={"B": 0.05}, limits={"B": (-0.5, 0.5)}
        )
        for k, days in enumerate((400, 200, 40)):
            meta, cols = small_capture(seed=k, device="IMU-7")
            s.save_calibration(
                accel_result(device="IMU-7", B=(0.1 + 0.01 * k, -0.2, 0.3)),
                meta=meta,
                columns=cols,
                time=now - timedelta(days=days),
            )
        s.add_device("MAG-1", interval_days=365)
        meta, cols = small_capture(seed=9, procedure="compass", device="MAG-1")
        s.save_calibration(compass_result(device="MAG-1"), meta=meta, columns=cols, time=now - timedelta(days=10))
        ids = [h["id"] for h in s.history("IMU-7")]
    return path, ids


def _kinds(capsys, path):
    code, out, err = _cli(capsys, "verify", "--json", "--db", path)
    assert "Traceback" not in err and "KeyError" not in err
    return code, [(p["kind"], p.get("device_id")) for p in json.loads(out)]


def test_untouched_record_verifies(capsys, record):
    path, _ = record
    assert _kinds(capsys, path) == (0, [])
    code, out, _ = _cli(capsys, "verify", "--db", path)
    assert code == 0 and out.startswith("ok: 4 calibrations")


def test_deleting_the_newest_calibration_is_seen(capsys, record):
    path, ids = record
    _edit(path, "DELETE FROM schedule WHERE device_id = 'IMU-7'")  # and what derives from it
    _edit(path, "DELETE FROM calibrations WHERE id = ?", [ids[-1]])
    code, kinds = _kinds(capsys, path)
    assert code == 1 and ("calibration removed", "IMU-7") in kinds
    code, out, err = _cli(capsys, "verify", "--db", path)
    assert code == 1 and f"calibration removed: calibration {ids[-1]} (device IMU-7)" in out


def test_deleting_all_of_a_devices_calibrations_is_seen(capsys, record):
    path, _ = record
    _edit(path, "DELETE FROM schedule WHERE device_id = 'IMU-7'")
    _edit(path, "DELETE FROM calibrations WHERE device_id = 'IMU-7'")
    code, kinds = _kinds(capsys, path)
    assert code == 1 and ("calibration removed", "IMU-7") in kinds


def test_deleting_the_newest_calibration_and_its_anchor_is_seen(capsys, record):
    path, ids = record
    _edit(path, "DELETE FROM calibrations WHERE id = ?", [ids[-1]])
    _edit(path, "DELETE FROM anchors WHERE id = (SELECT max(id) FROM anchors WHERE device_id = 'IMU-7')")
    code, kinds = _kinds(capsys, path)
    assert code == 1 and kinds  # the anchor chain (and the id counters) remember


@pytest.mark.parametrize(
    "sql",
    [
        "UPDATE devices SET tolerances = '{\"B\": 5.0}' WHERE id = 'IMU-7'",
        "UPDATE devices SET interval_days = 3650 WHERE id = 'IMU-7'",
        "UPDATE devices SET notes = 'all fine' WHERE id = 'IMU-7'",
        "UPDATE devices SET model = 'other' WHERE id = 'IMU-7'",
        # the limits set through `station devices add --limit B=-0.5:0.5`, widened behind its back
        "UPDATE devices SET limits = '{\"B\": [-5.0, 5.0]}' WHERE id = 'IMU-7'",
        "UPDATE devices SET limits = '{}' WHERE id = 'IMU-7'",
    ],
    ids=["tolerances", "interval", "notes", "model", "limits widened", "limits removed"],
)
def test_changing_device_settings_is_seen(capsys, record, sql):
    path, _ = record
    _edit(path, sql)
    code, kinds = _kinds(capsys, path)
    assert code == 1 and ("settings changed", "IMU-7") in kinds


def test_settings_changed_through_the_station_verify(capsys, record):
    path, _ = record
    assert _cli(capsys, "devices", "add", "IMU-7", "--interval-days", "90", "--notes", "moved", "--db", path)[0] == 0
    assert _kinds(capsys, path) == (0, [])
    assert _cli(capsys, "devices", "add", "IMU-7", "--limit", "B=-0.2:0.2", "--db", path)[0] == 0
    assert _kinds(capsys, path) == (0, [])
    _edit(path, "UPDATE devices SET limits = '{\"B\": [-0.2, 2.0]}' WHERE id = 'IMU-7'")
    code, out, _ = _cli(capsys, "verify", "--db", path)
    assert code == 1 and "settings changed" in out and "IMU-7" in out and "limits" in out


def test_limits_of_a_database_from_before_0004_are_anchored_when_it_is_opened(capsys, tmp_path):
    """A database whose anchors predate the limits' hashing (migrations 0001-0003 only, limits
    set then): it verifies as it is, opening it anchors the limits as found, and an edit of
    them afterwards is seen."""
    from db.integrity import settings_hash

    path = str(tmp_path / "old.db")
    conn = database_before(path, 3)
    created = "2024-01-01T00:00:00Z"
    conn.execute("INSERT INTO devices (id, created, limits) VALUES ('OLD-2', ?, ?)", [created, '{"B": [-0.5, 0.5]}'])
    dev = dict(zip(("id", "created"), ("OLD-2", created)))
    dev.update({"model": None, "sensor_kinds": "[]", "notes": None, "interval_days": None, "tolerances": "{}"})
    row = {
        "time": created,
        "device_id": "OLD-2",
        "event": "settings",
        "head_id": None,
        "head_hash": None,
        "n_calibrations": 0,
        "settings_hash": settings_hash(dev, 1),  # as the station wrote it before 0004
        "capture_id": None,
        "prev_hash": None,
    }
    from db.integrity import anchor_hash

    cur = conn.execute(
        f"INSERT INTO anchors ({', '.join(row)}, hash) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, '')", list(row.values())
    )
    row["id"] = cur.lastrowid
    conn.execute("UPDATE anchors SET hash = ? WHERE id = ?", [anchor_hash(row), row["id"]])
    conn.commit()
    conn.close()
    assert _kinds(capsys, path) == (0, [])  # opened by the new code: migrated, old anchor intact
    raw = sqlite3.connect(path)
    hashes = [r[0] for r in raw.execute("SELECT settings_hash FROM anchors WHERE device_id = 'OLD-2' ORDER BY id")]
    raw.close()
    assert len(hashes) == 2 and ":" not in hashes[0] and hashes[1].startswith("2:")
    _edit(path, "UPDATE devices SET limits = '{\"B\": [-9.0, 9.0]}' WHERE id = 'OLD-2'")
    assert _kinds(capsys, path) == (1, [("settings changed", "OLD-2")])


def test_moving_a_due_date_in_the_schedule_is_seen(capsys, record):
    path, _ = record
    code, out, _ = _cli(capsys, "due", "--db", path)
    assert code == 1 and out.startswith("IMU-7: overdue by")
    _edit(
        path,
        "UPDATE schedule SET due = '2999-01-01T00:00:00Z', interval_due = '2999-01-01T00:00:00Z' "
        "WHERE device_id = 'IMU-7'",
    )
    assert _cli(capsys, "due", "--db", path)[:2] == (0, "nothing due\n")  # the tamper works on `due` ...
    code, kinds = _kinds(capsys, path)
    assert code == 1 and kinds == [("schedule changed", "IMU-7")]  # ... and verify names it
    code, out, _ = _cli(capsys, "verify", "--db", path)
    assert "stored due 2999-01-01T00:00:00Z" in out


def test_deleting_a_schedule_row_is_seen(capsys, record):
    path, _ = record
    _edit(path, "DELETE FROM schedule WHERE device_id = 'MAG-1'")
    assert _kinds(capsys, path) == (1, [("schedule changed", "MAG-1")])


def test_a_capture_left_without_its_calibration_is_seen(capsys, record):
    path, ids = record
    with Store(path) as s:
        capture_id = s.calibration(ids[1])["capture_id"]
    _edit(path, "DELETE FROM calibrations WHERE id = ?", [ids[1]])
    code, out, _ = _cli(capsys, "verify", "--json", "--db", path)
    problems = json.loads(out)
    assert code == 1
    assert ("orphaned capture", capture_id) in [(p["kind"], p.get("capture_id")) for p in problems]
    assert ("chain broken", ids[2]) in [(p["kind"], p.get("calibration_id")) for p in problems]


def test_a_stored_capture_on_its_own_is_not_an_orphan(capsys, record):
    path, _ = record
    meta, cols = small_capture(device="LONE")
    with Store(path) as s:
        s.save_capture(device_id="LONE", procedure="accel-tabletop", meta=meta, columns=cols)
    assert _kinds(capsys, path) == (0, [])


@pytest.mark.parametrize(
    "sql,detail",
    [
        ("ALTER TABLE calibrations DROP COLUMN hash", "lacks column hash"),
        ("DROP TABLE anchors", "'anchors' is missing"),
        ("ALTER TABLE devices DROP COLUMN notes", "lacks column notes"),
    ],
)
def test_a_damaged_schema_is_reported_not_a_crash(capsys, record, sql, detail):
    path, _ = record
    raw = sqlite3.connect(path)
    raw.execute("DROP VIEW IF EXISTS calibration_params")  # SQLite refuses to drop a column a view uses
    raw.execute(sql)
    raw.commit()
    raw.close()
    code, out, err = _cli(capsys, "verify", "--db", path)
    assert code == 1, err
    assert "schema damaged" in out and detail in out
    assert "KeyError" not in err and "cannot process" not in err


def test_verify_on_a_missing_database_is_one_line_exit_2(capsys, tmp_path):
    code, out, err = _cli(capsys, "verify", "--db", tmp_path / "typo" / "station.db")
    assert code == 2 and out == "" and err.count("\n") == 1 and "no station database" in err
    assert not (tmp_path / "typo").exists()


@pytest.mark.parametrize(
    "args",
    [
        ("due",),
        ("devices", "list"),
        ("history", "X"),
        ("drift", "X"),
        ("recompute", "1"),
        ("export", "1", "--format", "json"),
        ("export-capture", "1"),
        ("devices", "show", "X"),
    ],
)
def test_reading_commands_refuse_a_missing_database_and_create_nothing(capsys, tmp_path, args):
    db = tmp_path / "no" / "such" / "station.db"
    code, out, err = _cli(capsys, *args, "--db", db)
    assert code == 2 and out == "" and err.count("\n") == 1 and "no station database" in err
    assert not (tmp_path / "no").exists()


def test_devices_add_creates_the_database_explicitly(capsys, tmp_path):
    db = tmp_path / "new" / "station.db"
    # a --db in a folder that does not exist is refused (a mistyped path made that folder)
    code, _, err = _cli(capsys, "devices", "add", "IMU-1", "--db", db)
    assert code == 2 and "the folder" in err and not (tmp_path / "new").exists()
    (tmp_path / "new").mkdir()
    assert _cli(capsys, "devices", "add", "IMU-1", "--db", db)[0] == 0
    assert db.exists()
    assert _cli(capsys, "due", "--db", db)[0] == 1  # a device never calibrated is due


def test_an_export_carries_the_anchor_that_exposes_a_rolled_back_file(capsys, tmp_path):
    """A whole file put back from an older copy is self-consistent; the anchor printed in a
    later export is what tells: `verify --anchor` says it is gone."""
    import shutil

    path = str(tmp_path / "station.db")
    with Store(path) as s:
        meta, cols = small_capture(seed=1, device="IMU-9")
        s.save_calibration(accel_result(device="IMU-9"), meta=meta, columns=cols)
    shutil.copyfile(path, tmp_path / "old.db")
    with Store(path) as s:
        meta, cols = small_capture(seed=2, device="IMU-9")
        second = s.save_calibration(accel_result(device="IMU-9", B=(0.2, -0.2, 0.3)), meta=meta, columns=cols)
    code, out, _ = _cli(capsys, "export", second, "--format", "json", "--db", path)
    anchor = json.loads(out)["anchor"]
    code, out, err = _cli(capsys, "export", second, "--format", "c-header", "--db", path)
    assert code == 0, err
    assert f"station anchor {anchor}" in out  # in the header comment of every text format
    assert _cli(capsys, "verify", "--anchor", anchor, "--db", path)[0] == 0
    for suffix in ("", "-wal", "-shm"):
        if os.path.exists(path + suffix):
            os.unlink(path + suffix)
    shutil.copyfile(tmp_path / "old.db", path)  # the file rolled back: consistent in itself
    assert _cli(capsys, "verify", "--db", path)[0] == 0
    code, out, _ = _cli(capsys, "verify", "--anchor", anchor, "--db", path)
    assert code == 1 and f"anchor missing: database: anchor {anchor}" in out


def test_an_anchor_that_is_no_hash_is_refused_and_a_pasted_one_still_verifies(capsys, tmp_path):
    """verify --anchor '' (an unset variable) or a typo said 'anchor missing ... removed or
    rewritten' with exit 1, the tamper alarm, on an intact record; so did the right hash pasted
    with a trailing newline or in capitals. No sha256 is refused as a usage error (exit 2);
    spaces around it and letter case do not matter."""
    path = str(tmp_path / "station.db")
    with Store(path) as s:
        meta, cols = small_capture(seed=1, device="IMU-9")
        cid = s.save_calibration(accel_result(device="IMU-9"), meta=meta, columns=cols)
    anchor = json.loads(_cli(capsys, "export", cid, "--format", "json", "--db", path)[1])["anchor"]
    for typed in (f"{anchor}\n", f" {anchor.upper()} "):
        code, out, err = _cli(capsys, "verify", "--anchor", typed, "--db", path)
        assert code == 0 and out.startswith("ok: "), (out, err)
    for typed in ("", "zz", anchor[:-1], anchor + "0", "g" * 64):
        code, out, err = _cli(capsys, "verify", "--anchor", typed, "--db", path)
        assert code == 2 and out == "" and err.count("\n") == 1 and "not an anchor hash" in err, (typed, out, err)
