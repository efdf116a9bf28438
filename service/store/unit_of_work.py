"""The one write path of the log: every append goes through a unit of work.

In one transaction: the expected-head check, the event rows (only finite numbers), every
projection (track table, baseline packages, the scene row's name, snapshot) and, for a
worker's batch, the lease fence that marks it done. The worker, every command, scene creation
and the tests use it; what is decided on a head that another writer moves meanwhile is decided
again (`on_the_head`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TypeVar

import sqlalchemy as sa

from core.events import BaselineFrozen, BatchSkipped, Event, SceneRenamed
from core.evolve import evolve, fold
from core.params import Params
from core.state import SceneState
from core.values import BaselineSource
from service.store.engine import write_transaction
from service.store.errors import ConcurrencyConflict
from service.store.event_log import EventLog, SceneRecord, snapshot_due
from service.store.projection import (
    last_seq_by_track,
    write_baseline,
    write_scene_name,
    write_tracks,
)
from service.store.queue import BatchQueue
from service.store.queue_records import Claim

ATTEMPTS = 5  # heads a decision is tried on before the caller is told to try again later
Decided = TypeVar("Decided")
Written = TypeVar("Written")


@dataclass(frozen=True)
class Appended:
    """What an append left behind: the state after the events and their seq range."""

    state: SceneState
    seqs: tuple[int, int] | None  # None when there was nothing to append


class UnitOfWork:
    """Opens write transactions on the store (`with uow.begin() as work: ...`)."""

    def __init__(
        self,
        engine: sa.Engine,
        log: EventLog,
        queue: BatchQueue,
        snapshot_interval: int,
        on_committed: Callable[[int], None] | None = None,
    ) -> None:
        self.engine = engine
        self.log = log
        self.queue = queue
        self.snapshot_interval = snapshot_interval
        self.on_committed = on_committed  # told how many events each commit appended (metrics)

    @contextmanager
    def begin(self) -> Iterator[Writes]:
        """One write transaction: committed when the block ends, rolled back when it raises."""
        with write_transaction(self.engine) as connection:
            writes = Writes(self, connection)
            yield writes
        if self.on_committed is not None and writes.events_appended:
            self.on_committed(writes.events_appended)

    def on_the_head(
        self,
        scene_id: str,
        decide: Callable[[SceneState], Decided],
        write: Callable[[Writes, SceneState, Decided], Written],
    ) -> Written:
        """Decide on the scene's head, then write in one transaction; decided again on the new
        head when another writer appended first (optimistic concurrency).

        `decide` runs outside the transaction (no write lock is held while the method works),
        and an error it raises propagates with nothing written. ConcurrencyConflict when the
        head moved on every one of ATTEMPTS tries.
        """
        for _attempt in range(ATTEMPTS):
            state = self.log.load_state(scene_id)
            decided = decide(state)
            try:
                with self.begin() as work:
                    return write(work, state, decided)
            except ConcurrencyConflict:
                continue
        raise ConcurrencyConflict(f"scene {scene_id!r} kept changing; try again", "scene_id")


class Writes:
    """The writes of one transaction."""

    def __init__(self, unit: UnitOfWork, connection: sa.Connection) -> None:
        self.unit = unit
        self.connection = connection
        self.events_appended = 0

    def create_scene(
        self,
        name: str,
        params: Params,
        *,
        baseline: BaselineSource | None = None,
        scene_id: str | None = None,
    ) -> tuple[SceneRecord, SceneState]:
        """A new scene and its event 0; the state after it."""
        record, created = self.unit.log.insert_scene(
            self.connection, name, params, scene_id, baseline
        )
        return record, fold(SceneState(), [created])

    def append(
        self,
        scene_id: str,
        state: SceneState,
        events: Sequence[Event],
        *,
        batch_id: str | None = None,
        batch_time: float | None = None,
    ) -> Appended:
        """Append `events` decided on `state` (its head is the expected head) and project them;
        a batch's events carry its `batch_time` (the robot's clock: its newest frame).

        ConcurrencyConflict when the head moved; NonFiniteEvent when an event holds NaN or
        infinity. Either way the transaction rolls back and nothing is stored.
        """
        seqs = self.unit.log.append(
            self.connection, scene_id, state.head_seq, events, batch_id, batch_time
        )
        after = fold(state, events)
        if seqs is not None:
            self.events_appended += seqs[1] - seqs[0] + 1
            self._project(scene_id, state, events, after, seqs[0])
        return Appended(after, seqs)

    def complete(self, claim: Claim, seqs: tuple[int, int] | None) -> None:
        """Mark the claimed batch done; LeaseLost (the whole transaction rolls back) if not ours."""
        self.unit.queue.complete(self.connection, claim, seqs)

    def skip(self, claim: Claim, state: SceneState, reason: str) -> Appended:
        """Park the claimed batch as dead and record the gap in the scene's log (`batch_skipped`)."""
        skipped = BatchSkipped(batch_id=claim.batch_id, attempts=claim.attempts, reason=reason)
        appended = self.append(claim.scene_id, state, [skipped], batch_id=claim.batch_id)
        self.unit.queue.mark_dead(self.connection, claim, reason)
        return appended

    def _project(
        self,
        scene_id: str,
        before: SceneState,
        events: Sequence[Event],
        after: SceneState,
        first_seq: int,
    ) -> None:
        """Every projection of an append: tracks, baseline packages, the scene's name, snapshot."""
        write_tracks(self.connection, scene_id, after, last_seq_by_track(first_seq, events))
        if any(isinstance(event, SceneRenamed) for event in events):
            write_scene_name(self.connection, scene_id, after.name)
        if any(isinstance(event, BaselineFrozen) for event in events):
            state = before
            for offset, event in enumerate(events):
                if isinstance(event, BaselineFrozen):
                    write_baseline(self.connection, scene_id, state, event, first_seq + offset)
                state = evolve(state, event)
        if snapshot_due(before.head_seq, after.head_seq, self.unit.snapshot_interval):
            self.unit.log.save_snapshot(self.connection, scene_id, after)
