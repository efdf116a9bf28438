"""The appenders `python -m bench.bench_store versus` compares: our log append and the
application recorder of the `eventsourcing` library (the `bench` extra), on the same events."""

from __future__ import annotations

import time
import uuid
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import orjson
import sqlalchemy as sa

from core.events import Event
from core.params import Params
from service.store.engine import is_sqlite, write_transaction
from service.store.event_log import EventLog, SceneRecord


def new_scene(log: EventLog) -> SceneRecord:
    """An empty scene with the default parameters."""
    with write_transaction(log.engine) as connection:
        return log.insert_scene(connection, "bench", Params())[0]


VERSUS_BATCHES = (1, 20, 500)
VERSUS_EVENTS = {1: 300, 20: 3000, 500: 15000}  # events per measurement, by batch size


class OurAppender:
    """Our log append: the expected-head update and the event rows in one write transaction."""

    name = "ours"

    def __init__(self, engine: sa.Engine) -> None:
        self.log = EventLog(engine)
        self.scene_id = new_scene(self.log).id
        self.head = 0

    def append(self, chunk: Sequence[Event]) -> None:
        with write_transaction(self.log.engine) as connection:
            self.log.append(connection, self.scene_id, self.head, chunk)
        self.head += len(chunk)

    def durability(self) -> str:
        """The settings a commit's durability depends on, as the appending connection has them."""
        with write_transaction(self.log.engine) as connection:
            driver: Any = connection.connection.driver_connection
            if is_sqlite(self.log.engine):
                return sqlite_durability(driver.cursor())
            return postgres_durability(driver.cursor())

    def close(self) -> None:
        """Nothing to release (the engine belongs to the caller)."""


class TheirAppender:
    """`eventsourcing`'s application recorder, the same JSON as its state.

    One aggregate for the whole stream (the library's fastest case), or, with `per_track`, one
    aggregate per track: then its primary key (aggregate, version) indexes each track's history
    as our `(scene_id, track_id, seq)` index does, and costs the same random b-tree inserts.
    """

    def __init__(self, engine: sa.Engine, folder: Path, per_track: bool = False) -> None:
        from eventsourcing.persistence import ApplicationRecorder
        from eventsourcing.postgres import PostgresApplicationRecorder, PostgresDatastore
        from eventsourcing.sqlite import SQLiteApplicationRecorder, SQLiteDatastore

        self.datastore: SQLiteDatastore | PostgresDatastore
        self.recorder: ApplicationRecorder
        self.name = "eventsourcing per track" if per_track else "eventsourcing"
        self.per_track = per_track
        if is_sqlite(engine):
            filename = "eventsourcing-per-track.db" if per_track else "eventsourcing.db"
            self.datastore = SQLiteDatastore(str(folder / filename))
            self.recorder = SQLiteApplicationRecorder(self.datastore)
        else:
            url = engine.url
            with engine.connect() as connection:
                schema = str(connection.execute(sa.text("select current_schema()")).scalar())
            self.datastore = PostgresDatastore(
                dbname=url.database or "postgres",
                host=url.host or "127.0.0.1",
                port=url.port or 5432,
                user=url.username or "postgres",
                password=url.password or "",
                schema=schema,
            )
            self.recorder = PostgresApplicationRecorder(
                self.datastore,
                events_table_name="stored_events_per_track" if per_track else "stored_events",
            )
        self.recorder.create_table()
        self.scene = uuid.uuid4()
        self.originators: dict[str | None, uuid.UUID] = {}
        self.versions: dict[uuid.UUID, int] = {}

    def _next(self, event: Event) -> tuple[uuid.UUID, int]:
        """The event's aggregate and its next version."""
        originator = self.scene
        if self.per_track and event.track_id is not None:
            originator = self.originators.setdefault(event.track_id, uuid.uuid4())
        version = self.versions.get(originator, 0) + 1
        self.versions[originator] = version
        return originator, version

    def append(self, chunk: Sequence[Event]) -> None:
        from eventsourcing.persistence import StoredEvent

        stored = []
        for event in chunk:
            originator, version = self._next(event)
            stored.append(
                StoredEvent(
                    originator_id=originator,
                    originator_version=version,
                    topic=event.topic,
                    state=orjson.dumps(event.details()),
                )
            )
        self.recorder.insert_events(stored)

    def durability(self) -> str:
        """The settings a commit's durability depends on, as the recorder's writer has them."""
        from eventsourcing.postgres import PostgresDatastore

        if isinstance(self.datastore, PostgresDatastore):
            with self.datastore.get_connection() as connection, connection.cursor() as cursor:
                return postgres_durability(cursor)
        with self.datastore.transaction(commit=True) as cursor:
            return sqlite_durability(cursor)

    def close(self) -> None:
        """Close the recorder's connection pool."""
        self.datastore.close()


def sqlite_durability(cursor: Any) -> str:
    """journal_mode and synchronous (2 is FULL) of a SQLite connection."""
    cursor.execute("PRAGMA journal_mode")
    journal = cursor.fetchone()[0]
    cursor.execute("PRAGMA synchronous")
    return f"journal_mode={journal} synchronous={cursor.fetchone()[0]}"


def postgres_durability(cursor: Any) -> str:
    """fsync, synchronous_commit and full_page_writes of a PostgreSQL session."""
    settings = []
    for name in ("fsync", "synchronous_commit", "full_page_writes"):
        cursor.execute(f"SHOW {name}")
        row = cursor.fetchone()
        settings.append(f"{name}={row[name] if isinstance(row, dict) else row[0]}")
    return " ".join(settings)


def ratio_range(ours: Sequence[float], theirs: Sequence[float]) -> tuple[float, float]:
    """The lowest and highest of the rounds' ratios (the rounds are paired: interleaved)."""
    ratios = [mine / peer for mine, peer in zip(ours, theirs, strict=True)]
    return min(ratios), max(ratios)


def appended_per_second(
    appender: OurAppender | TheirAppender, stream: list[Event], batch: int
) -> float:
    """Events per second appending `stream` in batches of `batch`, one transaction per batch."""
    chunks = [stream[start : start + batch] for start in range(0, len(stream), batch)]
    started = time.perf_counter()
    for chunk in chunks:
        appender.append(chunk)
    return len(stream) / (time.perf_counter() - started)
