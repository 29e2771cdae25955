"""The station database: devices, captures, calibrations, drift (SQLite via sqlite-utils).

Entry point: `db.store.Store` (re-exported here). Never imports `station` or `textual`.
"""

from __future__ import annotations

from db.store import NotFound, Store, default_db_path

__all__ = ["NotFound", "Store", "default_db_path"]
