"""`Store`: the station's SQLite database of devices, captures and calibrations.

One file, WAL journal, foreign keys on, a 30 s busy timeout so that two processes
saving at once take turns instead of failing. Every write is one `BEGIN IMMEDIATE`
transaction: a process killed mid-save leaves the previous state intact.

Conventions:
- Times are stored as UTC `YYYY-MM-DDTHH:MM:SSZ`; inputs may be any ISO 8601 date or
  date-time (naive = UTC).
- A calibration's time is the `time` argument, else the capture's `date`, else now.
- Non-finite numbers in results are stored as JSON null (see `db.params.clean_json`).
- Tolerances are per parameter name (`B[0]`) or per block (`B` = every element of B):
  the largest change from the value in use (the last accepted calibration) that the
  application can live with, in the parameter's own units.
- Parameter drift rates are per year (365.25 d).

Neither numpy nor sqlite-utils is imported at module level: opening an up-to-date
database and reading history must stay fast for the CLI.
"""

from __future__ import annotations

import json
import os
import socket
import sqlite3
import stat
import threading
import time
import weakref
from contextlib import contextmanager
from datetime import timedelta

from db import params as P
from db.codec import capture_digest, decode_column, encode_column
from db.integrity import (
    ANCHOR_COLUMNS,
    SETTINGS_COLUMNS,
    SETTINGS_COLUMNS_V2,
    anchor_hash,
    record_hash,
    settings_hash,
    settings_version,
)
from db.schema import MIGRATION_NAMES, MIGRATION_SET, RECORD_VERSION

BUSY_TIMEOUT_S = 30.0
FUTURE_MARGIN = timedelta(days=1)  # a date-only capture east of UTC, a clock a little ahead
MAX_PREDICTION_YEARS = 1000.0  # a drift slower than tolerance per millennium predicts no exit
# the longest recalibration interval [days]: 100 years (a due date must stay a date)
MAX_INTERVAL_DAYS = 36525.0
SQLITE_INT_RANGE = range(-(1 << 63), 1 << 63)  # a row id beyond SQLite's INTEGER names no row

_RESULT_COLUMNS = ("procedure", "device", "model", "params", "uncertainty", "residual_rms", "n_positions", "warnings")


class NotFound(LookupError):
    """No such device, capture or calibration (message names it)."""

    def __str__(self) -> str:  # LookupError would quote the message
        return str(self.args[0]) if self.args else "not found"


class DuplicateCapture(ValueError):
    """The capture's samples and metadata are already stored (`samples_sha256` matches)."""

    def __init__(self, capture_id: int, calibration_id: int | None, device_id: str):
        self.capture_id = capture_id
        self.calibration_id = calibration_id
        self.device_id = device_id
        held = f"calibration #{calibration_id}" if calibration_id is not None else f"capture #{capture_id}"
        super().__init__(
            f"this capture is already saved ({held} of {device_id}); a second save would count "
            "the same measurement twice"
        )


class ReferenceChanged(ValueError):
    """Another calibration became the result's reference (the device's latest accepted one of
    the procedure at or before the result's time ``at``) after the result being saved was
    judged against ``judged_id``: the judgement (the change from the reference, the
    previous_calibration_id it records) is out of date."""

    def __init__(
        self, device_id: str, procedure: str, judged_id: int | None, now_id: int | None, at: str | None = None
    ):
        self.device_id, self.procedure, self.judged_id, self.now_id = device_id, procedure, judged_id, now_id
        self.at = at  # the result's own time: its reference is the one in use then (`Store.reference(before=at)`)
        judged = f"calibration #{judged_id}" if judged_id is not None else "no previous calibration"
        now = f"calibration #{now_id}" if now_id is not None else "none"
        super().__init__(
            f"the reference of {device_id} ({procedure}) changed while this result was judged against {judged}: "
            f"it is now {now} (saved meanwhile by another process)"
        )


_UNSET = object()

# Review decisions stored in calibrations.review (see db/schema.py, migration 0002_review).
DECISIONS = ("accepted", "rejected", "override")


def default_db_path() -> str:
    """`$STATION_DB`, else `${XDG_DATA_HOME:-~/.local/share}/station/station.db`."""
    explicit = os.environ.get("STATION_DB")
    if explicit:
        return explicit
    base = os.environ.get("XDG_DATA_HOME") or os.path.join(os.path.expanduser("~"), ".local", "share")
    return os.path.join(base, "station", "station.db")


def _why_not_writable(path: str, exc: BaseException, memory: bool) -> None:
    """Raise SQLite's failure to open ``path`` with its cause when that is a permission: SQLite
    makes the -wal and -shm files beside a WAL database, to read it too, so a folder this user
    cannot write fails every command with "unable to open database file" (or "attempt to write
    a readonly database"), which did not say why. Returns when the cause is something else."""
    if memory or not isinstance(exc, sqlite3.OperationalError):
        return
    text = str(exc)
    if "unable to open database file" not in text and "readonly database" not in text:
        return
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(folder) and not os.access(folder, os.W_OK | os.X_OK):
        raise sqlite3.OperationalError(
            f"{text}: the folder {folder} is not writable by this user, and SQLite makes the database's "
            "-wal and -shm files beside it (to read it too)"
        ) from None
    if os.path.isfile(path) and not os.access(path, os.R_OK | os.W_OK):
        raise sqlite3.OperationalError(f"{text}: the file is not readable and writable by this user") from None


SQLITE_MAGIC = b"SQLite format 3\x00"  # the first 16 bytes of every SQLite 3 database file


# The database files this process has open through a Store: (st_dev, st_ino) -> count.
# Closing any descriptor of a file drops every POSIX lock the process holds on it, SQLite's
# included (fcntl semantics); with its locks gone, another process closing the database
# took itself for the last connection and deleted the -wal and -shm files under this one,
# whose later writes went to the deleted WAL and whose reads came from pages that no longer
# matched (a device row read back as a migration row). So the header is read only from a
# file this process does not hold open already.
_OPEN_FILES: dict[tuple[int, int], int] = {}
_OPEN_FILES_LOCK = threading.Lock()


def _file_key(path: str) -> tuple[int, int] | None:
    try:
        st = os.stat(path)  # stat opens nothing: no lock is dropped
    except (OSError, ValueError):
        return None
    return (st.st_dev, st.st_ino)


def _hold(key: tuple[int, int] | None) -> None:
    if key is not None:
        with _OPEN_FILES_LOCK:
            _OPEN_FILES[key] = _OPEN_FILES.get(key, 0) + 1


def _release(key: tuple[int, int] | None) -> None:
    if key is not None:
        with _OPEN_FILES_LOCK:
            n = _OPEN_FILES.get(key, 0) - 1
            if n > 0:
                _OPEN_FILES[key] = n
            else:
                _OPEN_FILES.pop(key, None)


_NOT_FILES = (
    (stat.S_ISFIFO, "a named pipe (FIFO)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def _refuse_non_sqlite(path: str) -> tuple[int, int] | None:
    """sqlite3.DatabaseError for an existing non-empty file that is not an SQLite database;
    else the file's key, now held in `_OPEN_FILES` (None: no file yet).

    SQLite itself takes a file shorter than its 100-byte header for an empty database and
    writes a new one over it: a one-byte text file given as the database was replaced.
    A file this process already holds open through a Store is SQLite (checked when it was
    opened) and is not opened again here (see `_OPEN_FILES`)."""
    if path.startswith("file:"):
        return None
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return None  # a new database (or a link to where one will be)
    except OSError as exc:  # a loop of links, a name too long
        raise sqlite3.DatabaseError(f"cannot open: {exc.strerror or exc}") from None
    if not stat.S_ISREG(mode):
        kind = next((name for test, name in _NOT_FILES if test(mode)), None)
        if kind is None:  # a folder: sqlite3.connect says why
            return None
        # SQLite reads a named pipe until a writer comes (or says 'disk I/O error')
        raise sqlite3.DatabaseError(f"{kind}, not a database file: refused")
    with _OPEN_FILES_LOCK:  # checked and held in one step: no other thread's first open in between
        key = _file_key(path)
        if key is None or key not in _OPEN_FILES:
            try:
                with open(path, "rb") as f:
                    head = f.read(len(SQLITE_MAGIC))
            except OSError:
                return None  # sqlite3.connect says why
            if head and head != SQLITE_MAGIC:
                raise sqlite3.DatabaseError("file is not a database (not SQLite: left as it is)")
        if key is not None:
            _OPEN_FILES[key] = _OPEN_FILES.get(key, 0) + 1
        return key


# A schedule row, in the order `_schedule_row` gives it (`reason` since migration 0005).
SCHEDULE_COLUMNS = (
    "device_id",
    "procedure",
    "last_calibration_id",
    "last_calibrated",
    "interval_due",
    "drift_due",
    "drift_param",
    "drift_rate_per_year",
    "due",
    "reason",
)


def _same_row(a, b) -> bool:
    """Two schedule rows agree (floats to 1e-9 relative: the drift rate)."""
    return all(
        (x == y) or (isinstance(x, float) and isinstance(y, float) and abs(x - y) <= 1e-9 * max(abs(x), abs(y)))
        for x, y in zip(a, b)
    )


def _drift_note(judged: list[dict], n: int) -> str:
    """Why no trend moves the due date, for the parameters with a tolerance (one phrase)."""
    if not judged:
        return "no tolerance names a parameter of this procedure, so drift does not move it"
    if n < P.DRIFT_MIN_CALIBRATIONS:
        return f"drift needs {P.DRIFT_MIN_CALIBRATIONS} accepted calibrations, has {n}"
    significant = [t for t in judged if t["significant"]]
    if significant:
        return f"drift of {significant[0]['param']} ({significant[0]['verdict']}) stays within its tolerance"
    rated = [t for t in judged if t["significance_sigmas"] is not None]
    if not rated:
        return f"no drift rate over {n} calibrations"
    t = max(rated, key=lambda t: t["significance_sigmas"])
    return (
        f"no significant drift over {n} calibrations (steepest {t['param']} "
        f"{t['rate_per_year']:+.3g} ± {t['rate_sigma_per_year']:.2g}/year, {t['verdict']})"
    )


def _loads(text, default=None):
    if text is None:
        return default
    try:
        return json.loads(text)
    except ValueError as exc:  # edited outside the station
        raise ValueError(
            f"the database holds a record that is not valid JSON ({exc}); "
            "`station verify` names the records changed after they were written"
        ) from None


def compared_with(cal: dict) -> int | None:
    """The calibration ``cal`` was compared with when saved: its review's
    `previous_calibration_id` (None: there was none), else what it `supersedes` (saves
    without a judgement: imports, tools)."""
    review = cal.get("review") or {}
    return review["previous_calibration_id"] if "previous_calibration_id" in review else cal.get("supersedes")


def _back_dated_before(cal: dict, others: list[dict], compared: dict | None) -> list[dict]:
    """Of ``others``, the accepted calibrations of ``cal``'s device and procedure saved after it
    (a higher id) that sort before it by (time, id) and after ``compared`` (the one it was
    compared with, None: all before it), nearest first (`Store.back_dated_before`); [] for a
    rejected ``cal`` (never in use, its place in the history changes nothing)."""
    if not cal["accepted"]:
        return []
    low = (compared["time"], compared["id"]) if compared is not None else None
    hits = [
        o
        for o in others
        if o["accepted"]
        and o["device_id"] == cal["device_id"]
        and o["procedure"] == cal["procedure"]
        and o["id"] > cal["id"]
        and (o["time"], o["id"]) < (cal["time"], cal["id"])
        and (low is None or (o["time"], o["id"]) > low)
    ]
    return sorted(hits, key=lambda o: (o["time"], o["id"]), reverse=True)


class Store:
    """The station database. Thread-safe (one lock). Several in one process (the TUI's screens
    and saves) keep SQLite's locks: see `_OPEN_FILES`."""

    def __init__(self, path: str):
        self.path = os.fspath(path)
        memory = self.path == ":memory:" or self.path.startswith("file::memory:")
        key = None
        if not memory:
            key = _refuse_non_sqlite(self.path)
            parent = os.path.dirname(os.path.abspath(self.path))
            os.makedirs(parent, exist_ok=True)
        self._lock = threading.RLock()
        try:
            self.conn = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_S, check_same_thread=False)
        except BaseException as exc:
            _release(key)
            _why_not_writable(self.path, exc, memory)
            raise
        self.conn.row_factory = sqlite3.Row
        try:
            self.conn.execute(f"PRAGMA busy_timeout = {int(BUSY_TIMEOUT_S * 1000)}")
            self.conn.execute("PRAGMA foreign_keys = ON")
            newer = self._unknown_migrations()
            if newer:  # written by a newer station: reading or writing it as this schema could lose what it keeps
                raise sqlite3.DatabaseError(
                    f"written by a newer station (schema step {', '.join(newer)}, which this version does not "
                    "have): use that version or a later one (left as it is)"
                )
            if not memory and self.conn.execute("PRAGMA journal_mode").fetchone()[0].lower() != "wal":
                self._to_wal()
            if self._pending_migrations():
                from db.migrations import apply

                apply(self.conn, post=self._after_migrations)
        except BaseException as exc:
            self.conn.close()
            _release(key)
            _why_not_writable(self.path, exc, memory)
            raise
        if key is None and not memory:  # the file SQLite has just made
            key = _file_key(self.path)
            _hold(key)
        self._unhold = weakref.finalize(self, _release, key)  # on close, or when collected unclosed

    # --- plumbing -----------------------------------------------------------------------

    def _to_wal(self) -> None:
        """Switch the file to WAL. Two processes opening a new database at once race here: the
        switch needs the file to itself, and SQLite answers 'database is locked' at once rather
        than through the busy timeout, so it is tried again until that timeout has passed."""
        deadline = time.monotonic() + BUSY_TIMEOUT_S
        while True:
            try:
                self.conn.execute("PRAGMA journal_mode = WAL")
                return
            except sqlite3.OperationalError as exc:
                if "locked" not in str(exc) or time.monotonic() > deadline:
                    raise
                time.sleep(0.02)

    def _applied_migrations(self) -> list[str] | None:
        """Names of the station's migrations the file records, in the order applied; None when it
        has no migrations table yet."""
        try:
            rows = self.conn.execute(
                "SELECT name FROM _sqlite_migrations WHERE migration_set = ? ORDER BY id", [MIGRATION_SET]
            ).fetchall()
        except sqlite3.OperationalError:
            return None
        return [r[0] for r in rows]

    def _unknown_migrations(self) -> list[str]:
        """Migrations of the station's set that this version does not have (a newer station's)."""
        return [n for n in self._applied_migrations() or [] if n not in MIGRATION_NAMES]

    def _pending_migrations(self) -> list[str]:
        done = set(self._applied_migrations() or [])
        return [n for n in MIGRATION_NAMES if n not in done]

    def _after_migrations(self, conn, names: list[str]) -> None:
        """The first anchors of a database that gets the anchors table now: its state as found."""
        if "0002_anchors" in names:
            for (device_id,) in conn.execute("SELECT id FROM devices ORDER BY id").fetchall():
                self._append_anchor(conn, device_id, "baseline")
        elif "0004_limits_anchored" in names:  # the limits as found, under the anchors from now on
            for (device_id,) in conn.execute("SELECT id FROM devices ORDER BY id").fetchall():
                self._append_anchor(conn, device_id, "settings")
        if "0005_significant_drift" in names:  # due dates by the significant-drift rule
            self._reschedule_old_rule(conn)

    def _reschedule_old_rule(self, conn) -> None:
        """Recompute each schedule row that the rule before 0005 (any drift rate moved the due
        date) gives exactly, and its new `reason`; any other row (edited by hand) stays, without
        a reason, for `verify` to report."""
        stored = conn.execute(f"SELECT {', '.join(SCHEDULE_COLUMNS[:-1])} FROM schedule").fetchall()
        for r in stored:
            try:
                old = self._schedule_row(conn, r[0], r[1], significant_only=False)
            except (ValueError, TypeError, KeyError):  # an edited record the trend cannot read
                continue
            if old is not None and _same_row(list(r), old[:-1]):
                self._update_schedule(conn, r[0], r[1])

    def _append_anchor(self, conn, device_id: str, event: str, capture_id: int | None = None) -> None:
        """Append one anchor: the device's chain head, calibration count and settings hash now."""
        dev = conn.execute("SELECT * FROM devices WHERE id = ?", [device_id]).fetchone()
        head = conn.execute(
            "SELECT id, hash FROM calibrations WHERE device_id = ? ORDER BY id DESC LIMIT 1", [device_id]
        ).fetchone()
        n = conn.execute("SELECT count(*) FROM calibrations WHERE device_id = ?", [device_id]).fetchone()[0]
        prev = conn.execute("SELECT hash FROM anchors ORDER BY id DESC LIMIT 1").fetchone()
        row = {
            "time": P.now_utc().strftime("%Y-%m-%dT%H:%M:%S.%fZ"),
            "device_id": device_id,
            "event": event,
            "head_id": head["id"] if head else None,
            "head_hash": head["hash"] if head else None,
            "n_calibrations": int(n),
            "settings_hash": settings_hash(dict(dev)) if dev is not None else "",
            "capture_id": capture_id,
            "prev_hash": prev["hash"] if prev else None,
        }
        cur = conn.execute(
            f"INSERT INTO anchors ({', '.join(row)}, hash) VALUES ({', '.join('?' * len(row))}, '')", list(row.values())
        )
        row["id"] = cur.lastrowid
        conn.execute("UPDATE anchors SET hash = ? WHERE id = ?", [anchor_hash(row), row["id"]])

    def has_anchor(self, anchor: str) -> bool:
        """Whether ``anchor`` (a hash shown in an export or report) is still in the anchors table."""
        return bool(self._query("SELECT 1 FROM anchors WHERE hash = ? LIMIT 1", [anchor]))

    def anchor_head(self) -> str | None:
        """The newest anchor's hash: written into exports and reports, so that `station verify
        --anchor HASH` can tell whether anchors were removed after they were shown."""
        rows = self._query("SELECT hash FROM anchors ORDER BY id DESC LIMIT 1")
        return rows[0]["hash"] if rows else None

    @property
    def database(self):
        """This connection as a `sqlite_utils.Database` (imports sqlite-utils on first use)."""
        from sqlite_utils import Database

        return Database(self.conn)

    @contextmanager
    def _write(self):
        """One write transaction holding the database's write lock from its start."""
        with self._lock:
            self.conn.execute("BEGIN IMMEDIATE")
            try:
                yield self.conn
            except BaseException:
                if self.conn.in_transaction:
                    self.conn.execute("ROLLBACK")
                raise
            self.conn.execute("COMMIT")

    def _query(self, sql: str, args=()) -> list[sqlite3.Row]:
        with self._lock:
            return self.conn.execute(sql, args).fetchall()

    def check_writable(self) -> None:
        """Raise sqlite3.OperationalError when a write to this database would fail (a file that
        may be read but not written: a read-only mode, an immutable file, a read-only mount).
        Opening such a WAL database succeeds and reads work, so the failure came only with the
        first write: in the TUI after a whole procedure. Nothing is written (the probe table is
        rolled back); a database another connection is writing counts as writable."""
        with self._lock:
            self.conn.execute("PRAGMA busy_timeout = 0")
            try:
                self.conn.execute("BEGIN IMMEDIATE")
                try:
                    self.conn.execute("CREATE TABLE station_write_probe (x)")
                finally:
                    self.conn.execute("ROLLBACK")
            except sqlite3.OperationalError as exc:
                if "locked" not in str(exc) and "busy" not in str(exc):
                    _why_not_writable(self.path, exc, False)
                    raise
            finally:
                self.conn.execute(f"PRAGMA busy_timeout = {int(BUSY_TIMEOUT_S * 1000)}")

    def close(self) -> None:
        with self._lock:
            self.conn.close()
        self._unhold()

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --- devices ------------------------------------------------------------------------

    @staticmethod
    def _check_id(device_id) -> str:
        if not isinstance(device_id, str) or not device_id.strip():
            raise ValueError(f"device id must be a non-empty string, got {device_id!r}")
        return device_id

    @staticmethod
    def _device_dict(row) -> dict:
        return {
            "id": row["id"],
            "model": row["model"],
            "sensor_kinds": _loads(row["sensor_kinds"], []),
            "notes": row["notes"],
            "interval_days": row["interval_days"],
            "tolerances": _loads(row["tolerances"], {}),
            "limits": _loads(row["limits"], {}) if "limits" in row.keys() else {},
            "created": row["created"],
        }

    def _ensure_device(self, conn, device_id: str, kind: str | None = None) -> None:
        row = conn.execute("SELECT sensor_kinds FROM devices WHERE id = ?", [device_id]).fetchone()
        if row is None:
            conn.execute(
                "INSERT INTO devices (id, sensor_kinds, tolerances, created) VALUES (?, ?, '{}', ?)",
                [device_id, json.dumps([kind] if kind else []), P.iso(P.now_utc())],
            )
            return
        kinds = _loads(row["sensor_kinds"], [])
        if kind and kind not in kinds:
            conn.execute("UPDATE devices SET sensor_kinds = ? WHERE id = ?", [json.dumps(kinds + [kind]), device_id])

    def add_device(
        self,
        device_id: str,
        *,
        model: str | None = None,
        sensor_kinds: list[str] | None = None,
        notes: str | None = None,
        interval_days: float | None = None,
        tolerances: dict | None = None,
        limits: dict | None = None,
    ) -> dict:
        """Add a device, or update the fields given (not None) of an existing one.

        `tolerances` merges into the stored ones; a value of None removes that name.
        `limits` ({name or block: (low, high)}, absolute, in the parameter's units;
        either end may be None) merges the same way.
        Changing the interval or tolerances updates the device's recalibration schedule.
        """
        self._check_id(device_id)
        if interval_days is not None:
            interval_days = float(interval_days)
            if not 0 < interval_days <= MAX_INTERVAL_DAYS:
                raise ValueError(f"interval_days must be positive, at most {MAX_INTERVAL_DAYS:g}, got {interval_days}")
        if tolerances is not None:
            for name, value in tolerances.items():
                if value is not None and not (isinstance(value, (int, float)) and value > 0):
                    raise ValueError(f"tolerance {name!r} must be a positive number, got {value!r}")
        if limits is not None:
            limits = {str(k): (None if v is None else _check_limit(k, v)) for k, v in limits.items()}
        with self._write() as conn:
            self._ensure_device(conn, device_id)
            row = conn.execute("SELECT * FROM devices WHERE id = ?", [device_id]).fetchone()
            current = self._device_dict(row)
            if model is not None:
                current["model"] = model
            if notes is not None:
                current["notes"] = notes
            if sensor_kinds is not None:
                current["sensor_kinds"] = list(dict.fromkeys(str(k) for k in sensor_kinds))
            if interval_days is not None:
                current["interval_days"] = interval_days
            if tolerances is not None:
                tol = dict(current["tolerances"])
                for name, value in tolerances.items():
                    if value is None:
                        tol.pop(str(name), None)
                    else:
                        tol[str(name)] = float(value)
                current["tolerances"] = tol
            if limits is not None:
                lim = dict(current["limits"])
                for name, value in limits.items():
                    if value is None:
                        lim.pop(name, None)
                    else:
                        lim[name] = value
                conn.execute(
                    "UPDATE devices SET limits = ? WHERE id = ?",
                    [json.dumps(lim, ensure_ascii=False, sort_keys=True), device_id],
                )
            conn.execute(
                "UPDATE devices SET model = ?, sensor_kinds = ?, notes = ?, interval_days = ?, tolerances = ? WHERE id = ?",
                [
                    current["model"],
                    json.dumps(current["sensor_kinds"], ensure_ascii=False),
                    current["notes"],
                    current["interval_days"],
                    json.dumps(current["tolerances"], ensure_ascii=False, sort_keys=True),
                    device_id,
                ],
            )
            self._append_anchor(conn, device_id, "settings")
            if interval_days is not None or tolerances is not None:
                for (procedure,) in conn.execute(
                    "SELECT DISTINCT procedure FROM calibrations WHERE device_id = ? AND accepted = 1", [device_id]
                ).fetchall():
                    self._update_schedule(conn, device_id, procedure)
        return self.get_device(device_id)

    def get_device(self, device_id: str) -> dict | None:
        rows = self._query("SELECT * FROM devices WHERE id = ?", [device_id])
        return self._device_dict(rows[0]) if rows else None

    def list_devices(self) -> list[dict]:
        """Every device, by id, with `n_calibrations` and `last_calibrated` (accepted only)."""
        rows = self._query(
            """
            SELECT d.*, (SELECT count(*) FROM calibrations c WHERE c.device_id = d.id) AS n_calibrations,
                   (SELECT max(s.last_calibrated) FROM schedule s WHERE s.device_id = d.id) AS last_calibrated
            FROM devices d ORDER BY d.id
            """
        )
        out = []
        for r in rows:
            d = self._device_dict(r)
            d["n_calibrations"] = r["n_calibrations"]
            d["last_calibrated"] = r["last_calibrated"]
            out.append(d)
        return out

    # --- captures -----------------------------------------------------------------------

    def _insert_capture(
        self, conn, *, device_id, procedure, meta, columns, operator, host, now=None
    ) -> tuple[int, str]:
        meta = {str(k): str(v) for k, v in dict(meta or {}).items()}
        if not columns:
            raise ValueError("a capture needs at least one column")
        encoded = [encode_column(name, arr) for name, arr in columns.items()]
        lengths = {c["length"] for c in encoded}
        if len(lengths) != 1:
            raise ValueError(f"capture columns differ in length: {sorted(lengths)}")
        now = now or P.now_utc()  # the save's time (a date alone is read at it: `params.capture_time`)
        time = P.capture_time(meta, now) or P.iso(now)

        def place(key):
            try:
                return float(meta[key]) if meta.get(key) not in (None, "") else None
            except ValueError:
                return None

        header = {
            "device_id": device_id,
            "procedure": procedure,
            "time": time,
            "operator": operator,
            "host": host,
            "meta": json.dumps(meta, ensure_ascii=False),
        }
        digest = capture_digest(header, [(c["name"], c["dtype"], c["length"], c["sha256"]) for c in encoded])
        cur = conn.execute(
            """INSERT INTO captures (device_id, procedure, time, operator, host, latitude_deg, longitude_deg,
                   altitude_m, n_rows, column_names, meta, raw_bytes, stored_bytes, sha256, saved_at, samples_sha256)
               VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)""",
            [
                device_id,
                procedure,
                time,
                operator,
                host,
                place("latitude_deg"),
                place("longitude_deg"),
                place("altitude_m"),
                lengths.pop(),
                json.dumps([c["name"] for c in encoded], ensure_ascii=False),
                header["meta"],
                sum(c["raw_bytes"] for c in encoded),
                sum(len(c["data"]) for c in encoded),
                digest,
                P.now_utc().strftime("%Y-%m-%dT%H:%M:%S.%fZ"),
                _samples_digest(header["meta"], encoded),
            ],
        )
        capture_id = cur.lastrowid
        conn.executemany(
            "INSERT INTO capture_columns (capture_id, ordinal, name, dtype, length, encoding, data) VALUES (?, ?, ?, ?, ?, ?, ?)",
            [
                (capture_id, i, c["name"], c["dtype"], c["length"], c["encoding"], c["data"])
                for i, c in enumerate(encoded)
            ],
        )
        return capture_id, digest

    def save_capture(
        self,
        *,
        device_id,
        procedure,
        meta: dict,
        columns: dict,
        operator=None,
        host=None,
        sensor_kind: str | None = None,
    ) -> int:
        """Store one capture losslessly (see `db.codec`); the device is created if unknown.
        ``sensor_kind`` (accel, gyro, mag, ldv: the caller's procedure registry says which) is
        merged into the device's ``sensor_kinds``."""
        self._check_id(device_id)
        operator = operator if operator is not None else (meta or {}).get("operator")
        host = host if host is not None else socket.gethostname()
        with self._write() as conn:
            self._ensure_device(conn, device_id, sensor_kind)
            capture_id, _ = self._insert_capture(
                conn, device_id=device_id, procedure=procedure, meta=meta, columns=columns, operator=operator, host=host
            )
            self._append_anchor(conn, device_id, "capture", capture_id)
        return capture_id

    def find_duplicate(self, meta: dict, columns: dict) -> dict | None:
        """The stored capture with these exact samples and metadata, or None.

        {capture_id, device_id, calibration_id (its latest calibration, or None)}.
        """
        meta = {str(k): str(v) for k, v in dict(meta or {}).items()}
        digest = _samples_digest(
            json.dumps(meta, ensure_ascii=False), [encode_column(n, a) for n, a in columns.items()]
        )
        return self._duplicate(self.conn, digest)

    def _duplicate(self, conn, digest: str) -> dict | None:
        with self._lock:
            row = conn.execute(
                """SELECT c.id, c.device_id, (SELECT max(k.id) FROM calibrations k WHERE k.capture_id = c.id) AS cal
                   FROM captures c WHERE c.samples_sha256 = ? ORDER BY c.id LIMIT 1""",
                [digest],
            ).fetchone()
        if row is None:
            return None
        return {"capture_id": row["id"], "device_id": row["device_id"], "calibration_id": row["cal"]}

    def _read_capture(self, capture_id):
        with self._lock:
            row = None
            if capture_id in SQLITE_INT_RANGE:
                row = self.conn.execute("SELECT * FROM captures WHERE id = ?", [capture_id]).fetchone()
            if row is None:
                raise NotFound(f"no capture {capture_id}")
            cols = self.conn.execute(
                "SELECT name, dtype, length, encoding, data FROM capture_columns WHERE capture_id = ? ORDER BY ordinal",
                [capture_id],
            ).fetchall()
        return row, cols

    def load_capture(self, capture_id: int) -> tuple[dict, dict]:
        """(meta, columns) exactly as saved: same column order, bit-identical arrays."""
        row, cols = self._read_capture(capture_id)
        meta = _loads(row["meta"])
        columns = {}
        for c in cols:
            try:
                columns[c["name"]], _ = decode_column(c["dtype"], c["length"], c["encoding"], c["data"])
            except (ValueError, TypeError) as exc:  # changed after it was written: `station verify` names it
                raise ValueError(f"capture {capture_id}, column {c['name']!r}: {exc}") from None
        return meta, columns

    def capture_info(self, capture_id: int) -> dict:
        """The capture's row without its samples."""
        row, _ = self._read_capture(capture_id)
        d = dict(row)
        d["meta"] = _loads(d["meta"])
        d["column_names"] = _loads(d["column_names"])
        return d

    # --- calibrations -------------------------------------------------------------------

    def save_calibration(
        self,
        result: dict,
        *,
        meta: dict,
        columns: dict,
        device_id: str | None = None,
        operator: str | None = None,
        accepted: bool = True,
        time=None,
        software_version: str | None = None,
        host: str | None = None,
        sensor_kind: str | None = None,
        review: dict | None = None,
        allow_duplicate: bool = False,
        judged_reference=_UNSET,
    ) -> int:
        """Store a capture and its calibration result (calibrate.md shape) in one transaction.

        The device is `device_id`, else `result['device']`, else `meta['device']`
        (created if unknown). Its time is ``time``, else the capture's (`params.capture_time`:
        a date alone is read at this save, so a capture dated today is stored at the save's
        time), else now. An accepted calibration supersedes the device's latest
        accepted calibration of the same procedure at or before its time. ``sensor_kind``
        (accel, gyro, mag, ldv) is merged into the device's ``sensor_kinds``. Returns the
        calibration id.

        `review` records how the result was judged and decided: {verdict, reasons,
        decision (accepted | rejected | override), note}; `decision` must agree with
        `accepted` (override = accepted despite a failed verdict, and needs a note).
        A capture whose samples and metadata are already stored raises
        `DuplicateCapture` unless `allow_duplicate`.

        ``judged_reference``: the id of the reference (`reference(device, procedure, before=time)`:
        the calibration in use at the result's own time, None for none) the result was judged
        against. It is read again inside the write transaction (BEGIN IMMEDIATE: no other save can
        come between), and a different one raises `ReferenceChanged` with nothing saved: two
        processes saving at once were both judged against the same reference, and the second
        stored a judgement the first had made stale. The calibration it supersedes is that same
        reference, so its `supersedes` and the judgement's `previous_calibration_id` agree, also
        for a result dated before the device's latest (a back-dated capture: it takes its place
        in the history at its date; the later calibrations keep their records, see `later`).
        """
        meta = dict(meta or {})
        device = device_id or result.get("device") or meta.get("device")
        if not device:
            raise ValueError("no device: pass device_id, or give 'device' in the result or the capture")
        self._check_id(device)
        procedure = result.get("procedure") or meta.get("procedure")
        if not procedure:
            raise ValueError("no procedure in the result or the capture")
        if not isinstance(result.get("params"), dict):
            raise ValueError("the result has no 'params' object")
        now = P.now_utc()  # one clock reading: a date alone is read at the save (`params.capture_time`)
        when = P.normalize_time(time) if time is not None else (P.capture_time(meta, now) or P.iso(now))
        if P.parse_time(when) > now + FUTURE_MARGIN:  # a typo (2062 for 2026) hid the device from `due`
            raise ValueError(
                f"the calibration's time {when} (the capture's 'date') is in the future (now "
                f"{P.iso(P.now_utc())}): it is when the data were measured; correct the date"
            )
        operator = operator if operator is not None else meta.get("operator")
        host = host if host is not None else socket.gethostname()
        params = P.clean_json(result["params"])
        uncertainty = P.clean_json(result.get("uncertainty") or {})
        warnings = P.clean_json(list(result.get("warnings") or []))
        extra = P.clean_json({k: v for k, v in result.items() if k not in _RESULT_COLUMNS})
        residual = P.clean_json(result.get("residual_rms"))
        n_pos = result.get("n_positions")
        review_text = None
        if review is not None:
            review = P.clean_json(dict(review))
            decision = review.get("decision")
            if decision not in DECISIONS:
                raise ValueError(f"review decision must be one of {', '.join(DECISIONS)}, got {decision!r}")
            if (decision != "rejected") != bool(accepted):
                raise ValueError(f"review decision {decision!r} disagrees with accepted={bool(accepted)}")
            if decision == "override" and not str(review.get("note") or "").strip():
                raise ValueError("accepting a failed calibration needs a note saying why")
            review_text = P.dumps(review)
        with self._write() as conn:
            if not allow_duplicate:
                meta_text = json.dumps({str(k): str(v) for k, v in meta.items()}, ensure_ascii=False)
                dup = self._duplicate(
                    conn, _samples_digest(meta_text, [encode_column(n, a) for n, a in columns.items()])
                )
                if dup is not None:
                    raise DuplicateCapture(dup["capture_id"], dup["calibration_id"], dup["device_id"])
            if judged_reference is not _UNSET:
                # the calibration in use at the result's own time: the one it supersedes below
                ref = conn.execute(
                    """SELECT id FROM calibrations WHERE device_id = ? AND procedure = ? AND accepted = 1 AND time <= ?
                       ORDER BY time DESC, id DESC LIMIT 1""",
                    [device, procedure, when],
                ).fetchone()
                now_id = ref["id"] if ref else None
                if now_id != judged_reference:
                    raise ReferenceChanged(device, procedure, judged_reference, now_id, when)
            self._ensure_device(conn, device, sensor_kind)
            capture_id, capture_sha = self._insert_capture(
                conn,
                device_id=device,
                procedure=procedure,
                meta=meta,
                columns=columns,
                operator=operator,
                host=host,
                now=now,
            )
            supersedes = None
            if accepted:
                prev = conn.execute(
                    """SELECT id FROM calibrations WHERE device_id = ? AND procedure = ? AND accepted = 1 AND time <= ?
                       ORDER BY time DESC, id DESC LIMIT 1""",
                    [device, procedure, when],
                ).fetchone()
                supersedes = prev["id"] if prev else None
            last = conn.execute(
                "SELECT hash FROM calibrations WHERE device_id = ? ORDER BY id DESC LIMIT 1", [device]
            ).fetchone()
            cur = conn.execute(
                """INSERT INTO calibrations (device_id, procedure, time, model, params, uncertainty, residual_rms,
                       n_positions, warnings, result_extra, software_version, capture_id, capture_sha256, operator,
                       host, accepted, supersedes, saved_at, record_version, prev_hash, review, hash)
                   VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, '')""",
                [
                    device,
                    procedure,
                    when,
                    result.get("model"),
                    P.dumps(params),
                    P.dumps(uncertainty),
                    residual,
                    None if n_pos is None else int(n_pos),
                    P.dumps(warnings),
                    P.dumps(extra),
                    software_version,
                    capture_id,
                    capture_sha,
                    operator,
                    host,
                    1 if accepted else 0,
                    supersedes,
                    P.now_utc().strftime("%Y-%m-%dT%H:%M:%S.%fZ"),
                    RECORD_VERSION,
                    last["hash"] if last else None,
                    review_text,
                ],
            )
            cal_id = cur.lastrowid
            row = conn.execute("SELECT * FROM calibrations WHERE id = ?", [cal_id]).fetchone()
            conn.execute("UPDATE calibrations SET hash = ? WHERE id = ?", [record_hash(dict(row)), cal_id])
            if accepted:
                self._update_schedule(conn, device, procedure)
            self._append_anchor(conn, device, "calibration")
        return cal_id

    @staticmethod
    def _cal_dict(row) -> dict:
        return {
            "id": row["id"],
            "device_id": row["device_id"],
            "time": row["time"],
            "procedure": row["procedure"],
            "model": row["model"],
            "params": _loads(row["params"]),
            "uncertainty": _loads(row["uncertainty"]),
            "residual_rms": row["residual_rms"],
            "n_positions": row["n_positions"],
            "warnings": _loads(row["warnings"]),
            "extra": _loads(row["result_extra"]),
            "accepted": bool(row["accepted"]),
            "capture_id": row["capture_id"],
            "supersedes": row["supersedes"],
            "software_version": row["software_version"],
            "operator": row["operator"],
            "host": row["host"],
            "saved_at": row["saved_at"],
            "review": _loads(row["review"]) if "review" in row.keys() else None,
        }

    def history(self, device_id: str, procedure: str | None = None) -> list[dict]:
        """The device's calibrations, oldest first (by time, then id); [] for an unknown device.

        Each accepted one also says `superseded_by`: the next accepted calibration of its
        procedure by time (None: the one in use). `supersedes` is what a calibration replaced
        when it was saved; a result saved later with an earlier date (a back-dated capture)
        takes its place between the two by date, so `superseded_by` follows the dates, not
        the order of the saves. `back_dated_before` lists such results that came before it
        after it was saved (`back_dated_before`), as ids, nearest first.
        """
        sql = "SELECT * FROM calibrations WHERE device_id = ?"
        args = [device_id]
        if procedure is not None:
            sql += " AND procedure = ?"
            args.append(procedure)
        rows = self._query(sql + " ORDER BY time, id", args)
        out = [self._cal_dict(r) for r in rows]
        last: dict[str, dict] = {}  # procedure -> its latest accepted so far
        for d in out:
            d["superseded_by"] = None
            if d["accepted"]:
                if d["procedure"] in last:
                    last[d["procedure"]]["superseded_by"] = d["id"]
                last[d["procedure"]] = d
        by_id = {d["id"]: d for d in out}
        saved_last = 0  # the highest id among the records before d (by time, then id)
        for d in out:
            # only a record saved after d can precede it: most have none, and no list is scanned
            before = _back_dated_before(d, out, by_id.get(compared_with(d))) if saved_last > d["id"] else []
            d["back_dated_before"] = [b["id"] for b in before]
            saved_last = max(saved_last, d["id"])
        return out

    def calibration(self, calibration_id: int) -> dict:
        """One calibration with its `result` rebuilt in the calibrate.md shape, and its hashes."""
        rows = []
        if calibration_id in SQLITE_INT_RANGE:
            rows = self._query("SELECT * FROM calibrations WHERE id = ?", [calibration_id])
        if not rows:
            raise NotFound(f"no calibration {calibration_id}")
        row = rows[0]
        d = self._cal_dict(row)
        d["hash"] = row["hash"]
        d["prev_hash"] = row["prev_hash"]
        d["capture_sha256"] = row["capture_sha256"]
        d["record_version"] = row["record_version"]
        d["anchor"] = self.anchor_head()  # the newest anchor when this was read (exports carry it)
        result = {
            "procedure": d["procedure"],
            "device": d["device_id"],
            "model": d["model"],
            "params": d["params"],
            "uncertainty": d["uncertainty"],
            "residual_rms": d["residual_rms"],
            "n_positions": d["n_positions"],
            "warnings": d["warnings"],
        }
        result.update(d["extra"])
        d["result"] = result
        later = self.later(calibration_id)[:1] if d["accepted"] else []
        d["superseded_by"] = later[0]["id"] if later else None  # by time, as `history` says it
        d["back_dated_before"] = [b["id"] for b in self.back_dated_before(calibration_id)]
        return d

    def back_dated_before(self, calibration_id: int) -> list[dict]:
        """For an accepted calibration, the accepted ones of the same device and procedure saved
        after it and dated before it, but after the one it was compared with when saved (its review's
        `previous_calibration_id`, else what it `supersedes`): back-dated captures that now come
        between the two in the history. Nearest first; [] for none. This one's record stays as
        saved, with the judgement made then (see `later`)."""
        rows = self._query(
            """SELECT l.* FROM calibrations c JOIN calibrations l
                   ON l.device_id = c.device_id AND l.procedure = c.procedure AND l.accepted = 1
                      AND l.id > c.id AND l.time < c.time
               WHERE c.id = ? ORDER BY l.time DESC, l.id DESC""",
            [calibration_id],
        )
        if not rows:
            return []
        cal = self._cal_dict(self._query("SELECT * FROM calibrations WHERE id = ?", [calibration_id])[0])
        ref = compared_with(cal)
        ref_rows = self._query("SELECT * FROM calibrations WHERE id = ?", [ref]) if ref is not None else []
        return _back_dated_before(
            cal, [self._cal_dict(r) for r in rows], self._cal_dict(ref_rows[0]) if ref_rows else None
        )

    def later(self, calibration_id: int) -> list[dict]:
        """The accepted calibrations of the same device and procedure dated after this one
        (by time, then id), oldest first: [] for the one in use. The first supersedes it in
        the history; for a calibration saved after them (a back-dated capture) they were
        judged, when saved, against the one before it."""
        rows = self._query(
            """SELECT l.* FROM calibrations c JOIN calibrations l
                   ON l.device_id = c.device_id AND l.procedure = c.procedure AND l.accepted = 1
                      AND (l.time > c.time OR (l.time = c.time AND l.id > c.id))
               WHERE c.id = ? ORDER BY l.time, l.id""",
            [calibration_id],
        )
        return [self._cal_dict(r) for r in rows]

    def reference(self, device_id: str, procedure: str, before=None) -> dict | None:
        """The calibration in use: the device's latest accepted calibration of `procedure`
        (at or before `before` when given), the reference a new result is compared with.
        Rejected calibrations never are."""
        sql = "SELECT * FROM calibrations WHERE device_id = ? AND procedure = ? AND accepted = 1"
        args: list = [device_id, procedure]
        if before is not None:
            sql += " AND time <= ?"
            args.append(P.normalize_time(before))
        rows = self._query(sql + " ORDER BY time DESC, id DESC LIMIT 1", args)
        return self._cal_dict(rows[0]) if rows else None

    # --- settings -----------------------------------------------------------------------

    def settings(self) -> dict[str, str]:
        """The station's remembered entries (operator, place, reference equipment...)."""
        return {r["name"]: r["value"] for r in self._query("SELECT name, value FROM settings ORDER BY name")}

    def set_settings(self, values: dict) -> None:
        """Remember entries; a value of None or '' forgets that name."""
        with self._write() as conn:
            for name, value in values.items():
                if value is None or str(value) == "":
                    conn.execute("DELETE FROM settings WHERE name = ?", [str(name)])
                else:
                    conn.execute(
                        "INSERT OR REPLACE INTO settings (name, value, updated) VALUES (?, ?, ?)",
                        [str(name), str(value), P.iso(P.now_utc())],
                    )

    # --- drift and schedule -------------------------------------------------------------

    @staticmethod
    def _trends(rows, tolerances: dict, param: str | None = None, significant_only: bool = True) -> list[dict]:
        """Per (procedure, scalar) trend over accepted calibration rows sorted by time.

        ``leaves_tolerance`` only for a significant trend (`db.params.trend_verdict`);
        ``significant_only=False`` is the rule before migration 0005 (any rate), kept to
        tell a schedule it wrote from one edited by hand."""
        series: dict[tuple[str, str], dict] = {}
        for r in rows:
            values = P.flatten(_loads(r["params"]))
            sigmas = P.flatten(_loads(r["uncertainty"]))
            for name, value in values.items():
                if value is None or (param is not None and not P.matches(name, param)):
                    continue
                s = series.setdefault((r["procedure"], name), {"ids": [], "times": [], "values": [], "sigmas": []})
                s["ids"].append(r["id"])
                s["times"].append(r["time"])
                s["values"].append(value)
                s["sigmas"].append(sigmas.get(name))
        out = []
        for (procedure, name), s in series.items():
            dts = [P.parse_time(t) for t in s["times"]]
            t0 = dts[0]
            t_years = [P.years_between(t0, dt) for dt in dts]
            fit = P.linear_trend(t_years, s["values"], s["sigmas"])
            verdict = P.trend_verdict(fit)
            tol = P.tolerance_for(name, tolerances)
            leaves = None
            if tol is not None and fit["rate"] and (verdict["significant"] or not significant_only):
                years = tol / abs(fit["rate"])
                if years < MAX_PREDICTION_YEARS:  # beyond that: never, for any practical purpose
                    leaves = P.iso(dts[-1] + timedelta(days=years * P.DAYS_PER_YEAR))
            fitted_last = None
            if fit["rate"] is not None:
                fitted_last = fit["intercept"] + fit["rate"] * t_years[-1]
            out.append(
                {
                    "procedure": procedure,
                    "param": name,
                    "n": len(s["values"]),
                    "calibration_ids": s["ids"],
                    "times": s["times"],
                    "values": s["values"],
                    "sigmas": s["sigmas"],
                    "rate_per_year": fit["rate"],
                    "rate_sigma_per_year": fit["rate_sigma"],
                    "chi2_per_dof": fit["chi2_per_dof"],
                    "significance_sigmas": verdict["sigmas"],
                    "significance_threshold": verdict["threshold"],
                    "significant": verdict["significant"],
                    "verdict": verdict["why"],
                    "value_in_use": s["values"][-1],
                    "trend_value_at_last": fitted_last,
                    "tolerance": tol,
                    "leaves_tolerance": leaves,
                }
            )
        return out

    def drift(self, device_id: str, procedure: str | None = None, param: str | None = None) -> list[dict]:
        """Trend of every scalar parameter over the device's accepted calibrations.

        `param` selects one name (`B[0]`) or a block (`B`). Each entry: procedure,
        param, times, values, sigmas, rate_per_year, rate_sigma_per_year (weighted
        linear regression, see `db.params.linear_trend`), significance_sigmas
        (|rate| / its sigma), significance_threshold, significant and verdict (a short
        phrase; `db.params.trend_verdict`), tolerance and leaves_tolerance: when a
        significant trend carries the parameter `tolerance` away from its value in use
        (last calibration time + tolerance / |rate|), else None.
        """
        device = self.get_device(device_id)
        tolerances = device["tolerances"] if device else {}
        sql = "SELECT id, procedure, time, params, uncertainty FROM calibrations WHERE device_id = ? AND accepted = 1"
        args = [device_id]
        if procedure is not None:
            sql += " AND procedure = ?"
            args.append(procedure)
        rows = self._query(sql + " ORDER BY time, id", args)
        return self._trends(rows, tolerances, param)

    def _update_schedule(self, conn, device_id: str, procedure: str) -> None:
        """Recompute the schedule row of one (device, procedure), inside a write."""
        row = self._schedule_row(conn, device_id, procedure)
        if row is None:
            conn.execute("DELETE FROM schedule WHERE device_id = ? AND procedure = ?", [device_id, procedure])
            return
        conn.execute(
            f"INSERT OR REPLACE INTO schedule ({', '.join(SCHEDULE_COLUMNS)}) VALUES ({', '.join('?' * len(row))})",
            row,
        )

    def _schedule_row(self, conn, device_id: str, procedure: str, significant_only: bool = True) -> list | None:
        """The schedule row one (device, procedure) should have, from devices and calibrations,
        in `SCHEDULE_COLUMNS` order (None: no accepted calibration, no row). ``reason`` says why
        the due date is what it is: the interval and why drift did not move it, or the
        significant drift that brought it forward."""
        dev = conn.execute("SELECT interval_days, tolerances FROM devices WHERE id = ?", [device_id]).fetchone()
        last = conn.execute(
            """SELECT id, time FROM calibrations WHERE device_id = ? AND procedure = ? AND accepted = 1
               ORDER BY time DESC, id DESC LIMIT 1""",
            [device_id, procedure],
        ).fetchone()
        if last is None or dev is None:
            return None
        tolerances = _loads(dev["tolerances"], {})
        interval_due = None
        if dev["interval_days"]:
            interval_due = P.iso(P.parse_time(last["time"]) + timedelta(days=dev["interval_days"]))
        drift = None
        note = "no tolerances set, so drift does not move it"
        if tolerances:
            rows = conn.execute(
                """SELECT id, procedure, time, params, uncertainty FROM calibrations
                   WHERE device_id = ? AND procedure = ? AND accepted = 1 ORDER BY time, id""",
                [device_id, procedure],
            ).fetchall()
            judged = [t for t in self._trends(rows, tolerances, significant_only=significant_only) if t["tolerance"]]
            for t in judged:
                if t["leaves_tolerance"] and (drift is None or t["leaves_tolerance"] < drift["leaves_tolerance"]):
                    drift = t
            note = _drift_note(judged, len(rows))
        drift_due = drift["leaves_tolerance"] if drift else None
        due = min((d for d in (interval_due, drift_due) if d), default=None)
        since = last["time"][:10]
        if drift is not None and (interval_due is None or drift_due < interval_due):
            how = f"{drift['rate_per_year']:+.3g}"
            if drift["rate_sigma_per_year"] is not None:
                how += f" ± {drift['rate_sigma_per_year']:.2g}"
            if drift["significance_sigmas"] is not None:
                how += f"/year, {drift['significance_sigmas']:.1f}σ over {drift['n']} calibrations"
            reason = (
                f"{procedure}: drift of {drift['param']} ({how}) leaves its tolerance {drift['tolerance']:g} on "
                f"{drift_due[:10]} (last calibrated {since})"
            )
        else:
            if drift is not None:
                note = f"drift of {drift['param']} ({drift['verdict']}) leaves its tolerance only on {drift_due[:10]}"
            head = f"{procedure}: {dev['interval_days']:g}-day interval since {since} ends {due[:10]}" if due else ""
            reason = f"{head}; {note}" if head else f"{procedure}: no interval set; {note}"
        return [
            device_id,
            procedure,
            last["id"],
            last["time"],
            interval_due,
            drift_due,
            drift["param"] if drift else None,
            drift["rate_per_year"] if drift else None,
            due,
            reason,
        ]

    def rebuild_schedule(self) -> int:
        """Recompute every schedule row from devices and calibrations; returns the row count."""
        with self._write() as conn:
            conn.execute("DELETE FROM schedule")
            pairs = conn.execute("SELECT DISTINCT device_id, procedure FROM calibrations WHERE accepted = 1").fetchall()
            for device_id, procedure in pairs:
                self._update_schedule(conn, device_id, procedure)
        return len(pairs)

    def due(self, within_days: float = 0, now=None) -> list[dict]:
        """Devices due for recalibration by `now + within_days`, soonest first.

        A (device, procedure) is due at the end of the device's interval since its
        last accepted calibration, or earlier when a parameter's significant drift trend
        leaves its tolerance first (`db.params.trend_verdict`); a device with no accepted
        calibration is due now. Each reason's text says which rule set the date and, for
        the interval, why drift did not move it.
        Each entry: device_id, model, due (time or None for never calibrated),
        days_left (negative = overdue), status (`overdue`, `due`, `never calibrated`),
        reason (one line) and reasons (one dict per procedure).
        """
        now_dt = P.parse_time(now) if now is not None else P.now_utc()
        horizon = P.iso(now_dt + timedelta(days=float(within_days)))
        rows = self._query(
            """SELECT s.*, d.model, d.interval_days FROM schedule s JOIN devices d ON d.id = s.device_id
               WHERE s.due IS NOT NULL AND s.due <= ? ORDER BY s.due, s.device_id""",
            [horizon],
        )
        never = self._query(
            """SELECT id, model FROM devices d WHERE NOT EXISTS (SELECT 1 FROM schedule s WHERE s.device_id = d.id)
               ORDER BY id"""
        )
        devices: dict[str, dict] = {}
        for r in rows:
            due_dt = P.parse_time(r["due"])
            days_left = (due_dt - now_dt).total_seconds() / 86400.0
            by_drift = (
                r["drift_due"] is not None
                and r["drift_due"] == r["due"]
                and (r["interval_due"] is None or r["drift_due"] < r["interval_due"])
            )
            text = r["reason"]
            if not text:  # a row no station wrote (`verify` reports it)
                text = f"{r['procedure']}: due {r['due'][:10]} (last calibrated {r['last_calibrated'][:10]})"
            reason = {
                "procedure": r["procedure"],
                "kind": "drift" if by_drift else "interval",
                "due": r["due"],
                "days_left": days_left,
                "last_calibration_id": r["last_calibration_id"],
                "last_calibrated": r["last_calibrated"],
                "param": r["drift_param"] if by_drift else None,
                "text": text,
            }
            entry = devices.setdefault(
                r["device_id"],
                {
                    "device_id": r["device_id"],
                    "model": r["model"],
                    "due": r["due"],
                    "days_left": days_left,
                    "reasons": [],
                },
            )
            entry["reasons"].append(reason)
        out = list(devices.values())
        for e in out:
            e["status"] = "overdue" if e["days_left"] < 0 else "due"
            e["reason"] = "; ".join(x["text"] for x in e["reasons"])
        for r in never:
            out.append(
                {
                    "device_id": r["id"],
                    "model": r["model"],
                    "due": None,
                    "days_left": None,
                    "status": "never calibrated",
                    "reason": "no accepted calibration",
                    "reasons": [{"procedure": None, "kind": "never", "due": None, "text": "no accepted calibration"}],
                }
            )
        return out

    # --- integrity ----------------------------------------------------------------------

    # Tables and columns verify reads; a missing one is a damaged schema (reported, not a crash).
    _VERIFY_SCHEMA = {
        "devices": SETTINGS_COLUMNS + SETTINGS_COLUMNS_V2,  # the columns a device's settings hash covers
        "calibrations": (
            "id",
            "device_id",
            "procedure",
            "time",
            "accepted",
            "capture_id",
            "capture_sha256",
            "prev_hash",
            "hash",
            "params",
            "uncertainty",
        ),
        "captures": ("id", "device_id", "procedure", "time", "operator", "host", "meta", "sha256"),
        "capture_columns": ("capture_id", "ordinal", "name", "dtype", "length", "encoding", "data"),
        "schedule": SCHEDULE_COLUMNS,
        "anchors": ANCHOR_COLUMNS + ("hash",),
    }

    def _schema_problems(self) -> tuple[list[dict], set[str]]:
        problems, broken = [], set()
        for table, columns in self._VERIFY_SCHEMA.items():
            have = {r[1] for r in self._query(f"PRAGMA table_info({table})")}
            if not have:
                problems.append({"kind": "schema damaged", "detail": f"table {table!r} is missing"})
                broken.add(table)
                continue
            missing = [c for c in columns if c not in have]
            if missing:
                problems.append(
                    {
                        "kind": "schema damaged",
                        "detail": f"table {table!r} lacks column{'s' if len(missing) > 1 else ''} {', '.join(missing)}",
                    }
                )
                broken.add(table)
        return problems, broken

    def _issued(self, table: str) -> int | None:
        """The largest id AUTOINCREMENT has issued for ``table`` (sqlite_sequence), or None."""
        try:
            rows = self._query("SELECT seq FROM sqlite_sequence WHERE name = ?", [table])
        except sqlite3.Error:
            return None
        return int(rows[0][0]) if rows and rows[0][0] is not None else None

    def verify(self, check_captures: bool = True) -> list[dict]:
        """Records changed or removed after they were written; [] when all is well.

        Each problem: kind, detail, and calibration_id / capture_id / device_id where one
        applies. Kinds: `schema damaged`, `tampered`, `chain broken` (a device's calibration
        chain), `capture changed`, `anchor tampered`, `anchors removed`, `calibration removed`
        (a chain head or the newest records: the anchors or the id counter remember them),
        `device removed`, `device added` (outside the station), `settings changed` (model,
        notes, interval, tolerances, limits), `schedule changed` (differs from the one recomputed from
        the calibrations), `orphaned capture`, `capture missing`. Findings that follow from
        an earlier one on the same device (its schedule after an edited calibration) are not
        repeated.
        """
        problems, broken = self._schema_problems()
        flagged: set = set()  # devices with a primary problem: derived checks say nothing more
        capture_refs = {}
        heads: dict[str, tuple[int, str, int]] = {}  # device -> (last id, its hash, count)
        if "calibrations" not in broken:
            with self._lock:
                cur = self.conn.execute("SELECT * FROM calibrations ORDER BY device_id, id")
                prev_device, prev_hash = object(), None
                for row in cur:
                    d = dict(row)
                    if d["device_id"] != prev_device:
                        prev_device, prev_hash = d["device_id"], None
                    if record_hash(d) != d["hash"]:
                        flagged.add(d["device_id"])
                        problems.append(
                            {
                                "kind": "tampered",
                                "calibration_id": d["id"],
                                "device_id": d["device_id"],
                                "detail": "its content no longer matches the hash written with it",
                            }
                        )
                    if d["prev_hash"] != prev_hash:
                        flagged.add(d["device_id"])
                        problems.append(
                            {
                                "kind": "chain broken",
                                "calibration_id": d["id"],
                                "device_id": d["device_id"],
                                "detail": "the record before it in this device's history was removed, added or changed",
                            }
                        )
                    prev_hash = d["hash"]
                    n = heads.get(d["device_id"], (0, "", 0))[2] + 1
                    heads[d["device_id"]] = (d["id"], d["hash"], n)
                    if d["capture_id"] is not None:
                        capture_refs[d["capture_id"]] = (d["id"], d["device_id"], d["capture_sha256"])
        counter = None
        if "calibrations" not in broken:
            issued = self._issued("calibrations")
            top = max((h[0] for h in heads.values()), default=0)
            if issued is not None and issued > top:
                counter = {
                    "kind": "calibration removed",
                    "calibration_id": issued,
                    "detail": f"calibration ids were issued up to {issued} but the newest present is "
                    f"{top or 'none'}: the newest records were removed",
                }
        if not broken & {"anchors", "devices", "calibrations"}:
            found = self._verify_anchors(heads, flagged)
            problems.extend(found)
            if counter and any(p.get("calibration_id") == counter["calibration_id"] for p in found):
                counter = None  # the anchors already name it, with its device
        if counter:
            problems.append(counter)
        if not broken & {"schedule", "devices", "calibrations"}:
            problems.extend(self._verify_schedule(flagged))
        if check_captures and not broken & {"captures", "capture_columns", "calibrations"}:
            problems.extend(self._verify_captures(capture_refs))
            problems.extend(self._verify_orphans(capture_refs, "anchors" not in broken))
        keys = ("kind", "calibration_id", "capture_id", "device_id", "detail")
        return [{k: p.get(k) for k in keys} | p for p in problems]

    def _verify_anchors(self, heads: dict, flagged: set) -> list[dict]:
        problems = []
        rows = [dict(r) for r in self._query("SELECT * FROM anchors ORDER BY id")]
        prev = None
        for a in rows:
            if anchor_hash(a) != a["hash"]:
                problems.append(
                    {
                        "kind": "anchor tampered",
                        "device_id": a["device_id"],
                        "detail": f"anchor {a['id']} no longer matches the hash written with it",
                    }
                )
                flagged.add(a["device_id"])
            if a["prev_hash"] != prev:
                problems.append(
                    {
                        "kind": "anchors removed",
                        "device_id": a["device_id"],
                        "detail": f"the anchor before anchor {a['id']} was removed, added or changed",
                    }
                )
            prev = a["hash"]
        issued = self._issued("anchors")
        if issued is not None and issued > (rows[-1]["id"] if rows else 0):
            problems.append(
                {
                    "kind": "anchors removed",
                    "detail": f"anchor ids were issued up to {issued} but the newest present is "
                    f"{rows[-1]['id'] if rows else 'none'}: the newest anchors were removed",
                }
            )
        latest: dict[str, dict] = {}
        for a in rows:
            latest[a["device_id"]] = a
        devices = {r["id"]: dict(r) for r in self._query("SELECT * FROM devices")}
        for device_id, a in latest.items():
            dev = devices.get(device_id)
            if dev is None:
                problems.append(
                    {
                        "kind": "device removed",
                        "device_id": device_id,
                        "detail": "the device and its record were deleted from the devices table",
                    }
                )
                continue
            if device_id in flagged:
                continue
            head = heads.get(device_id)
            have_id, have_hash, have_n = head if head else (None, None, 0)
            if (a["head_id"], a["head_hash"]) != (have_id, have_hash) or a["n_calibrations"] != have_n:
                gone = a["head_id"] is not None and (have_id is None or have_id < a["head_id"])
                problems.append(
                    {
                        "kind": "calibration removed" if gone or have_n < a["n_calibrations"] else "chain broken",
                        "calibration_id": a["head_id"],
                        "device_id": device_id,
                        "detail": f"the anchors record {a['n_calibrations']} calibration(s) ending with "
                        f"#{a['head_id']}; the table holds {have_n}"
                        + (f" ending with #{have_id}" if have_id is not None else ""),
                    }
                )
                flagged.add(device_id)
            if settings_hash(dev, settings_version(a["settings_hash"])) != a["settings_hash"]:
                problems.append(
                    {
                        "kind": "settings changed",
                        "device_id": device_id,
                        "detail": "model, notes, interval, tolerances or limits differ from what the station "
                        "last wrote (changed outside `station devices add` and the TUI)",
                    }
                )
                flagged.add(device_id)
        for device_id in devices:
            if device_id not in latest:
                problems.append(
                    {
                        "kind": "device added",
                        "device_id": device_id,
                        "detail": "the device has no anchor: it was added outside the station",
                    }
                )
                flagged.add(device_id)
        return problems

    def _verify_schedule(self, flagged: set) -> list[dict]:
        """The stored schedule against the one recomputed from devices and calibrations."""
        problems = []
        with self._lock:
            stored = {
                (r["device_id"], r["procedure"]): list(r)
                for r in self.conn.execute(f"SELECT {', '.join(SCHEDULE_COLUMNS)} FROM schedule")
            }
            pairs = self.conn.execute(
                "SELECT DISTINCT device_id, procedure FROM calibrations WHERE accepted = 1"
            ).fetchall()
            try:
                expected = {(d, p): self._schedule_row(self.conn, d, p) for d, p in pairs}
            except (ValueError, TypeError, KeyError):  # an edited record the trend cannot read: reported above
                return problems
        expected = {k: v for k, v in expected.items() if v is not None}

        for key in sorted(set(stored) | set(expected), key=lambda k: (str(k[0]), str(k[1]))):
            if key[0] in flagged:
                continue
            have, want = stored.get(key), expected.get(key)
            if have is not None and want is not None and _same_row(have, want):
                continue
            detail = (
                f"{key[1]}: stored due {have[8] if have else 'none'}, the calibrations give "
                f"{want[8] if want else 'none'}"
            )
            problems.append({"kind": "schedule changed", "device_id": key[0], "detail": detail})
        return problems

    def _verify_orphans(self, capture_refs: dict, anchors_ok: bool) -> list[dict]:
        problems = []
        standalone = set()
        if anchors_ok:
            standalone = {r[0] for r in self._query("SELECT capture_id FROM anchors WHERE event = 'capture'")}
        for r in self._query("SELECT id, device_id FROM captures ORDER BY id"):
            if r["id"] in capture_refs or r["id"] in standalone:
                continue
            problems.append(
                {
                    "kind": "orphaned capture",
                    "capture_id": r["id"],
                    "device_id": r["device_id"],
                    "detail": "no calibration refers to it: the calibration saved with it was removed",
                }
            )
        present = {r[0] for r in self._query("SELECT id FROM captures")}
        for capture_id, (cal_id, device_id, _) in sorted(capture_refs.items()):
            if capture_id not in present:
                problems.append(
                    {
                        "kind": "capture missing",
                        "capture_id": capture_id,
                        "calibration_id": cal_id,
                        "device_id": device_id,
                        "detail": "the capture this calibration was made from is gone",
                    }
                )
        return problems

    def _verify_captures(self, capture_refs: dict) -> list[dict]:
        problems = []
        ids = [r[0] for r in self._query("SELECT id FROM captures ORDER BY id")]
        for capture_id in ids:
            row, cols = self._read_capture(capture_id)
            header = {k: row[k] for k in ("device_id", "procedure", "time", "operator", "host", "meta")}
            try:
                digests = []
                for c in cols:
                    _, sha = decode_column(c["dtype"], c["length"], c["encoding"], c["data"])
                    digests.append((c["name"], c["dtype"], c["length"], sha))
                actual = capture_digest(header, digests)
            except Exception as exc:  # undecodable BLOB: changed
                actual = f"unreadable ({exc})"
            ref = capture_refs.get(capture_id)
            if actual != row["sha256"] or (ref is not None and ref[2] != row["sha256"]):
                problems.append(
                    {
                        "kind": "capture changed",
                        "capture_id": capture_id,
                        "calibration_id": ref[0] if ref else None,
                        "device_id": row["device_id"],
                        "detail": "its samples or metadata no longer match the digest written with them",
                    }
                )
        return problems

    def counts(self) -> dict:
        """Number of devices, captures and calibrations."""
        r = self._query(
            "SELECT (SELECT count(*) FROM devices) AS devices, (SELECT count(*) FROM captures) AS captures,"
            " (SELECT count(*) FROM calibrations) AS calibrations"
        )[0]
        return dict(r)

    def integrity_check(self) -> str:
        """SQLite's own `PRAGMA integrity_check` ('ok' when the file is sound)."""
        return "\n".join(r[0] for r in self._query("PRAGMA integrity_check"))


def _samples_digest(meta_text: str, encoded: list[dict]) -> str:
    """sha256 of a capture's metadata JSON and its columns (name, dtype, length, raw sha256):
    the same measurement has the same digest whoever saves it, wherever and whenever."""
    return capture_digest({"meta": meta_text}, [(c["name"], c["dtype"], c["length"], c["sha256"]) for c in encoded])


def _check_limit(name, value) -> list:
    """[low, high] from a pair (either end None = open), or [low, high, unit] from a triple whose
    third item names the unit of the two (text); low <= high."""
    try:
        low, high, *unit = value
        low = None if low is None else float(low)
        high = None if high is None else float(high)
        if len(unit) > 1 or (unit and not (isinstance(unit[0], str) and unit[0].strip())):
            raise ValueError
    except (TypeError, ValueError):
        raise ValueError(f"limit {name!r} must be a pair (low, high) or (low, high, unit), got {value!r}") from None
    if (low is None and high is None) or any(x is not None and x != x for x in (low, high)):
        raise ValueError(f"limit {name!r} needs at least one finite end, got {value!r}")
    if low is not None and high is not None and low > high:
        raise ValueError(f"limit {name!r}: low {low:g} is above high {high:g}")
    return [low, high, *unit]
