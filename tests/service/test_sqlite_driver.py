"""SQLite statements run on the driver's own connection (`sqlite_execute`: the append and the
BEGIN of every transaction) raise what SQLAlchemy's error handling would have raised."""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Any

import pytest
import sqlalchemy as sa

from core.params import Params
from service.store.engine import make_engine, migrate, sqlite_execute, write_transaction
from service.store.errors import StoreUnavailable
from service.store.event_log import EventLog
from tests.service.minimal_events import added


def impatient_engine(path: Path) -> sa.Engine:
    """A migrated SQLite engine that waits 50 ms for a lock instead of 30 s."""
    engine = make_engine(f"sqlite:///{path}")

    @sa.event.listens_for(engine, "connect")
    def _impatient(dbapi_connection: Any, _record: Any) -> None:
        dbapi_connection.execute("PRAGMA busy_timeout=50")

    migrate(engine)
    return engine


def test_a_write_lock_held_too_long_is_store_unavailable_and_nothing_is_appended(
    tmp_path: Path,
) -> None:
    engine = impatient_engine(tmp_path / "pbdag.db")
    log = EventLog(engine)
    with write_transaction(engine) as connection:
        scene, _created = log.insert_scene(connection, "s", Params())
    other = sqlite3.connect(tmp_path / "pbdag.db", isolation_level=None)
    try:
        other.execute("BEGIN IMMEDIATE")  # another process holds the write lock
        with pytest.raises(StoreUnavailable) as raised, write_transaction(engine) as connection:
            log.append(connection, scene.id, 0, [added("trk-1")])
        assert isinstance(raised.value.__cause__, sa.exc.OperationalError)
        assert "locked" in str(raised.value.__cause__)
        other.execute("ROLLBACK")
        assert [event.seq for event in log.read(scene.id)] == [0]
        with write_transaction(engine) as connection:  # the lock released: the append goes in
            assert log.append(connection, scene.id, 0, [added("trk-1")]) == (1, 1)
    finally:
        other.close()
        engine.dispose()


def test_an_error_that_cannot_pass_keeps_sqlalchemys_class_and_the_driver_cause(
    tmp_path: Path,
) -> None:
    engine = impatient_engine(tmp_path / "pbdag.db")
    try:
        with write_transaction(engine) as connection:
            row = ("scn-1", "s", "{}", 0, 0.0, None)
            insert = "INSERT INTO scenes VALUES (?, ?, ?, ?, ?, ?)"
            sqlite_execute(connection, insert, row)
            with pytest.raises(sa.exc.IntegrityError) as raised:
                sqlite_execute(connection, insert, [row], many=True)
        assert isinstance(raised.value.orig, sqlite3.IntegrityError)
        assert isinstance(raised.value.__cause__, sqlite3.IntegrityError)
    finally:
        engine.dispose()
