"""Raw batch retention and `pbdag gc`: which raw batches may go, and deleting them safely.

Events are kept (until an administrator deletes their whole scene,
service/store/scene_deletion.py); only a batch's raw body (its blob) is collected. A batch's raw
body is **expired** when the batch is done or dead, finished more than `PBDAG_RAW_RETENTION` ago, and
is not **referenced**. Neither a verification nor an inspection names a batch: they name
frames. A verification request (`verification_requested`) and a fixture's track carry
`best_frame`, the frame to crop for a verifier; an inspection capture brings its own frames in
its request, which are not raw batches and are never stored. So a raw batch is referenced when
it is the batch in which a track's `best_frame` came (an event on that track with that
`frame_id` and that `batch_id`), for a track that

- waits for a verdict (`verification == "pending"`, not removed: `GET /verifications`), or
- is a fixture whose inspection is unresolved (`GET /inspection-queue`: confirmed, of the
  inspection taxonomy, not rejected, no `inspection_status` yet).

The state read is the scene's head when gc starts. A quarantined scene serves no state, so no
frame of it is referenced (its batches were copied, with their blobs, to the repaired scene).

Collecting is two steps, so that it is safe while the service runs:
1. one transaction marks the rows (`blob_collected_at`), only those still done or dead and not
   collected; `requeue` and `pbdag repair` test and lock the same rows, so a batch is either
   requeued or collected, never both;
2. after the commit, the blobs that no uncollected row holds any more are deleted through the
   `BlobStore` protocol. A worker only claims queued batches, which are never marked, and a
   blob written since the compact format is held by one row only (the scene is in it).

A gc killed between the two steps leaves blobs whose rows are all collected, and an API killed
between writing a folder blob and committing its row leaves a blob no row names. So every gc
then **sweeps** the blob store: a blob whose rows are all collected is deleted at once (no row
can take it back), a blob that no row names once it is `ORPHAN_GRACE_SECONDS` old (younger, it
may belong to a batch being queued right now), and the temp files of interrupted writes
(`pbdag blobs migrate`, a killed `put`) once they are as old. The sweep lists the blobs before
it reads the rows: on PostgreSQL a blob commits with its row, so a listed blob's row is visible.
A blob is deleted only after every row that names it is marked collected, so no row that a
worker may claim ever points at a deleted blob.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import islice

import sqlalchemy as sa

from core.graph import pending_verifications
from core.planner import unresolved_fixtures
from pbdag_errors import Refused
from service.bootstrap import Container
from service.store.blobs import ORPHAN_GRACE_SECONDS
from service.store.engine import read_transaction
from service.store.queue_records import BatchRecord
from service.store.tables import batches


@dataclass
class GcReport:
    """What `collect` found and did."""

    retention_seconds: float | None
    cutoff: float | None
    dry_run: bool
    expired: list[BatchRecord] = field(default_factory=list)  # collected (or would be)
    kept_referenced: list[BatchRecord] = field(default_factory=list)
    # Scenes whose state could not be read (a log needing `pbdag repair`): all their batches kept.
    unreadable_scenes: dict[str, str] = field(default_factory=dict)
    bytes_freed: int = 0  # the blob bytes of the batches collected
    blobs_deleted: int = 0  # blobs removed from the store (0 on a dry run)
    # The sweep (see above): blobs whose rows were collected by an interrupted gc, blobs no row
    # names, temp files of interrupted writes (what a dry run would remove, on a dry run).
    swept_collected: int = 0
    swept_unnamed: int = 0
    swept_leftovers: int = 0

    @property
    def batches(self) -> int:
        """Raw batches collected (or that a dry run would collect)."""
        return len(self.expired)


def referenced_batches(container: Container, scene_id: str) -> set[str]:
    """The batch ids of a scene whose raw body a pending verification or an unresolved
    inspection still needs (see the module's docstring)."""
    scene = container.log.scene(scene_id)
    if scene.quarantined is not None:
        return set()
    state = container.log.load_state(scene_id)
    tracks = {track_id: state.tracks[track_id] for track_id in pending_verifications(state)}
    tracks.update({fixture.track_id: fixture for fixture in unresolved_fixtures(state)})
    frames = [(t.track_id, t.best_frame) for t in tracks.values() if t.best_frame is not None]
    return container.log.batches_of_frames(scene_id, frames) if frames else set()


def collect(
    container: Container,
    retention_seconds: float | None,
    *,
    dry_run: bool = False,
    clock: Callable[[], float] = time.time,
) -> GcReport:
    """Delete the raw bodies of expired batches (none when `retention_seconds` is None)."""
    if retention_seconds is None:
        return GcReport(None, None, dry_run)
    cutoff = clock() - retention_seconds
    report = GcReport(retention_seconds, cutoff, dry_run)
    candidates = container.queue.finished_before(cutoff)
    referenced: dict[str, set[str] | None] = {}  # None: the scene's state cannot be read
    for record in candidates:
        if record.scene_id not in referenced:
            try:
                referenced[record.scene_id] = referenced_batches(container, record.scene_id)
            except Refused as error:  # the store failing is no unreadable scene: gc stops
                referenced[record.scene_id] = None
                report.unreadable_scenes[record.scene_id] = error.detail
        held = referenced[record.scene_id]
        if held is None or record.batch_id in held:
            report.kept_referenced.append(record)
        else:
            report.expired.append(record)
    if dry_run:
        report.bytes_freed = sum(record.blob_bytes for record in report.expired)
        sweep(container, report, clock())
        return report
    marked, deletable = container.queue.mark_collected([record.id for record in report.expired])
    marked_ids = {item.id for item in marked}
    # A batch requeued (or collected by another gc) meanwhile is not counted.
    report.expired = [record for record in report.expired if record.id in marked_ids]
    report.bytes_freed = sum(item.blob_bytes for item in marked)
    for key in sorted(deletable):
        report.blobs_deleted += container.blobs.delete(key)
    sweep(container, report, clock())
    return report


SWEEP_CHUNK = 500


def sweep(container: Container, report: GcReport, now: float) -> None:
    """Delete the blobs no uncollected row holds, then the leftovers of interrupted writes
    (counted in `report`; a dry run counts the blobs and deletes nothing)."""
    cutoff = now - ORPHAN_GRACE_SECONDS
    listed = container.blobs.keys()  # each chunk listed before its rows are read (see above)
    while chunk := list(islice(listed, SWEEP_CHUNK)):
        held = _holders(container.engine, chunk)
        for key in chunk:
            if held.get(key) is True:
                continue
            if key in held:  # named by collected rows only
                report.swept_collected += report.dry_run or container.blobs.delete(key)
                continue
            stored = container.blobs.stored_at(key)
            if stored is not None and stored < cutoff:
                report.swept_unnamed += report.dry_run or container.blobs.delete(key)
    if not report.dry_run:
        report.swept_leftovers = container.blobs.remove_leftovers(cutoff)


def _holders(engine: sa.Engine, keys: list[str]) -> dict[str, bool]:
    """For each key some row names: True when an uncollected row holds it."""
    held = sa.func.max(sa.case((batches.c.blob_collected_at.is_(None), 1), else_=0))
    with read_transaction(engine) as connection:
        rows = connection.execute(
            sa.select(batches.c.blob_key, held)
            .where(batches.c.blob_key.in_(keys))
            .group_by(batches.c.blob_key)
        ).all()
    return {str(key): bool(value) for key, value in rows}
