"""Wire every concrete part in one place; tests pass an in-memory blob store or a temp SQLite file."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import sqlalchemy as sa

from service.metrics import Metrics
from service.settings import Settings
from service.store.blobs import BlobStore, FileBlobStore
from service.store.engine import make_engine, migrate
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
    if migrate_schema:
        migrate(engine)
    log = EventLog(engine, clock)
    queue = BatchQueue(engine, clock)
    metrics = Metrics(queue, clock)
    return Container(
        settings=settings,
        engine=engine,
        log=log,
        queue=queue,
        blobs=blobs or FileBlobStore(settings.data_dir / "blobs"),
        uow=UnitOfWork(engine, log, queue, settings.snapshot_interval, metrics.events_appended.inc),
        metrics=metrics,
    )
