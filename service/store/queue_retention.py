"""The queue's side of raw batch retention (`pbdag gc`): which finished batches still keep their
raw body, and marking bodies collected. A part of `BatchQueue`, kept in its own module."""

from __future__ import annotations

from collections.abc import Callable

import sqlalchemy as sa

from service.store.engine import read_transaction, write_transaction
from service.store.queue_records import FINISHED, BatchRecord, Collected, record_of
from service.store.tables import batches


class QueueRetention:
    """The retention reads and marks of the batch queue (mixed into `BatchQueue`)."""

    engine: sa.Engine
    clock: Callable[[], float]

    def finished_before(self, cutoff: float) -> list[BatchRecord]:
        """Done or dead batches finished before `cutoff` whose raw body is still kept."""
        with read_transaction(self.engine) as connection:
            rows = connection.execute(
                sa.select(batches)
                .where(
                    batches.c.status.in_(FINISHED),
                    batches.c.finished_at < cutoff,
                    batches.c.blob_collected_at.is_(None),
                )
                .order_by(batches.c.id)
            ).all()
        return [record_of(row) for row in rows]

    def mark_collected(self, ids: list[int]) -> tuple[list[Collected], set[str]]:
        """Mark these batches' raw bodies collected, those still finished and not yet collected;
        (the marked ones, the keys among theirs that no uncollected row holds any more).

        Only blobs of the second set may be deleted, after this commits: a requeue and a claim
        need a row that is not collected, and `requeue` tests that under the same row lock.
        """
        marked: list[Collected] = []
        with write_transaction(self.engine) as connection:
            for start in range(0, len(ids), 500):
                rows = connection.execute(
                    sa.update(batches)
                    .where(
                        batches.c.id.in_(ids[start : start + 500]),
                        batches.c.status.in_(FINISHED),
                        batches.c.blob_collected_at.is_(None),
                    )
                    .values(blob_collected_at=self.clock())
                    .returning(
                        batches.c.id,
                        batches.c.scene_id,
                        batches.c.batch_id,
                        batches.c.blob_key,
                        batches.c.blob_bytes,
                    )
                ).all()
                marked += [Collected(*row) for row in rows]
            keys = sorted({item.blob_key for item in marked})
            still_held: set[str] = set()
            for start in range(0, len(keys), 500):
                still_held |= set(
                    connection.execute(
                        sa.select(batches.c.blob_key)
                        .where(
                            batches.c.blob_key.in_(keys[start : start + 500]),
                            batches.c.blob_collected_at.is_(None),
                        )
                        .distinct()
                    ).scalars()
                )
        return sorted(marked, key=lambda item: item.id), set(keys) - still_held
