"""The append's statements, per backend: the conditional head update and the insert of the rows.

The head update serializes writers of one scene until commit; zero rows updated means somebody
else appended first, and nothing is written. On PostgreSQL the head update also notifies
`EVENTS_CHANNEL` (service/store/notifications.py), delivered at commit, in the same statement.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import orjson
import sqlalchemy as sa

from service.store.engine import sqlite_execute
from service.store.errors import ConcurrencyConflict
from service.store.notifications import EVENTS_CHANNEL
from service.store.tables import events

# An event's row (EventLog._event_row): its values in this order, one per column of `events`.
EVENT_COLUMNS = (
    "scene_id",
    "seq",
    "type",
    "track_id",
    "state",
    "batch_id",
    "frame_id",
    "recorded_at",
    "details",
    "batch_time",
)
EventRow = tuple[Any, ...]
if sorted(EVENT_COLUMNS) != sorted(events.columns.keys()):  # a column added to one, not the other
    raise RuntimeError(f"EVENT_COLUMNS {EVENT_COLUMNS} are not the columns of events")

# The same two statements as SQLite's driver runs them (qmark parameters).
SQLITE_HEAD_UPDATE = "UPDATE scenes SET head_seq = head_seq + ? WHERE id = ? AND head_seq = ?"
SQLITE_INSERT = (
    f"INSERT INTO events ({', '.join(EVENT_COLUMNS)}) "
    f"VALUES ({', '.join('?' for _ in EVENT_COLUMNS)})"
)

# The append on PostgreSQL: the conditional head update and the insert of the rows (each
# column a JSON array of its values, read back in order) in one statement, one round trip, for
# a batch of any size. When the head is not the expected one the update matches nothing and no
# row is inserted; the updated scene row stays locked until commit, so writers of one scene are
# serialized and the seq stays gapless and commit-ordered. The columns go as JSON text rather
# than as text[] parameters, which psycopg builds element by element in Python (about 0.8 ms of
# a worker's CPU for a batch of 25 events of 1 kB, and slower than a head update then an
# executemany from about 100 rows on); `json_array_elements_text` gives each string back
# exactly, and a JSON null as NULL. `python -m bench.bench_store versus`, interleaved with the
# library: 1.27-1.29x at batches of 1, 1.66x at 20, 2.12x at 500 (text[] parameters up to 32
# rows, then the two statements: 1.00-1.11x, 1.11-1.13x, 1.50-1.60x, the same day).
ARRAY_COLUMNS = ("type", "track_id", "state", "frame_id", "details")
ARRAY_POSITIONS = tuple((column, EVENT_COLUMNS.index(column)) for column in ARRAY_COLUMNS)
POSTGRES_APPEND = sa.text(
    """
    WITH head AS (
        UPDATE scenes SET head_seq = head_seq + :count
        WHERE id = CAST(:scene_id AS text) AND head_seq = :expected
        RETURNING head_seq, pg_notify(CAST(:channel AS text), CAST(:scene_id AS text))
    )
    INSERT INTO events
        (scene_id, seq, type, track_id, state, batch_id, frame_id, recorded_at, details,
        batch_time)
    SELECT CAST(:scene_id AS text), CAST(:expected AS bigint) + row.n, row.type, row.track_id,
        row.state, CAST(:batch_id AS text), row.frame_id, CAST(:recorded_at AS double precision),
        row.details, CAST(:batch_time AS double precision)
    FROM head, ROWS FROM (
        json_array_elements_text(CAST(:types AS json)),
        json_array_elements_text(CAST(:track_ids AS json)),
        json_array_elements_text(CAST(:states AS json)),
        json_array_elements_text(CAST(:frame_ids AS json)),
        json_array_elements_text(CAST(:detailss AS json))
    ) WITH ORDINALITY AS row(type, track_id, state, frame_id, details, n)
    """
)


def insert_rows(
    connection: sa.Connection,
    scene_id: str,
    expected_head: int,
    rows: Sequence[EventRow],
    batch_id: str | None,
    now: float,
    batch_time: float | None = None,
) -> None:
    """Move the scene's head from `expected_head` past the rows and insert them, inside the
    caller's write transaction; ConcurrencyConflict (nothing written) when the head moved.
    PostgreSQL: the listeners of EVENTS_CHANNEL are told the scene's id at commit."""
    count = len(rows)
    if connection.dialect.name == "postgresql":
        inserted = connection.execute(
            POSTGRES_APPEND,
            {
                "scene_id": scene_id,
                "expected": expected_head,
                "count": count,
                "channel": EVENTS_CHANNEL,
                "batch_id": batch_id,
                "recorded_at": now,
                "batch_time": batch_time,
                **{
                    f"{column}s": orjson.dumps([row[at] for row in rows]).decode()
                    for column, at in ARRAY_POSITIONS
                },
            },
        ).rowcount
        if inserted != count:
            raise _moved(scene_id, expected_head)
        return
    # SQLite, on the driver's own connection: SQLAlchemy's execution costs more CPU than
    # SQLite's work for a batch of one (`bench.bench_store versus`); its errors are raised as
    # SQLAlchemy's would be (sqlite_execute).
    head = (count, scene_id, expected_head)
    if sqlite_execute(connection, SQLITE_HEAD_UPDATE, head).rowcount != 1:
        raise _moved(scene_id, expected_head)
    sqlite_execute(connection, SQLITE_INSERT, rows, many=True)


def _moved(scene_id: str, expected_head: int) -> ConcurrencyConflict:
    """Somebody else appended first: the head is no longer the one this append read."""
    return ConcurrencyConflict(f"scene {scene_id!r}: head is not {expected_head}")
