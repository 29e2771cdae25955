"""The station database schema, as an ordered list of named migrations.

Each migration is a list of SQL statements run once, in one transaction, by
`db.migrations.apply` (sqlite-utils `Migrations`, set name `station`, recorded in
the `_sqlite_migrations` table). Never edit a migration that has shipped: append a
new one. This module holds plain data so that opening an up-to-date database needs
neither sqlite-utils nor numpy (both are slow to import; the CLI must start fast).

Tables (readable names so `sqlite3`, `sqlite-utils` and Datasette can query them):

- `devices`: one row per device (id = serial number), its tolerances and interval.
- `captures`: one row per recording; its samples are in `capture_columns`, one
  row per column, each a zlib-compressed BLOB (see `db/codec.py`).
- `calibrations`: one row per calibration result, append-only, hash-chained per
  device (`prev_hash` -> `hash`, see `db/integrity.py`).
- `schedule`: per (device, procedure) the last accepted calibration and when the
  device is next due; derived data, rebuilt by `Store.rebuild_schedule()`.
- view `calibration_params`: one row per scalar calibration parameter.
- `anchors`: append-only, hash-chained log of each device's chain head, calibration
  count and settings hash after every change (`Store.verify` compares it with the tables).

Times are UTC ISO 8601 text `YYYY-MM-DDTHH:MM:SSZ` (sortable as text).
"""

from __future__ import annotations

import hashlib

MIGRATION_SET = "station"

_INITIAL = [
    """
    CREATE TABLE devices (
        id TEXT PRIMARY KEY NOT NULL CHECK (length(id) > 0),
        model TEXT,
        sensor_kinds TEXT NOT NULL DEFAULT '[]',
        notes TEXT,
        interval_days REAL CHECK (interval_days IS NULL OR interval_days > 0),
        tolerances TEXT NOT NULL DEFAULT '{}',
        created TEXT NOT NULL
    )
    """,
    """
    CREATE TABLE captures (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        device_id TEXT NOT NULL REFERENCES devices(id),
        procedure TEXT,
        time TEXT NOT NULL,
        operator TEXT,
        host TEXT,
        latitude_deg REAL,
        longitude_deg REAL,
        altitude_m REAL,
        n_rows INTEGER NOT NULL,
        column_names TEXT NOT NULL,
        meta TEXT NOT NULL,
        raw_bytes INTEGER NOT NULL,
        stored_bytes INTEGER NOT NULL,
        sha256 TEXT NOT NULL,
        saved_at TEXT NOT NULL
    )
    """,
    "CREATE INDEX captures_device_time ON captures(device_id, time)",
    """
    CREATE TABLE capture_columns (
        capture_id INTEGER NOT NULL REFERENCES captures(id) ON DELETE CASCADE,
        ordinal INTEGER NOT NULL,
        name TEXT NOT NULL,
        dtype TEXT NOT NULL,
        length INTEGER NOT NULL,
        encoding TEXT NOT NULL,
        data BLOB NOT NULL,
        PRIMARY KEY (capture_id, ordinal)
    )
    """,
    """
    CREATE TABLE calibrations (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        device_id TEXT NOT NULL REFERENCES devices(id),
        procedure TEXT NOT NULL,
        time TEXT NOT NULL,
        model TEXT,
        params TEXT NOT NULL,
        uncertainty TEXT NOT NULL,
        residual_rms REAL,
        n_positions INTEGER,
        warnings TEXT NOT NULL DEFAULT '[]',
        result_extra TEXT NOT NULL DEFAULT '{}',
        software_version TEXT,
        capture_id INTEGER REFERENCES captures(id),
        capture_sha256 TEXT,
        operator TEXT,
        host TEXT,
        accepted INTEGER NOT NULL CHECK (accepted IN (0, 1)),
        supersedes INTEGER REFERENCES calibrations(id),
        saved_at TEXT NOT NULL,
        record_version INTEGER NOT NULL,
        prev_hash TEXT,
        hash TEXT NOT NULL
    )
    """,
    "CREATE INDEX calibrations_device_time ON calibrations(device_id, time, id)",
    "CREATE INDEX calibrations_device_procedure_time ON calibrations(device_id, procedure, accepted, time, id)",
    "CREATE INDEX calibrations_procedure_time ON calibrations(procedure, time)",
    """
    CREATE TABLE schedule (
        device_id TEXT NOT NULL REFERENCES devices(id),
        procedure TEXT NOT NULL,
        last_calibration_id INTEGER NOT NULL REFERENCES calibrations(id),
        last_calibrated TEXT NOT NULL,
        interval_due TEXT,
        drift_due TEXT,
        drift_param TEXT,
        drift_rate_per_year REAL,
        due TEXT,
        PRIMARY KEY (device_id, procedure)
    )
    """,
    "CREATE INDEX schedule_due ON schedule(due)",
    # One row per scalar parameter: names like B[0], M[1][2], beam1.dK (json_tree's
    # fullkey without the leading '$.' and without the quotes some SQLite versions put
    # around nested keys); sigma from the same path in `uncertainty`.
    """
    CREATE VIEW calibration_params AS
    SELECT c.id AS calibration_id,
           c.device_id AS device_id,
           c.procedure AS procedure,
           c.time AS time,
           c.accepted AS accepted,
           replace(substr(p.fullkey, 3), '"', '') AS param,
           p.value AS value,
           (SELECT u.value FROM json_tree(c.uncertainty) AS u
             WHERE u.fullkey = p.fullkey AND u.type IN ('integer', 'real')) AS sigma
    FROM calibrations AS c, json_tree(c.params) AS p
    WHERE p.type IN ('integer', 'real')
    """,
]

# Anchors (issue 16): an append-only, hash-chained log of each device's state after every
# change the station makes: the head of its calibration chain (id, hash, count), the hash of
# its settings (model, kinds, notes, interval, tolerances) and a capture stored on its own.
# Deleting a device's newest calibration, or all of them, or editing its settings, leaves
# the newest anchor disagreeing with the tables; deleting anchors breaks their own chain
# (and `sqlite_sequence` still counts the ids issued). See `Store.verify`.
_ANCHORS = [
    """
    CREATE TABLE anchors (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        time TEXT NOT NULL,
        device_id TEXT NOT NULL,
        event TEXT NOT NULL CHECK (event IN ('baseline', 'calibration', 'settings', 'capture')),
        head_id INTEGER,
        head_hash TEXT,
        n_calibrations INTEGER NOT NULL,
        settings_hash TEXT NOT NULL,
        capture_id INTEGER,
        prev_hash TEXT,
        hash TEXT NOT NULL
    )
    """,
    "CREATE INDEX anchors_device ON anchors(device_id, id)",
]

# Accept, reject or override, never silently (record_version 2 hashes `review` too):
# - calibrations.review: JSON {verdict: pass|fail|no tolerance, reasons: [...],
#   decision: accepted|rejected|override, note}; NULL on records saved before it.
# - devices.limits: JSON {param or block: [low, high]}, absolute limits in the
#   parameter's units (tolerances are changes from the value in use).
# - captures.samples_sha256: sha256 of the capture's metadata and samples only (not
#   who saved it or from where): the same capture saved twice has the same digest.
# - settings: the station's remembered entries (operator, place, reference equipment).
_REVIEW = [
    "ALTER TABLE calibrations ADD COLUMN review TEXT",
    "ALTER TABLE devices ADD COLUMN limits TEXT NOT NULL DEFAULT '{}'",
    "ALTER TABLE captures ADD COLUMN samples_sha256 TEXT",
    "CREATE INDEX captures_samples ON captures(samples_sha256)",
    """
    CREATE TABLE settings (
        name TEXT PRIMARY KEY NOT NULL,
        value TEXT NOT NULL,
        updated TEXT NOT NULL
    )
    """,
]

# The anchors' settings hash covers devices.limits (settings version 2, db/integrity.py):
# no SQL; the station appends a `settings` anchor for every device after it (the limits as
# found become the anchored state). Anchors written before keep their version-1 hash.
_LIMITS_ANCHORED: list[str] = []

# A drift trend moves a due date only when it is significant (db.params.trend_verdict), and
# each schedule row says why its date is what it is (schedule.reason, one line). The station
# then recomputes each row the earlier rule (any rate) wrote, so the due dates follow the new
# rule and `verify` agrees; a row that neither rule gives (an edit by hand) is left, without
# a reason, for `verify` to report.
_SIGNIFICANT_DRIFT = ["ALTER TABLE schedule ADD COLUMN reason TEXT"]

# (name, statements), applied in this order. Append only.
MIGRATIONS: list[tuple[str, list[str]]] = [
    ("0001_initial", _INITIAL),
    ("0002_anchors", _ANCHORS),
    ("0003_review", _REVIEW),
    ("0004_limits_anchored", _LIMITS_ANCHORED),
    ("0005_significant_drift", _SIGNIFICANT_DRIFT),
]

MIGRATION_NAMES = [name for name, _ in MIGRATIONS]

# Changes whenever any migration's SQL changes (benchmarks key their cached DBs on it).
SCHEMA_VERSION = hashlib.sha256(
    "\n".join(name + "\n" + "\n".join(stmts) for name, stmts in MIGRATIONS).encode()
).hexdigest()[:12]

# Calibration record layout version, stored in every row (calibrations.record_version)
# and part of its hash. 2: the `review` column is hashed too.
RECORD_VERSION = 2
