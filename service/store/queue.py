"""The batch queue: durable jobs, leased claims, arrival order per scene, fenced completion."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import sqlalchemy as sa

from service.store.engine import read_transaction, write_transaction
from service.store.errors import BatchConflict, LeaseLost
from service.store.tables import batches

CLAIMABLE = ("queued", "failed")  # failed: an attempt failed, the batch waits for a retry
UNFINISHED = ("queued", "failed", "running")  # these hold back later batches of the scene


@dataclass(frozen=True)
class BatchRecord:
    """One row of the queue."""

    id: int
    scene_id: str
    batch_id: str
    content_sha256: str
    blob_key: str
    frame_count: int
    status: str
    attempts: int
    lease_owner: str | None
    lease_until: float | None
    error: str | None
    first_seq: int | None
    last_seq: int | None
    received_at: float
    finished_at: float | None


@dataclass(frozen=True)
class Claim:
    """A batch leased to one worker."""

    id: int
    scene_id: str
    batch_id: str
    blob_key: str
    owner: str
    attempts: int


def held_by(claim: Claim) -> sa.ColumnElement[bool]:
    """The lease fence: the batch is still running under this claim's owner."""
    return sa.and_(
        batches.c.id == claim.id,
        batches.c.lease_owner == claim.owner,
        batches.c.status == "running",
    )


def _record(row: sa.Row[Any]) -> BatchRecord:
    return BatchRecord(**{column.name: row._mapping[column.name] for column in batches.columns})


class BatchQueue:
    """The job queue on one engine; `clock` is injectable so tests can expire leases."""

    def __init__(self, engine: sa.Engine, clock: Callable[[], float] = time.time) -> None:
        self.engine = engine
        self.clock = clock

    def submit(
        self, scene_id: str, batch_id: str, content_sha256: str, blob_key: str, frame_count: int
    ) -> tuple[BatchRecord, bool]:
        """Queue a batch; (record, True) when new, the original when re-posted with equal content."""
        with write_transaction(self.engine) as connection:
            existing = self._get(connection, scene_id, batch_id)
            if existing is not None:
                if existing.content_sha256 != content_sha256:
                    raise BatchConflict(
                        f"batch {batch_id!r} was already posted with different content"
                    )
                return existing, False
            connection.execute(
                batches.insert().values(
                    scene_id=scene_id,
                    batch_id=batch_id,
                    content_sha256=content_sha256,
                    blob_key=blob_key,
                    frame_count=frame_count,
                    status="queued",
                    attempts=0,
                    received_at=self.clock(),
                )
            )
            created = self._get(connection, scene_id, batch_id)
        assert created is not None
        return created, True

    def get(self, scene_id: str, batch_id: str) -> BatchRecord | None:
        """The batch's record, or None."""
        with read_transaction(self.engine) as connection:
            return self._get(connection, scene_id, batch_id)

    def _get(self, connection: sa.Connection, scene_id: str, batch_id: str) -> BatchRecord | None:
        row = connection.execute(
            sa.select(batches).where(batches.c.scene_id == scene_id, batches.c.batch_id == batch_id)
        ).first()
        return None if row is None else _record(row)

    def claim(self, owner: str, lease_seconds: float) -> Claim | None:
        """Lease the oldest claimable batch that is the first unfinished one of its scene."""
        earlier = batches.alias("earlier")
        first_of_scene = ~sa.exists().where(
            earlier.c.scene_id == batches.c.scene_id,
            earlier.c.id < batches.c.id,
            earlier.c.status.in_(UNFINISHED),
        )
        pick = (
            sa.select(batches.c.id)
            .where(batches.c.status.in_(CLAIMABLE), first_of_scene)
            .order_by(batches.c.id)
            .limit(1)
            .with_for_update(skip_locked=True)  # PostgreSQL; SQLite serializes via BEGIN IMMEDIATE
        )
        with write_transaction(self.engine) as connection:
            batch_row_id = connection.execute(pick).scalar()
            if batch_row_id is None:
                return None
            row = connection.execute(
                sa.update(batches)
                .where(batches.c.id == batch_row_id, batches.c.status.in_(CLAIMABLE))
                .values(
                    status="running",
                    lease_owner=owner,
                    lease_until=self.clock() + lease_seconds,
                    attempts=batches.c.attempts + 1,
                )
                .returning(
                    batches.c.id,
                    batches.c.scene_id,
                    batches.c.batch_id,
                    batches.c.blob_key,
                    batches.c.attempts,
                )
            ).first()
        if row is None:
            return None
        return Claim(row.id, row.scene_id, row.batch_id, row.blob_key, owner, row.attempts)

    def requeue_expired(self, max_attempts: int) -> int:
        """Expired leases go back to the queue, or to `dead` once their attempts are used up."""
        now = self.clock()
        expired = sa.and_(batches.c.status == "running", batches.c.lease_until < now)
        with write_transaction(self.engine) as connection:
            dead = connection.execute(
                sa.update(batches)
                .where(expired, batches.c.attempts >= max_attempts)
                .values(
                    status="dead",
                    lease_owner=None,
                    finished_at=now,
                    error=sa.func.coalesce(batches.c.error, "lease expired on every attempt"),
                )
            ).rowcount
            requeued = connection.execute(
                sa.update(batches)
                .where(expired)
                .values(status="failed", lease_owner=None, error="lease expired")
            ).rowcount
        return int(dead + requeued)

    def fail(self, claim: Claim, error: str, max_attempts: int) -> str:
        """Record a failed attempt (fenced by the lease); returns the new status."""
        status = "dead" if claim.attempts >= max_attempts else "failed"
        with write_transaction(self.engine) as connection:
            updated = connection.execute(
                sa.update(batches)
                .where(held_by(claim))
                .values(
                    status=status,
                    lease_owner=None,
                    error=error[:4000],
                    finished_at=self.clock() if status == "dead" else None,
                )
            ).rowcount
        if updated != 1:
            raise LeaseLost(f"batch {claim.batch_id!r}: lease lost before the failure was recorded")
        return status

    def complete(
        self, connection: sa.Connection, claim: Claim, seqs: tuple[int, int] | None
    ) -> None:
        """Mark done inside the append transaction; LeaseLost (so the caller rolls back) if not ours."""
        first_seq, last_seq = seqs if seqs is not None else (None, None)
        updated = connection.execute(
            sa.update(batches)
            .where(held_by(claim))
            .values(
                status="done",
                lease_owner=None,
                lease_until=None,
                error=None,
                first_seq=first_seq,
                last_seq=last_seq,
                finished_at=self.clock(),
            )
        ).rowcount
        if updated != 1:
            raise LeaseLost(f"batch {claim.batch_id!r}: lease lost, append rolled back")

    def counts(self, scene_id: str | None = None) -> dict[str, int]:
        """Number of batches per status."""
        query = sa.select(batches.c.status, sa.func.count()).group_by(batches.c.status)
        if scene_id is not None:
            query = query.where(batches.c.scene_id == scene_id)
        with read_transaction(self.engine) as connection:
            return {status: int(n) for status, n in connection.execute(query).all()}
