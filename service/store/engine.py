"""Engines for SQLite (WAL, BEGIN IMMEDIATE for writes) and PostgreSQL (psycopg 3), migration,
and the contexts reads and writes run in.

The engine is the store's adapter to the drivers: a driver error that may pass (a lost
connection, a lock held too long) leaves it as the store's own `StoreUnavailable`, so nothing above
the store knows SQLAlchemy's exception classes.
"""

from __future__ import annotations

import gc
import sqlite3
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import sqlalchemy as sa
from alembic import command
from alembic.config import Config

from service.store.errors import StoreUnavailable

MIGRATIONS_DIR = Path(__file__).resolve().parents[2] / "migrations"
IMMEDIATE = "pbdag_immediate"
WAL_CHECKPOINT_PAGES = 10_000  # about 40 MB of WAL between automatic checkpoints (4 kB pages)


def make_engine(url: str, **kwargs: Any) -> sa.Engine:
    """An engine with the house settings for its backend, translating the errors that may pass."""
    if url.startswith("sqlite"):
        engine = _sqlite_engine(url, **kwargs)
    else:
        engine = sa.create_engine(url, pool_pre_ping=True, **kwargs)
    sa.event.listen(engine, "handle_error", _translated)
    return engine


def may_pass(error: BaseException) -> bool:
    """Whether a driver error may pass on a later attempt: the database unavailable, a lock held
    too long (OperationalError), the connection itself broken (InterfaceError)."""
    return isinstance(error, sa.exc.OperationalError | sa.exc.InterfaceError)


def _translated(context: sa.engine.ExceptionContext) -> BaseException | None:
    """SQLAlchemy's `handle_error` hook: the exception to raise instead of a driver error that may
    pass (None keeps SQLAlchemy's own: an integrity or programming error is no passing failure).
    A pool's liveness probe keeps SQLAlchemy's, which the pool handles itself."""
    error = context.sqlalchemy_exception
    if context.is_pre_ping or error is None or not may_pass(error):
        return None
    return StoreUnavailable("the database", error)  # SQLAlchemy chains the driver's as its cause


def _sqlite_engine(url: str, **kwargs: Any) -> sa.Engine:
    database = sa.make_url(url).database
    if database and database != ":memory:":
        Path(database).parent.mkdir(parents=True, exist_ok=True)
    engine = sa.create_engine(
        url, connect_args={"check_same_thread": False, "timeout": 30}, **kwargs
    )

    @sa.event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection: Any, _record: Any) -> None:
        # Let SQLAlchemy's BEGIN below be the only transaction start (pysqlite would defer it).
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        cursor.execute("PRAGMA journal_mode=WAL")
        cursor.execute("PRAGMA synchronous=FULL")  # an acknowledged batch survives a crash
        # Copy the WAL back into the database every WAL_CHECKPOINT_PAGES pages rather than
        # SQLite's 1000: an append dirties a leaf of the per-track index for each track it
        # touches, and a checkpoint writes (and syncs) each page once however often it changed.
        # Durability is unchanged: every commit still syncs the WAL.
        cursor.execute(f"PRAGMA wal_autocheckpoint={WAL_CHECKPOINT_PAGES}")
        cursor.execute("PRAGMA busy_timeout=30000")
        cursor.execute("PRAGMA foreign_keys=ON")
        cursor.close()

    @sa.event.listens_for(engine, "begin")
    def _on_begin(connection: sa.Connection) -> None:
        # A deferred transaction that reads then writes fails with SQLITE_BUSY under concurrency
        # and busy_timeout does not help; writers take the lock up front.
        immediate = connection.get_execution_options().get(IMMEDIATE, False)
        sqlite_execute(connection, "BEGIN IMMEDIATE" if immediate else "BEGIN")

    return engine


def sqlite_execute(
    connection: sa.Connection, statement: str, parameters: Sequence[Any] = (), many: bool = False
) -> sqlite3.Cursor:
    """Run `statement` on SQLite's own connection (executemany with `many`), without
    SQLAlchemy's execution machinery: about 25 us a statement, as much as the rest of a one-event
    append's CPU. A driver error is raised as SQLAlchemy's `handle_error` hook would have it:
    StoreUnavailable when it may pass (a lock held too long), SQLAlchemy's own error otherwise."""
    driver: Any = connection.connection.driver_connection  # the sqlite3 connection
    cursor: sqlite3.Cursor = driver.cursor()
    try:
        if many:
            cursor.executemany(statement, parameters)
        else:
            cursor.execute(statement, parameters)
    except sqlite3.Error as error:
        wrapped = sa.exc.DBAPIError.instance(statement, parameters, error, sqlite3.Error)
        if may_pass(wrapped):
            raise StoreUnavailable("the database", wrapped) from wrapped
        raise wrapped from error
    return cursor


def is_sqlite(engine: sa.Engine) -> bool:
    """True for the embedded SQLite backend."""
    return engine.dialect.name == "sqlite"


def is_postgres(engine: sa.Engine) -> bool:
    """True for PostgreSQL."""
    return engine.dialect.name == "postgresql"


@contextmanager
def write_transaction(engine: sa.Engine) -> Iterator[sa.Connection]:
    """One short write transaction (BEGIN IMMEDIATE on SQLite); commits or rolls back."""
    with engine.connect().execution_options(**{IMMEDIATE: True}) as connection, connection.begin():
        yield connection


@contextmanager
def read_transaction(engine: sa.Engine) -> Iterator[sa.Connection]:
    """A read-only transaction (a consistent view within it)."""
    with engine.connect() as connection, connection.begin():
        yield connection


MIGRATION_LOCK_KEY = 0x70626461  # PostgreSQL advisory lock held while migrating


def migrate(engine: sa.Engine) -> None:
    """Bring the schema to the newest Alembic revision; safe when several processes start at once."""
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    # SQLite: alembic's transaction begins IMMEDIATE; PostgreSQL: an advisory lock serializes.
    with engine.connect().execution_options(**{IMMEDIATE: True}) as connection:
        if not is_sqlite(engine):
            connection.execute(
                sa.text("SELECT pg_advisory_lock(:key)"), {"key": MIGRATION_LOCK_KEY}
            )
            connection.commit()
        try:
            config.attributes["connection"] = connection
            command.upgrade(config, "head")
            if connection.in_transaction():
                connection.commit()
        finally:
            if not is_sqlite(engine):
                connection.execute(
                    sa.text("SELECT pg_advisory_unlock(:key)"), {"key": MIGRATION_LOCK_KEY}
                )
                connection.commit()


@contextmanager
def gc_paused() -> Iterator[None]:
    """No cyclic collection while a state is decoded and folded.

    That work allocates thousands of acyclic tuples and dicts; in a long-running process each
    allocation burst can trigger a gen-2 pass over the whole heap (as_of p90 133 ms -> 32 ms).
    Collections are only deferred: the collector resumes afterwards.
    """
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()
