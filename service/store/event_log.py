"""The per-scene event log: gapless commit-ordered seq, expected-head appends, snapshots, as_of."""

from __future__ import annotations

import math
import time
import uuid
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import orjson
import pydantic
import sqlalchemy as sa

from core.errors import field_path
from core.event_records import STORED_NAMES, event_from_record, non_finite_field, stored_names
from core.events import Event, SceneCreated
from core.evolve import fold
from core.params import Params
from core.state import SceneState
from core.values import BaselineSource
from service.store.append_sql import EVENT_COLUMNS, EventRow, insert_rows
from service.store.engine import gc_paused, read_transaction
from service.store.errors import (
    NonFiniteEvent,
    SceneNotFound,
    SeqOutOfRange,
    UnreadableEvent,
)
from service.store.snapshot_codec import (
    READABLE_VERSIONS,
    SNAPSHOT_VERSION,
    decode_snapshot,
    encode_snapshot,
)
from service.store.tables import events, scenes, snapshots

READ_PAGE = 5000

# The newest snapshot at or before a seq, for psycopg's binary cursor (PostgreSQL).
SNAPSHOT_AT_OR_BEFORE_BINARY = (
    "SELECT format_version, body FROM snapshots WHERE scene_id = %s AND seq <= %s "
    "ORDER BY seq DESC LIMIT 1"
)


@dataclass(frozen=True)
class SceneRecord:
    """One row of `scenes`."""

    id: str
    name: str
    params: dict[str, Any]
    head_seq: int
    created_at: float
    quarantined: str | None = None  # why the scene takes no more writes (see `pbdag repair`)


@dataclass(frozen=True)
class StoredEvent:
    """One row: `topic` names the form of `details` (as stored), `type` is its audit type."""

    scene_id: str
    seq: int
    topic: str
    type: str
    track_id: str | None
    state: str | None
    batch_id: str | None
    frame_id: str | None
    recorded_at: float
    details: dict[str, Any]
    batch_time: float | None = None  # the robot's clock of the batch that appended it

    def to_core(self) -> Event:
        """The typed core event (UnreadableEvent when the row cannot be one)."""
        return decoded_event(
            self.seq, self.topic, self.track_id, self.state, self.frame_id, self.details
        )


def _scene(row: sa.Row[Any]) -> SceneRecord:
    return SceneRecord(
        row.id, row.name, orjson.loads(row.params), row.head_seq, row.created_at, row.quarantined
    )


def _stored(scene_id: str, row: sa.Row[Any]) -> StoredEvent:
    details = orjson.loads(row.details)
    topic, audit_type = stored_names(row.type, details)  # the `type` column: the stored name
    return StoredEvent(
        scene_id,
        row.seq,
        topic,
        audit_type,
        row.track_id,
        row.state,
        row.batch_id,
        row.frame_id,
        row.recorded_at,
        details,
        row.batch_time,
    )


def decoded_event(
    seq: int,
    stored_name: str,
    track_id: str | None,
    state: str | None,
    frame_id: str | None,
    details: str | dict[str, Any],
) -> Event:
    """A stored row as its typed event; UnreadableEvent names the seq and the field otherwise."""
    try:
        payload = orjson.loads(details) if isinstance(details, str) else details
        return event_from_record(
            {
                "topic": stored_name,
                "track_id": track_id,
                "state": state,
                "frame_id": frame_id,
                "details": payload,
            }
        )
    except pydantic.ValidationError as error:
        first = error.errors()[0]
        where = field_path(["details", *first["loc"]])
        raise UnreadableEvent(seq, f"{where}: {first['msg']}") from None
    except (ValueError, TypeError, KeyError) as error:
        raise UnreadableEvent(seq, str(error)) from None


def _core_event(row: sa.Row[Any, Any, Any, Any, Any, Any]) -> Event:
    """A log row straight to its core event (the as_of path skips StoredEvent)."""
    return decoded_event(row.seq, row.type, row.track_id, row.state, row.frame_id, row.details)


class EventLog:
    """Scenes and their append-only logs on one engine."""

    def __init__(self, engine: sa.Engine, clock: Any = time.time) -> None:
        self.engine = engine
        self.clock = clock

    # -- scenes -------------------------------------------------------------------------------

    def insert_scene(
        self,
        connection: sa.Connection,
        name: str,
        params: Params,
        scene_id: str | None = None,
        baseline: BaselineSource | None = None,
    ) -> tuple[SceneRecord, SceneCreated]:
        """Insert the scene row and its event 0 (`scene_created`, recording the parameters)."""
        scene_id = scene_id or f"scn-{uuid.uuid4().hex[:12]}"
        now = self.clock()
        params_json = orjson.dumps(params.to_dict(), option=orjson.OPT_SORT_KEYS).decode()
        connection.execute(
            scenes.insert().values(
                id=scene_id, name=name, params=params_json, head_seq=0, created_at=now
            )
        )
        created = SceneCreated(name=name, params=params.to_dict(), baseline=baseline)
        row = self._event_row(scene_id, 0, created, None, now, None)
        connection.execute(events.insert(), [dict(zip(EVENT_COLUMNS, row, strict=True))])
        return SceneRecord(scene_id, name, params.to_dict(), 0, now, None), created

    def scene(self, scene_id: str, connection: sa.Connection | None = None) -> SceneRecord:
        """The scene row; SceneNotFound when absent."""
        query = sa.select(scenes).where(scenes.c.id == scene_id)
        if connection is None:
            with read_transaction(self.engine) as own:
                row = own.execute(query).first()
        else:
            row = connection.execute(query).first()
        if row is None:
            raise SceneNotFound(scene_id)
        return _scene(row)

    def scenes(self, after: str | None = None, limit: int | None = None) -> list[SceneRecord]:
        """The scenes, oldest first: every one, or a page of `limit` after the scene `after`
        (SceneNotFound when that scene does not exist)."""
        query = sa.select(scenes).order_by(scenes.c.created_at, scenes.c.id).limit(limit)
        with read_transaction(self.engine) as connection:
            if after is not None:
                cursor = self.scene(after, connection)
                query = query.where(
                    sa.tuple_(scenes.c.created_at, scenes.c.id) > (cursor.created_at, cursor.id)
                )
            rows = connection.execute(query).all()
        return [_scene(row) for row in rows]

    # -- the log ------------------------------------------------------------------------------

    def _event_row(
        self,
        scene_id: str,
        seq: int,
        event: Event,
        batch_id: str | None,
        now: float,
        batch_time: float | None,
    ) -> EventRow:
        """The event's row, its values in the order of EVENT_COLUMNS."""
        details = event.details()
        bad = non_finite_field(details)
        if bad is not None:  # orjson would store null, and the log could not be replayed
            raise NonFiniteEvent(
                f"{event.type} event of {event.track_id or 'the scene'} has a non-finite number "
                f"at {bad}; nothing was appended",
                field=bad,
            )
        return (
            scene_id,
            seq,
            event.topic,
            event.track_id,
            event.state,
            batch_id,
            event.frame_id,
            now,
            orjson.dumps(details).decode(),
            batch_time,
        )

    def append(
        self,
        connection: sa.Connection,
        scene_id: str,
        expected_head: int,
        new_events: Sequence[Event],
        batch_id: str | None = None,
        batch_time: float | None = None,
    ) -> tuple[int, int] | None:
        """Append inside the caller's write transaction; (first_seq, last_seq), None if no events.
        `batch_time` is the robot's clock of the batch that decided them (its newest frame).

        The conditional head update serializes writers of one scene until commit; a rollback
        leaves no gap; zero rows updated means somebody else appended first.
        """
        if not new_events:
            return None
        if batch_time is not None and not math.isfinite(batch_time):
            raise NonFiniteEvent("batch_time is not finite; nothing was appended", "batch_time")
        count = len(new_events)
        now = self.clock()
        rows = [
            self._event_row(scene_id, expected_head + 1 + i, event, batch_id, now, batch_time)
            for i, event in enumerate(new_events)
        ]  # before any write: a non-finite number stops the append here
        insert_rows(connection, scene_id, expected_head, rows, batch_id, now, batch_time)
        return expected_head + 1, expected_head + count

    def read(
        self,
        scene_id: str,
        *,
        after: int = -1,
        up_to: int | None = None,
        limit: int | None = None,
        track_id: str | None = None,
        event_type: str | None = None,
        connection: sa.Connection | None = None,
    ) -> list[StoredEvent]:
        """Events with after < seq (<= up_to), in seq order, optionally filtered (`event_type`:
        an audit type, add or confirm, matches every topic of that type)."""
        query = sa.select(events).where(events.c.scene_id == scene_id, events.c.seq > after)
        if up_to is not None:
            query = query.where(events.c.seq <= up_to)
        if track_id is not None:
            query = query.where(events.c.track_id == track_id)
        if event_type is not None:
            query = query.where(events.c.type.in_(STORED_NAMES.get(event_type, ())))
        query = query.order_by(events.c.seq)
        if limit is not None:
            query = query.limit(limit)
        if connection is None:
            with read_transaction(self.engine) as own:
                rows = own.execute(query).all()
        else:
            rows = connection.execute(query).all()
        return [_stored(scene_id, row) for row in rows]

    def seq_at_time(self, scene_id: str, at: float) -> int | None:
        """The last seq appended by a batch whose time (the robot's clock, `batch_time`) is at
        or before `at`; None when no batch is. One index seek while the clock only moves
        forward; a clock that stepped back costs a scan of the earlier times' index entries."""
        query = sa.select(sa.func.max(events.c.seq)).where(
            events.c.scene_id == scene_id, events.c.batch_time <= at
        )
        with read_transaction(self.engine) as connection:
            seq = connection.execute(query).scalar()
        return None if seq is None else int(seq)

    def last_changes(self, scene_id: str, track_ids: Sequence[str], up_to: int) -> dict[str, int]:
        """The seq of each track's last event at or before `up_to` (one index range per track)."""
        found: dict[str, int] = {}
        with read_transaction(self.engine) as connection:
            for start in range(0, len(track_ids), 500):
                chunk = list(track_ids[start : start + 500])
                rows = connection.execute(
                    sa.select(events.c.track_id, sa.func.max(events.c.seq))
                    .where(
                        events.c.scene_id == scene_id,
                        events.c.track_id.in_(chunk),
                        events.c.seq <= up_to,
                    )
                    .group_by(events.c.track_id)
                ).all()
                found.update({str(track): int(seq) for track, seq in rows})
        return found

    def iter_events(
        self, scene_id: str, *, after: int = -1, up_to: int | None = None
    ) -> Iterator[StoredEvent]:
        """All events in pages, for replays of long logs."""
        cursor = after
        while True:
            page = self.read(scene_id, after=cursor, up_to=up_to, limit=READ_PAGE)
            yield from page
            if len(page) < READ_PAGE:
                return
            cursor = page[-1].seq

    def batches_of_frames(self, scene_id: str, frames: Iterable[tuple[str, str]]) -> set[str]:
        """The batches whose events on `track_id` carry `frame_id`, for each (track_id, frame_id):
        the batches a track's frame came in."""
        wanted = sorted(set(frames))
        found: set[str] = set()
        with read_transaction(self.engine) as connection:
            for start in range(0, len(wanted), 200):
                chunk = wanted[start : start + 200]
                rows = connection.execute(
                    sa.select(events.c.batch_id)
                    .where(
                        events.c.scene_id == scene_id,
                        events.c.track_id.in_([track for track, _frame in chunk]),
                        sa.tuple_(events.c.track_id, events.c.frame_id).in_(chunk),
                        events.c.batch_id.is_not(None),
                    )
                    .distinct()
                ).scalars()
                found |= {str(batch_id) for batch_id in rows}
        return found

    # -- state --------------------------------------------------------------------------------

    def load_state(self, scene_id: str, as_of: int | None = None) -> SceneState:
        """State at `as_of` (default the head): the newest snapshot at or before it plus the tail."""
        with gc_paused(), read_transaction(self.engine) as connection:
            head = connection.execute(
                sa.select(scenes.c.head_seq).where(scenes.c.id == scene_id)
            ).scalar()
            if head is None:
                raise SceneNotFound(scene_id)
            target = head if as_of is None else as_of
            if target > head or target < 0:
                raise SeqOutOfRange(f"as_of {target} is outside 0..{head}")
            base = self._snapshot_at_or_before(connection, scene_id, target) or SceneState()
            rows = connection.execute(
                sa.select(
                    events.c.seq,
                    events.c.type,
                    events.c.track_id,
                    events.c.state,
                    events.c.frame_id,
                    events.c.details,
                )
                .where(
                    events.c.scene_id == scene_id,
                    events.c.seq > base.head_seq,
                    events.c.seq <= target,
                )
                .order_by(events.c.seq)
            ).all()
        return fold(base, (_core_event(row) for row in rows))

    def replay(self, scene_id: str, up_to: int | None = None) -> SceneState:
        """Full replay from seq 0, ignoring snapshots."""
        return fold(SceneState(), (e.to_core() for e in self.iter_events(scene_id, up_to=up_to)))

    def _snapshot_at_or_before(
        self, connection: sa.Connection, scene_id: str, seq: int
    ) -> SceneState | None:
        found = self.snapshot_row(connection, scene_id, seq)
        if found is None or found[0] not in READABLE_VERSIONS:
            return None  # a cache in another format is ignored: replay from the start
        return decode_snapshot(found[1], found[0])

    def snapshot_row(
        self, connection: sa.Connection, scene_id: str, seq: int
    ) -> tuple[int, bytes] | None:
        """The newest snapshot at or before `seq`: its body version and body."""
        if connection.dialect.name == "postgresql":
            # Binary results: psycopg's default text format sends a bytea as hex, twice its
            # size, and decodes it in Python (a 666 kB body: 7.7 -> 1.7 ms).
            driver: Any = connection.connection.driver_connection  # the psycopg connection
            with driver.cursor(binary=True) as cursor:
                cursor.execute(SNAPSHOT_AT_OR_BEFORE_BINARY, (scene_id, seq))
                found = cursor.fetchone()
        else:
            found = connection.execute(
                sa.select(snapshots.c.format_version, snapshots.c.body)
                .where(snapshots.c.scene_id == scene_id, snapshots.c.seq <= seq)
                .order_by(snapshots.c.seq.desc())
                .limit(1)
            ).first()
        return None if found is None else (int(found[0]), bytes(found[1]))

    def save_snapshot(self, connection: sa.Connection, scene_id: str, state: SceneState) -> None:
        """Store a snapshot of `state` at its head (inside the caller's transaction)."""
        connection.execute(
            snapshots.insert().values(
                scene_id=scene_id,
                seq=state.head_seq,
                format_version=SNAPSHOT_VERSION,
                body=encode_snapshot(state),
            )
        )

    def quarantine(self, connection: sa.Connection, scene_id: str, reason: str) -> None:
        """The scene takes no more writes and its state is not served; its log stays as it is."""
        connection.execute(
            sa.update(scenes).where(scenes.c.id == scene_id).values(quarantined=reason)
        )

    def snapshot_seqs(self, scene_id: str) -> list[int]:
        """Where snapshots exist."""
        with read_transaction(self.engine) as connection:
            rows = connection.execute(
                sa.select(snapshots.c.seq)
                .where(snapshots.c.scene_id == scene_id)
                .order_by(snapshots.c.seq)
            ).all()
        return [row.seq for row in rows]


def snapshot_due(previous_head: int, new_head: int, interval: int) -> bool:
    """True when an append crossed a multiple of the snapshot interval."""
    return interval > 0 and new_head // interval > previous_head // interval
