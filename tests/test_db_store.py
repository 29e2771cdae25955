"""db.store on real SQLite files: schema, devices, lossless captures, calibrations, history."""

from __future__ import annotations

import json
import os
import sqlite3

import numpy as np
import pytest
from db_testdata import accel_result, compass_result, ldv_result, small_capture
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from db import NotFound, Store, default_db_path
from db.schema import MIGRATION_NAMES


@pytest.fixture
def store(tmp_path):
    s = Store(str(tmp_path / "sub" / "station.db"))
    yield s
    s.close()


# --- opening, schema, migrations -------------------------------------------------------


def test_open_creates_parent_folder_wal_foreign_keys_and_migrations(tmp_path):
    path = tmp_path / "a" / "b" / "station.db"
    with Store(str(path)) as s:
        assert path.exists()
        assert s.conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert s.conn.execute("PRAGMA foreign_keys").fetchone()[0] == 1
        assert s.conn.execute("PRAGMA busy_timeout").fetchone()[0] >= 10000
    raw = sqlite3.connect(path)
    applied = [
        r[0] for r in raw.execute("SELECT name FROM _sqlite_migrations WHERE migration_set='station' ORDER BY id")
    ]
    assert applied == MIGRATION_NAMES
    names = {r[0] for r in raw.execute("SELECT name FROM sqlite_master WHERE type IN ('table','view')")}
    assert {"devices", "captures", "capture_columns", "calibrations", "schedule", "calibration_params"} <= names
    raw.close()


def test_reopening_applies_nothing_twice(tmp_path):
    path = str(tmp_path / "s.db")
    Store(path).close()
    Store(path).close()
    raw = sqlite3.connect(path)
    assert raw.execute("SELECT count(*) FROM _sqlite_migrations").fetchone()[0] == len(MIGRATION_NAMES)
    raw.close()


def test_sqlite_utils_sees_the_migrations(tmp_path):
    from db.migrations import STATION_MIGRATIONS

    with Store(str(tmp_path / "s.db")) as s:
        assert STATION_MIGRATIONS.pending(s.database) == []
        assert [m.name for m in STATION_MIGRATIONS.applied(s.database)] == MIGRATION_NAMES


def test_a_new_migration_is_applied_once_to_an_existing_database(tmp_path, monkeypatch):
    import db.migrations as dm
    import db.schema as ds
    import db.store as dst

    path = str(tmp_path / "s.db")
    with Store(path) as s:
        meta, cols = small_capture()
        cid = s.save_calibration(accel_result(), meta=meta, columns=cols)
    extra = ("9999_test_add_column", ["ALTER TABLE devices ADD COLUMN location TEXT"])
    monkeypatch.setattr(dm, "MIGRATIONS", ds.MIGRATIONS + [extra])
    monkeypatch.setattr(dst, "MIGRATION_NAMES", ds.MIGRATION_NAMES + [extra[0]])
    monkeypatch.setattr(dm, "STATION_MIGRATIONS", dm._build())
    for _ in range(2):
        with Store(path) as s:
            assert "location" in {r[1] for r in s.conn.execute("PRAGMA table_info(devices)")}
            assert s.calibration(cid)["params"]["B"] == [0.1, -0.2, 0.3] and s.verify() == []
    raw = sqlite3.connect(path)
    names = [r[0] for r in raw.execute("SELECT name FROM _sqlite_migrations ORDER BY id")]
    raw.close()
    assert names == MIGRATION_NAMES + ["9999_test_add_column"]


def _other_process(path: str, code: str) -> str:
    """Run ``code`` with ``s = Store(path)`` in a separate Python process; its stdout."""
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    script = f"from db import Store\ns = Store({path!r})\n{code}\ns.close()\n"
    out = subprocess.run([sys.executable, "-c", script], cwd=root, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_a_second_store_in_the_process_keeps_the_first_ones_locks(tmp_path):
    """The TUI holds one Store and opens another to save or read, then closes it. Reading the
    file's header for the second one closed a descriptor of the database, which drops every
    POSIX lock of the process (SQLite's too): the next command in another process then took
    itself for the last connection and deleted the -wal and -shm under the TUI, whose later
    writes went nowhere another process could see, and whose reads came back from the wrong
    pages (a device read as a migration row: 'not valid JSON')."""
    path = str(tmp_path / "station.db")
    with Store(path) as tui:
        tui.add_device("FIRST")
        Store(path).close()  # a save or a screen's read, in the same process
        assert "FIRST" in _other_process(path, "print([d['id'] for d in s.list_devices()])")
        assert sorted(os.listdir(tmp_path)) == ["station.db", "station.db-shm", "station.db-wal"]
        tui.add_device("SECOND", model="written after")
        assert _other_process(path, "print(s.get_device('SECOND')['model'])").strip() == "written after"
        _other_process(path, "s.add_device('THIRD', model='from elsewhere')")
        assert tui.get_device("THIRD")["model"] == "from elsewhere"
        assert [d["id"] for d in tui.list_devices()] == ["FIRST", "SECOND", "THIRD"]


def test_default_path_follows_station_db_then_xdg(monkeypatch, tmp_path):
    monkeypatch.delenv("STATION_DB", raising=False)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert default_db_path() == str(tmp_path / "xdg" / "station" / "station.db")
    monkeypatch.delenv("XDG_DATA_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert default_db_path() == str(tmp_path / "home" / ".local" / "share" / "station" / "station.db")
    monkeypatch.setenv("STATION_DB", str(tmp_path / "x.db"))
    assert default_db_path() == str(tmp_path / "x.db")


def test_foreign_keys_refuse_orphans(store):
    with pytest.raises(sqlite3.IntegrityError):
        with store._write() as conn:
            conn.execute(
                "INSERT INTO schedule (device_id, procedure, last_calibration_id, last_calibrated) VALUES ('ghost','x',1,'t')"
            )


# --- devices ---------------------------------------------------------------------------


def test_add_get_update_device(store):
    d = store.add_device(
        "IMU-7",
        model="ADXL355",
        sensor_kinds=["accel"],
        notes="bench 2",
        interval_days=180,
        tolerances={"B": 0.05, "M[0][0]": 1e-3},
    )
    assert d["id"] == "IMU-7" and d["model"] == "ADXL355" and d["interval_days"] == 180.0
    assert d["tolerances"] == {"B": 0.05, "M[0][0]": 1e-3}
    d = store.add_device("IMU-7", notes="moved to bench 3", tolerances={"M[0][0]": None, "B[2]": 0.01})
    assert d["model"] == "ADXL355" and d["notes"] == "moved to bench 3"
    assert d["tolerances"] == {"B": 0.05, "B[2]": 0.01}
    assert store.get_device("nope") is None
    assert [x["id"] for x in store.list_devices()] == ["IMU-7"]


@pytest.mark.parametrize("bad", ["", "   ", None, 12])
def test_device_id_must_be_text(store, bad):
    with pytest.raises(ValueError):
        store.add_device(bad)


def test_bad_interval_and_tolerance_refused(store):
    with pytest.raises(ValueError):
        store.add_device("X", interval_days=0)
    with pytest.raises(ValueError):
        store.add_device("X", tolerances={"B": -1})
    assert store.get_device("X") is None


NASTY = [
    "IMU \"quoted\" 'single'",
    "x'); DROP TABLE devices; --",
    "Gerät-Ω-温度-🙂",
    "line one\nline two\r\nline three",
    "tab\there\x1b[31mred",
    " leading and trailing ",
    "%s %d {} {0} \\N \\ backslash",
]


@pytest.mark.parametrize("device_id", NASTY)
def test_nasty_ids_and_notes_round_trip_verbatim(store, device_id):
    notes = device_id + "\n-- notes; DELETE FROM calibrations;"
    store.add_device(device_id, notes=notes, model=device_id[::-1])
    d = store.get_device(device_id)
    assert d["id"] == device_id and d["notes"] == notes and d["model"] == device_id[::-1]
    meta, cols = small_capture(device=device_id)
    cid = store.save_calibration(accel_result(device=device_id), meta=meta, columns=cols)
    assert store.history(device_id)[0]["id"] == cid
    assert store.calibration(cid)["device_id"] == device_id
    assert {x["id"] for x in store.list_devices()} == {device_id}
    assert store.verify() == []


# --- captures --------------------------------------------------------------------------


def _bits(a: np.ndarray) -> np.ndarray:
    return a.view(np.uint64) if a.dtype == np.float64 else a


def test_capture_round_trip_bit_exact(store):
    meta, cols = small_capture(n=200, date="2026-03-04T05:06:07+02:00", latitude_deg="39.98", operator="ana")
    cols["ax"][3] = np.nan
    cols["ay"][4] = -0.0
    cols["az"][5] = np.inf
    cols["ax"][6] = 5e-324  # subnormal
    payload_nan = np.array([0x7FF8_0000_DEAD_BEEF], dtype=np.uint64).view(np.float64)[0]
    cols["ay"][7] = payload_nan
    cid = store.save_capture(device_id="IMU-1", procedure="accel-tabletop", meta=meta, columns=cols)
    meta2, cols2 = store.load_capture(cid)
    assert meta2 == meta and list(meta2) == list(meta)
    assert list(cols2) == list(cols)
    for name in cols:
        assert cols2[name].dtype == cols[name].dtype
        assert np.array_equal(_bits(cols2[name]), _bits(cols[name])), name
    assert cols2["position"].dtype == object and all(isinstance(v, str) for v in cols2["position"])
    info = store.capture_info(cid)
    assert info["time"] == "2026-03-04T03:06:07Z" and info["latitude_deg"] == 39.98 and info["operator"] == "ana"
    assert info["n_rows"] == 200 and info["stored_bytes"] > 0


def test_capture_columns_are_compressed(store):
    n = 30000
    t = np.arange(n) / 100.0
    cols = {"t": t, "ax": np.round(np.sin(t), 4), "az": np.full(n, 9.80665)}
    cid = store.save_capture(device_id="D", procedure="gyro-drift", meta={}, columns=cols)
    info = store.capture_info(cid)
    assert info["raw_bytes"] == 3 * n * 8
    assert info["stored_bytes"] < info["raw_bytes"] / 2


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    arr=hnp.arrays(np.float64, st.integers(0, 64), elements=st.floats(allow_nan=True, allow_infinity=True, width=64)),
    labels=st.lists(st.text(max_size=6), min_size=0, max_size=64),
)
def test_capture_round_trip_property(store, arr, labels):
    n = min(len(arr), len(labels))
    pos = np.empty(n, dtype=object)
    pos[:] = labels[:n]
    cols = {"x": arr[:n].copy(), "position": pos}
    cid = store.save_capture(device_id="H", procedure="compass", meta={"k": "v"}, columns=cols)
    _, back = store.load_capture(cid)
    assert np.array_equal(back["x"].view(np.uint64), cols["x"].view(np.uint64))
    assert back["position"].tolist() == labels[:n]


def test_capture_bad_columns_refused(store):
    with pytest.raises(ValueError, match="differ in length"):
        store.save_capture(device_id="D", procedure="x", meta={}, columns={"a": np.zeros(3), "b": np.zeros(4)})
    with pytest.raises(ValueError, match="1-D"):
        store.save_capture(device_id="D", procedure="x", meta={}, columns={"a": np.zeros((3, 2))})
    with pytest.raises(ValueError):
        store.save_capture(device_id="D", procedure="x", meta={}, columns={})
    assert store.counts()["captures"] == 0
    with pytest.raises(NotFound):
        store.load_capture(99)


# --- calibrations ----------------------------------------------------------------------


def test_save_calibration_stores_capture_result_and_device(store):
    meta, cols = small_capture(device="IMU-9", date="2026-11-21")
    r = accel_result(device="IMU-9")
    r["uncertainty"]["B"][1] = float("nan")
    cid = store.save_calibration(
        r, meta=meta, columns=cols, operator="bo", software_version="0.1.0", sensor_kind="accel"
    )
    cal = store.calibration(cid)
    # a date alone, saved on a later day: that day's last second (db.params.capture_time)
    assert cal["device_id"] == "IMU-9" and cal["time"] == "2026-11-21T23:59:59Z"
    assert cal["software_version"] == "0.1.0" and cal["operator"] == "bo" and cal["accepted"] is True
    expected = dict(r)
    expected["uncertainty"] = {"B": [0.01, None, 0.01], "M": r["uncertainty"]["M"]}  # NaN stored as null
    assert cal["result"] == expected
    m2, c2 = store.load_capture(cal["capture_id"])
    assert m2 == meta and np.array_equal(c2["az"], cols["az"])
    assert store.get_device("IMU-9")["sensor_kinds"] == ["accel"]


def test_device_resolution_order(store):
    meta, cols = small_capture(device="FROM-META")
    r = accel_result(device="FROM-RESULT")
    assert (
        store.calibration(
            store.save_calibration(r, meta=meta, columns=cols, allow_duplicate=True, device_id="FROM-ARG")
        )["device_id"]
        == "FROM-ARG"
    )
    assert (
        store.calibration(store.save_calibration(r, meta=meta, columns=cols, allow_duplicate=True))["device_id"]
        == "FROM-RESULT"
    )
    r.pop("device")
    assert (
        store.calibration(store.save_calibration(r, meta=meta, columns=cols, allow_duplicate=True))["device_id"]
        == "FROM-META"
    )
    meta.pop("device")
    with pytest.raises(ValueError, match="no device"):
        store.save_calibration(r, meta=meta, columns=cols, allow_duplicate=True)


def test_time_is_argument_then_capture_date_then_now(store):
    meta, cols = small_capture(date="2025-05-06T07:08:09Z")
    a = store.save_calibration(accel_result(), meta=meta, columns=cols, allow_duplicate=True, time="2020-01-02")
    b = store.save_calibration(accel_result(), meta=meta, columns=cols, allow_duplicate=True)
    meta.pop("date")
    c = store.save_calibration(accel_result(), meta=meta, columns=cols, allow_duplicate=True)
    assert store.calibration(a)["time"] == "2020-01-02T00:00:00Z"
    assert store.calibration(b)["time"] == "2025-05-06T07:08:09Z"
    now = store.calibration(c)["time"]
    assert now[:4] >= "2025" and now.endswith("Z") and len(now) == 20
    with pytest.raises(ValueError, match="ISO 8601"):
        store.save_calibration(accel_result(), meta={"device": "X", "date": "21/11/2026"}, columns=cols)


def test_failed_save_leaves_nothing(store):
    meta, cols = small_capture()
    bad = accel_result()
    bad["params"]["B"][0] = object()  # not storable
    with pytest.raises(ValueError):
        store.save_calibration(bad, meta=meta, columns=cols)
    assert store.counts() == {"devices": 0, "captures": 0, "calibrations": 0}


def test_history_oldest_first_supersedes_and_rejections(store):
    meta, cols = small_capture()
    ids = {}
    for date, accepted in [("2025-06-01", True), ("2024-01-01", True), ("2025-01-01", False), ("2026-01-01", True)]:
        ids[date] = store.save_calibration(accel_result(), meta=dict(meta, date=date), columns=cols, accepted=accepted)
    store.save_calibration(compass_result(device="IMU-1"), meta=dict(meta, date="2025-03-01"), columns=cols)
    h = store.history("IMU-1", procedure="accel-tabletop")
    assert [x["time"][:10] for x in h] == ["2024-01-01", "2025-01-01", "2025-06-01", "2026-01-01"]
    by = {x["time"][:10]: x for x in h}
    assert by["2024-01-01"]["supersedes"] is None
    assert by["2025-01-01"]["accepted"] is False and by["2025-01-01"]["supersedes"] is None  # rejected replaces nothing
    assert by["2025-06-01"]["supersedes"] is None  # saved first: nothing before it yet
    assert by["2026-01-01"]["supersedes"] == ids["2025-06-01"]
    assert by["2025-06-01"]["superseded_by"] == ids["2026-01-01"]
    for key in (
        "id",
        "time",
        "procedure",
        "params",
        "uncertainty",
        "residual_rms",
        "accepted",
        "capture_id",
        "supersedes",
        "software_version",
        "warnings",
    ):
        assert key in h[0]
    assert len(store.history("IMU-1")) == 5
    assert store.history("unknown") == []
    with pytest.raises(NotFound):
        store.calibration(12345)


def test_calibration_params_view_matches_flattened_params(store):
    meta, cols = small_capture()
    c1 = store.save_calibration(accel_result(B=(1.5, 2.5, 3.5)), meta=meta, columns=cols)
    c2 = store.save_calibration(ldv_result(device="LDV-1"), meta=dict(meta, procedure="ldv"), columns=cols)
    rows = {
        (r[0], r[1]): (r[2], r[3])
        for r in store.conn.execute("SELECT calibration_id, param, value, sigma FROM calibration_params")
    }
    assert rows[(c1, "B[1]")] == (2.5, 0.01)
    assert rows[(c1, "M[2][2]")] == (1.0, 0.001)
    assert rows[(c2, "beam2.alpha_deg")] == (60.1, 0.001)
    assert rows[(c2, "condition_number")] == (3.2, None)
    assert sum(1 for k in rows if k[0] == c1) == 12
    assert sum(1 for k in rows if k[0] == c2) == 16


def test_json_safe_storage_of_numpy_values(store):
    meta, cols = small_capture()
    r = accel_result()
    r["params"]["B"] = np.array([0.1, 0.2, 0.3])
    r["params"]["M"] = np.eye(3)
    r["n_positions"] = np.int64(9)
    r["residual_rms"] = np.float64(0.02)
    r["converged"] = np.bool_(True)
    cal = store.calibration(store.save_calibration(r, meta=meta, columns=cols))
    assert cal["params"]["B"] == [0.1, 0.2, 0.3] and cal["n_positions"] == 9 and cal["residual_rms"] == 0.02
    assert cal["result"]["converged"] is True
    raw = store.conn.execute("SELECT params FROM calibrations").fetchone()[0]
    assert json.loads(raw)["M"][1] == [0.0, 1.0, 0.0]


def test_store_survives_threads(tmp_path):
    import threading

    s = Store(str(tmp_path / "t.db"))
    meta, cols = small_capture()
    errors = []

    def work(k):
        try:
            for _ in range(10):
                s.save_calibration(accel_result(device=f"T{k}"), meta=meta, columns=cols, allow_duplicate=True)
                s.history(f"T{k}")
        except Exception as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert s.counts()["calibrations"] == 40 and s.verify() == []
    s.close()


def test_memory_store_works(tmp_path):
    with Store(":memory:") as s:
        meta, cols = small_capture()
        cid = s.save_calibration(accel_result(), meta=meta, columns=cols)
        assert s.history("IMU-1")[0]["id"] == cid
    assert not os.path.exists(":memory:")
