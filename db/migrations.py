"""Apply `db.schema.MIGRATIONS` with sqlite-utils' `Migrations` (recorded in `_sqlite_migrations`).

Imported only when a migration is pending: sqlite-utils pulls in pandas when it is
installed, which costs a third of a second at start-up.
"""

from __future__ import annotations

import sqlite3

from sqlite_utils import Database, Migrations

from db.schema import MIGRATION_SET, MIGRATIONS


def _build() -> Migrations:
    migrations = Migrations(MIGRATION_SET)
    for name, statements in MIGRATIONS:

        def run(db: Database, statements=statements) -> None:
            for sql in statements:
                db.execute(sql)

        run.__name__ = name
        migrations(name=name)(run)
    return migrations


STATION_MIGRATIONS = _build()


def apply(conn: sqlite3.Connection, post=None) -> list[str]:
    """Apply pending migrations under one write lock; returns the names applied.

    `BEGIN IMMEDIATE` first, so two processes opening a fresh database at once take
    turns: the second finds nothing pending (sqlite-utils' own `apply` would nest
    its per-migration transactions inside ours as savepoints). ``post(conn, names)`` runs
    inside the same transaction after the SQL.
    """
    db = Database(conn)
    conn.execute("BEGIN IMMEDIATE")
    try:
        names = [m.name for m in STATION_MIGRATIONS.pending(db)]
        STATION_MIGRATIONS.apply(db)
        if post is not None:  # data steps that need Python (e.g. the first anchors), same transaction
            post(conn, names)
    except BaseException:
        if conn.in_transaction:
            conn.execute("ROLLBACK")
        raise
    conn.execute("COMMIT")
    return names
