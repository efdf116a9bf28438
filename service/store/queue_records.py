"""What the batch queue hands out and refuses: its records, claims and admission, the errors of
admission and requeue, and the lease fence (`service.store.queue` is the queue itself).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import sqlalchemy as sa

from pbdag_errors import Refused
from service.store.tables import batches

CLAIMABLE = ("queued", "failed")  # failed: an attempt failed, the batch waits for a retry
UNFINISHED = ("queued", "failed", "running")  # these hold back later batches of the scene
FINISHED = ("done", "dead")  # only these may lose their raw body to retention


class QueueFull(Refused):
    """The scene holds as many unfinished batches as it may: the client retries after
    `retry_after` seconds."""

    def __init__(self, queued: int, limit: int, retry_after: int) -> None:
        super().__init__(
            f"the scene has {queued} unfinished batches, its limit "
            f"(PBDAG_MAX_QUEUED_BATCHES_PER_SCENE) is {limit}; retry in {retry_after} s",
        )
        self.retry_after = retry_after


class QuotaExceeded(Refused):
    """The scene's raw batches would exceed its byte quota."""

    def __init__(self, stored: int, incoming: int, limit: int) -> None:
        super().__init__(
            f"the scene stores {stored} bytes of raw batches; {incoming} more would exceed its "
            f"quota (PBDAG_MAX_SCENE_BLOB_BYTES) of {limit}",
            None,
        )


class NotRequeueable(Refused):
    """Only a dead batch can be requeued."""


class RawBatchCollected(Refused):
    """The batch's raw body was deleted by `pbdag gc` (retention); its events stay."""

    def __init__(self, batch_id: str, collected_at: float) -> None:
        when = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(collected_at))
        super().__init__(
            f"batch {batch_id!r}: its raw body was deleted by `pbdag gc` at {when} "
            "(PBDAG_RAW_RETENTION); its events are kept",
            "batch_id",
        )


@dataclass(frozen=True)
class Admission:
    """The bounds a scene's queue holds to."""

    max_queued: int
    max_blob_bytes: int
    retry_after_seconds: int


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
    not_before: float | None
    blob_bytes: int
    blob_collected_at: float | None


@dataclass(frozen=True)
class Claim:
    """A batch leased to one worker."""

    id: int
    scene_id: str
    batch_id: str
    blob_key: str
    owner: str
    attempts: int
    blob_collected_at: float | None = None  # set only on a copy made by `pbdag repair`
    # The scene's head when the batch was claimed (read in the claim's statement, so the worker
    # need not read it again); None when not known (a lapsed lease's claim, a deleted scene).
    head_seq: int | None = None


@dataclass(frozen=True)
class Collected:
    """A batch whose raw body `pbdag gc` marked as collected."""

    id: int
    scene_id: str
    batch_id: str
    blob_key: str
    blob_bytes: int


def held_by(claim: Claim) -> sa.ColumnElement[bool]:
    """The lease fence: the batch is still running under this claim's owner."""
    return sa.and_(
        batches.c.id == claim.id,
        batches.c.lease_owner == claim.owner,
        batches.c.status == "running",
    )


def record_of(row: sa.Row[Any]) -> BatchRecord:
    return BatchRecord(**{column.name: row._mapping[column.name] for column in batches.columns})
