"""Wire every concrete part in one place; tests pass an in-memory blob store or a temp SQLite file."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import sqlalchemy as sa

from service.metrics import Metrics
from service.settings import Settings, SettingsError
from service.store.blobs import BlobStore, FileBlobStore, PgBlobStore
from service.store.engine import is_postgres, make_engine, migrate
from service.store.event_log import EventLog
from service.store.queue import BatchQueue
from service.store.unit_of_work import UnitOfWork


@dataclass
class Container:
    """The service's parts, built once per process."""

    settings: Settings
    engine: sa.Engine
    log: EventLog
    queue: BatchQueue
    blobs: BlobStore
    uow: UnitOfWork  # the one write path of the log
    metrics: Metrics  # this process's Prometheus registry


def build_container(
    settings: Settings | None = None,
    *,
    blobs: BlobStore | None = None,
    engine: sa.Engine | None = None,
    clock: Callable[[], float] = time.time,
    migrate_schema: bool = True,
) -> Container:
    """Engine, schema, event log, queue and blob store from the settings."""
    settings = settings or Settings()
    engine = engine or make_engine(settings.resolved_database_url())
    blobs = blobs or blob_store(settings, engine)  # before migrating: a wrong choice stops here
    if migrate_schema:
        migrate(engine)
    log = EventLog(engine, clock)
    queue = BatchQueue(engine, blobs, clock)
    metrics = Metrics(queue, clock)
    return Container(
        settings=settings,
        engine=engine,
        log=log,
        queue=queue,
        blobs=blobs,
        uow=UnitOfWork(engine, log, queue, settings.snapshot_interval, metrics.events_appended.inc),
        metrics=metrics,
    )


def blob_store(settings: Settings, engine: sa.Engine) -> BlobStore:
    """The blob backend PBDAG_BLOB_BACKEND names (auto: PostgreSQL's table on PostgreSQL, the
    folder on SQLite); SettingsError for a table asked of a database that is not PostgreSQL."""
    choice = settings.blob_backend
    if choice == "postgres" and not is_postgres(engine):
        raise SettingsError(
            f"PBDAG_BLOB_BACKEND=postgres needs a PostgreSQL database, but the database is "
            f"{engine.dialect.name} (PBDAG_DATABASE_URL); set PBDAG_BLOB_BACKEND=folder or auto, "
            "or point PBDAG_DATABASE_URL at PostgreSQL"
        )
    if choice == "postgres" or (choice == "auto" and is_postgres(engine)):
        return PgBlobStore(engine)
    return FileBlobStore(settings.data_dir / "blobs")
