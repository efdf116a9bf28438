"""The batch queue: durable jobs, leased claims, arrival order per scene, fenced completion.

Admission is bounded (a per-scene queue bound and a per-scene quota of raw batch bytes); a
failed attempt waits for its retry (`not_before`, set by the worker's backoff); a worker renews
its lease while it works; a dead batch can be requeued by an operator.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import sqlalchemy as sa

from service.store.blobs import BlobStore
from service.store.engine import read_transaction, write_transaction
from service.store.errors import BatchConflict, LeaseLost, SceneNotFound, StoreError
from service.store.queue_records import (
    CLAIMABLE,
    UNFINISHED,
    Admission,
    BatchRecord,
    Claim,
    NotRequeueable,
    QueueFull,
    QuotaExceeded,
    RawBatchCollected,
    held_by,
    record_of,
)
from service.store.queue_retention import QueueRetention
from service.store.tables import batches, scenes

# The claim's two statements, built once (building them cost about 0.4 ms of a worker's CPU per
# batch): the oldest due batch that is the first unfinished one of its scene, locked, skipping
# rows another worker holds (PostgreSQL; SQLite serializes writers by BEGIN IMMEDIATE); then its
# lease, while it is still claimable, returning its scene's head as well.
_EARLIER = batches.alias("earlier")
CLAIM_PICK = (
    sa.select(batches.c.id)
    .where(
        batches.c.status.in_(CLAIMABLE),
        sa.or_(batches.c.not_before.is_(None), batches.c.not_before <= sa.bindparam("now")),
        ~sa.exists().where(
            _EARLIER.c.scene_id == batches.c.scene_id,
            _EARLIER.c.id < batches.c.id,
            _EARLIER.c.status.in_(UNFINISHED),
        ),
    )
    .order_by(batches.c.id)
    .limit(1)
    .with_for_update(skip_locked=True)
)
CLAIM_TAKE = (
    sa.update(batches)
    .where(batches.c.id == sa.bindparam("row_id"), batches.c.status.in_(CLAIMABLE))
    .values(
        status="running",
        lease_owner=sa.bindparam("owner"),
        lease_until=sa.bindparam("until"),
        attempts=batches.c.attempts + 1,
    )
    .returning(
        batches.c.id,
        batches.c.scene_id,
        batches.c.batch_id,
        batches.c.blob_key,
        batches.c.attempts,
        batches.c.blob_collected_at,
        sa.select(scenes.c.head_seq)
        .where(scenes.c.id == batches.c.scene_id)
        .scalar_subquery()
        .label("head_seq"),
    )
)


class BatchQueue(QueueRetention):
    """The job queue on one engine, with the blob store of the raw batches; `clock` is
    injectable so tests can expire leases."""

    def __init__(
        self, engine: sa.Engine, blobs: BlobStore, clock: Callable[[], float] = time.time
    ) -> None:
        self.engine = engine
        self.blobs = blobs
        self.clock = clock

    # -- admission ----------------------------------------------------------------------------

    def check_admission(
        self, scene_id: str, incoming_bytes: int, bounds: Admission, connection: sa.Connection
    ) -> None:
        """QueueFull (429) or QuotaExceeded (507) when the scene cannot take another batch."""
        queued, stored = connection.execute(
            sa.select(
                sa.func.count().filter(batches.c.status.in_(UNFINISHED)),
                sa.func.coalesce(
                    sa.func.sum(batches.c.blob_bytes).filter(batches.c.blob_collected_at.is_(None)),
                    0,
                ),
            ).where(batches.c.scene_id == scene_id)
        ).one()
        if queued >= bounds.max_queued:
            raise QueueFull(int(queued), bounds.max_queued, bounds.retry_after_seconds)
        if stored + incoming_bytes > bounds.max_blob_bytes:
            raise QuotaExceeded(int(stored), incoming_bytes, bounds.max_blob_bytes)

    def submit(
        self,
        scene_id: str,
        batch_id: str,
        content_sha256: str,
        blob: bytes | None,
        frame_count: int,
        bounds: Admission,
    ) -> tuple[BatchRecord, bool]:
        """Queue a batch and its blob (its stored raw body); (record, True) when new, the
        original when re-posted with equal content. `blob` is None for a batch the caller found
        queued already (a re-post writes no blob: `pbdag gc` may have collected the first).

        A store that joins the transaction (PostgreSQL's table) writes the blob in the one that
        inserts the row: both commit or neither. A folder writes it durably first, after the
        admission check, so that SQLite's write lock is not held over the file's fsync; a crash
        in between leaves an orphan file, never a row without its blob.

        Two posts of one batch racing each other both end here: the loser of the unique
        constraint reads the winner's row (PostgreSQL's reads are not serialized as SQLite's).
        """
        first = blob is not None and not self.blobs.joins_transaction
        key = self._put_first(scene_id, batch_id, blob, bounds) if first else None
        try:
            with write_transaction(self.engine) as connection:
                existing = self._get(connection, scene_id, batch_id)
                if existing is None:
                    if blob is None:  # deleted with its scene, or the caller's read was wrong
                        raise StoreError(f"batch {batch_id!r} is not queued; its body is needed")
                    self.check_admission(scene_id, len(blob), bounds, connection)
                    blob_key = self.blobs.put(blob, connection) if key is None else key
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
                            blob_bytes=len(blob),
                        )
                    )
                    created = self._get(connection, scene_id, batch_id)
                    assert created is not None
                    return created, True
        except sa.exc.IntegrityError:
            existing = self.get(scene_id, batch_id)
            if existing is None:
                self._scene_exists_or_raise(scene_id)  # deleted since the caller found it
                raise
        if existing.content_sha256 != content_sha256:
            raise BatchConflict(f"batch {batch_id!r} was already posted with different content")
        return existing, False

    def _scene_exists_or_raise(self, scene_id: str) -> None:
        """SceneNotFound when the scene is gone: its row's foreign key refused the batch (a
        folder's blob, written first, is an orphan that `pbdag gc` sweeps)."""
        with read_transaction(self.engine) as connection:
            found = connection.execute(sa.select(scenes.c.id).where(scenes.c.id == scene_id))
            if found.first() is None:
                raise SceneNotFound(scene_id)

    def _put_first(
        self, scene_id: str, batch_id: str, blob: bytes | None, bounds: Admission
    ) -> str | None:
        """A folder's blob, before the row's transaction: written unless the batch is already
        queued (a re-post) or refused (429 / 507, raised here); its key, or None."""
        with read_transaction(self.engine) as connection:
            if blob is None or self._get(connection, scene_id, batch_id) is not None:
                return None
            self.check_admission(scene_id, len(blob), bounds, connection)
        return self.blobs.put(blob)

    # -- reads --------------------------------------------------------------------------------

    def get(self, scene_id: str, batch_id: str) -> BatchRecord | None:
        """The batch's record, or None."""
        with read_transaction(self.engine) as connection:
            return self._get(connection, scene_id, batch_id)

    def _get(self, connection: sa.Connection, scene_id: str, batch_id: str) -> BatchRecord | None:
        row = connection.execute(
            sa.select(batches).where(batches.c.scene_id == scene_id, batches.c.batch_id == batch_id)
        ).first()
        return None if row is None else record_of(row)

    def blob_keys(self) -> list[str]:
        """The key of every blob a batch still holds (any status, not collected by `pbdag gc`),
        each once, in key order."""
        with read_transaction(self.engine) as connection:
            rows = connection.execute(
                sa.select(batches.c.blob_key)
                .where(batches.c.blob_collected_at.is_(None))
                .distinct()
                .order_by(batches.c.blob_key)
            ).scalars()
            return [str(key) for key in rows]

    def of_scene(self, scene_id: str) -> list[BatchRecord]:
        """Every batch of a scene, in arrival order."""
        with read_transaction(self.engine) as connection:
            rows = connection.execute(
                sa.select(batches).where(batches.c.scene_id == scene_id).order_by(batches.c.id)
            ).all()
        return [record_of(row) for row in rows]

    def counts(self, scene_id: str | None = None) -> dict[str, int]:
        """Number of batches per status."""
        query = sa.select(batches.c.status, sa.func.count()).group_by(batches.c.status)
        if scene_id is not None:
            query = query.where(batches.c.scene_id == scene_id)
        with read_transaction(self.engine) as connection:
            return {status: int(n) for status, n in connection.execute(query).all()}

    def oldest_waiting_received_at(self) -> float | None:
        """When the oldest batch still waiting for a worker (queued, or failed and waiting for
        its retry) was received; None when none waits."""
        query = sa.select(sa.func.min(batches.c.received_at)).where(batches.c.status.in_(CLAIMABLE))
        with read_transaction(self.engine) as connection:
            oldest = connection.execute(query).scalar()
        return None if oldest is None else float(oldest)

    # -- the worker's side --------------------------------------------------------------------

    def claim(self, owner: str, lease_seconds: float) -> Claim | None:
        """Lease the oldest due batch that is the first unfinished one of its scene."""
        now = self.clock()
        with write_transaction(self.engine) as connection:
            batch_row_id = connection.execute(CLAIM_PICK, {"now": now}).scalar()
            if batch_row_id is None:
                return None
            row = connection.execute(
                CLAIM_TAKE, {"row_id": batch_row_id, "owner": owner, "until": now + lease_seconds}
            ).first()
        if row is None:
            return None
        return Claim(
            row.id,
            row.scene_id,
            row.batch_id,
            row.blob_key,
            owner,
            row.attempts,
            row.blob_collected_at,
            row.head_seq,
        )

    def renew(self, claim: Claim, lease_seconds: float) -> bool:
        """Extend the lease while the batch is worked on; False when it is no longer ours."""
        with write_transaction(self.engine) as connection:
            updated = connection.execute(
                sa.update(batches)
                .where(held_by(claim))
                .values(lease_until=self.clock() + lease_seconds)
            ).rowcount
        return bool(updated == 1)

    def expired(self) -> list[Claim]:
        """Running batches whose worker stopped renewing their lease (crashed, or cut off)."""
        with read_transaction(self.engine) as connection:
            rows = connection.execute(
                sa.select(batches).where(
                    batches.c.status == "running", batches.c.lease_until < self.clock()
                )
            ).all()
        return [
            Claim(
                row.id,
                row.scene_id,
                row.batch_id,
                row.blob_key,
                row.lease_owner,
                row.attempts,
                row.blob_collected_at,
            )
            for row in rows
        ]

    def retry_later(self, claim: Claim, error: str, delay_seconds: float) -> None:
        """Record a failed attempt and when it may be retried (fenced by the lease)."""
        with write_transaction(self.engine) as connection:
            updated = connection.execute(
                sa.update(batches)
                .where(held_by(claim))
                .values(
                    status="failed",
                    lease_owner=None,
                    lease_until=None,
                    error=error,
                    not_before=self.clock() + delay_seconds,
                )
            ).rowcount
        if updated != 1:
            raise LeaseLost(f"batch {claim.batch_id!r}: lease lost before the failure was recorded")

    def complete(
        self, connection: sa.Connection, claim: Claim, seqs: tuple[int, int] | None
    ) -> None:
        """Mark done inside the append transaction; LeaseLost (so the caller rolls back) if not ours."""
        first_seq, last_seq = seqs if seqs is not None else (None, None)
        self._finish(connection, claim, status="done", first_seq=first_seq, last_seq=last_seq)

    def mark_dead(self, connection: sa.Connection, claim: Claim, error: str) -> None:
        """Park the batch as dead inside the transaction that records the skip in the log."""
        self._finish(connection, claim, status="dead", error=error)

    def _finish(self, connection: sa.Connection, claim: Claim, **values: Any) -> None:
        updated = connection.execute(
            sa.update(batches)
            .where(held_by(claim))
            .values(
                lease_owner=None,
                lease_until=None,
                not_before=None,
                finished_at=self.clock(),
                **{"error": None, **values},
            )
        ).rowcount
        if updated != 1:
            raise LeaseLost(f"batch {claim.batch_id!r}: lease lost, the transaction rolled back")

    # -- operators ----------------------------------------------------------------------------

    def requeue(self, scene_id: str, batch_id: str) -> BatchRecord:
        """A dead batch goes back to the queue with fresh attempts (it runs at its turn)."""
        with write_transaction(self.engine) as connection:
            updated = connection.execute(
                sa.update(batches)
                .where(
                    batches.c.scene_id == scene_id,
                    batches.c.batch_id == batch_id,
                    batches.c.status == "dead",
                    batches.c.blob_collected_at.is_(None),  # gc marks under the same row lock
                )
                .values(
                    status="queued",
                    attempts=0,
                    error=None,
                    not_before=None,
                    finished_at=None,
                    first_seq=None,
                    last_seq=None,
                )
            ).rowcount
            record = self._get(connection, scene_id, batch_id)
        if record is None:
            raise NotRequeueable(f"batch {batch_id!r} does not exist", "batch_id")
        if updated != 1 and record.blob_collected_at is not None:
            raise RawBatchCollected(batch_id, record.blob_collected_at)
        if updated != 1:
            raise NotRequeueable(
                f"batch {batch_id!r} is {record.status}; only a dead batch can be requeued",
                "batch_id",
            )
        return record

    # -- repair -------------------------------------------------------------------------------

    def copy_into(
        self, connection: sa.Connection, scene_id: str, record: BatchRecord, *, done: bool
    ) -> None:
        """A batch of another scene in this one: as it was when `done`, else queued afresh.

        The source row is read again under a row lock, so a `pbdag gc` running meanwhile either
        collected it before (the copy says so, and a worker skips it) or sees the copy.
        """
        kept = {"first_seq": record.first_seq, "last_seq": record.last_seq} if done else {}
        collected_at = connection.execute(
            sa.select(batches.c.blob_collected_at)
            .where(batches.c.id == record.id)
            .with_for_update()
        ).scalar()
        connection.execute(
            batches.insert().values(
                scene_id=scene_id,
                batch_id=record.batch_id,
                content_sha256=record.content_sha256,
                blob_key=record.blob_key,
                frame_count=record.frame_count,
                status="done" if done else "queued",
                attempts=record.attempts if done else 0,
                received_at=record.received_at,
                finished_at=record.finished_at if done else None,
                blob_bytes=record.blob_bytes,
                blob_collected_at=collected_at,
                **kept,
            )
        )

    def retire_scene(self, connection: sa.Connection, scene_id: str, reason: str) -> None:
        """Every unfinished batch of a scene is parked dead (its scene takes no more writes)."""
        connection.execute(
            sa.update(batches)
            .where(batches.c.scene_id == scene_id, batches.c.status.in_(UNFINISHED))
            .values(
                status="dead",
                lease_owner=None,
                lease_until=None,
                not_before=None,
                error=reason,
                finished_at=self.clock(),
            )
        )
