"""The append's statements, per backend: the conditional head update and the insert of the rows.

The head update serializes writers of one scene until commit; zero rows updated means somebody
else appended first, and nothing is written.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import sqlalchemy as sa

from service.store.errors import ConcurrencyConflict
from service.store.tables import events, scenes

# The conditional head update, built once (the append is the hot path).
HEAD_UPDATE = (
    sa.update(scenes)
    .where(scenes.c.id == sa.bindparam("scene_id"), scenes.c.head_seq == sa.bindparam("expected"))
    .values(head_seq=scenes.c.head_seq + sa.bindparam("count", type_=sa.BigInteger))
)

# The same two statements as SQLite's driver runs them (qmark parameters).
EVENT_COLUMNS = tuple(column.name for column in events.columns)
SQLITE_HEAD_UPDATE = "UPDATE scenes SET head_seq = head_seq + ? WHERE id = ? AND head_seq = ?"
SQLITE_INSERT = (
    f"INSERT INTO events ({', '.join(EVENT_COLUMNS)}) "
    f"VALUES ({', '.join('?' for _ in EVENT_COLUMNS)})"
)

# The append on PostgreSQL: the conditional head update and the insert of the rows (arrays of
# the columns, unnested in order) in one statement. When the head is not the expected one the
# update matches nothing and no row is inserted; the updated scene row stays locked until commit,
# so writers of one scene are serialized and the seq stays gapless and commit-ordered.
# Measured against the update then an executemany of the rows: 1.4 times the events per
# second in batches of 20, slower from about 100 on (the arrays' text costs more than the
# round trip saved), so larger batches take the two statements.
ONE_STATEMENT_MAX = 32
ARRAY_COLUMNS = ("type", "track_id", "state", "frame_id", "details")
POSTGRES_APPEND = sa.text(
    """
    WITH head AS (
        UPDATE scenes SET head_seq = head_seq + :count
        WHERE id = CAST(:scene_id AS text) AND head_seq = :expected
        RETURNING head_seq
    )
    INSERT INTO events
        (scene_id, seq, type, track_id, state, batch_id, frame_id, recorded_at, details,
        batch_time)
    SELECT CAST(:scene_id AS text), CAST(:expected AS bigint) + row.n, row.type, row.track_id,
        row.state, CAST(:batch_id AS text), row.frame_id, CAST(:recorded_at AS double precision),
        row.details, CAST(:batch_time AS double precision)
    FROM head, unnest(
        CAST(:types AS text[]), CAST(:track_ids AS text[]), CAST(:states AS text[]),
        CAST(:frame_ids AS text[]), CAST(:detailss AS text[])
    ) WITH ORDINALITY AS row(type, track_id, state, frame_id, details, n)
    """
)


def insert_rows(
    connection: sa.Connection,
    scene_id: str,
    expected_head: int,
    rows: Sequence[dict[str, Any]],
    batch_id: str | None,
    now: float,
    batch_time: float | None = None,
) -> None:
    """Move the scene's head from `expected_head` past the rows and insert them, inside the
    caller's write transaction; ConcurrencyConflict (nothing written) when the head moved."""
    count = len(rows)
    dialect = connection.dialect.name
    if dialect == "postgresql" and count <= ONE_STATEMENT_MAX:
        # One statement, one round trip: the head update gates the insert of every row.
        inserted = connection.execute(
            POSTGRES_APPEND,
            {
                "scene_id": scene_id,
                "expected": expected_head,
                "count": count,
                "batch_id": batch_id,
                "recorded_at": now,
                "batch_time": batch_time,
                **{f"{column}s": [row[column] for row in rows] for column in ARRAY_COLUMNS},
            },
        ).rowcount
        if inserted != count:
            raise _moved(scene_id, expected_head)
        return
    if dialect == "sqlite":
        # The driver's own statements: SQLAlchemy's compilation and parameter handling cost
        # more than SQLite's commit for a batch of one (`bench.bench_store versus`). Its error
        # handling still applies (exec_driver_sql).
        head = (count, scene_id, expected_head)
        if connection.exec_driver_sql(SQLITE_HEAD_UPDATE, head).rowcount != 1:
            raise _moved(scene_id, expected_head)
        values = [tuple(row[column] for column in EVENT_COLUMNS) for row in rows]
        connection.exec_driver_sql(SQLITE_INSERT, values)
        return
    parameters = {"scene_id": scene_id, "expected": expected_head, "count": count}
    if connection.execute(HEAD_UPDATE, parameters).rowcount != 1:
        raise _moved(scene_id, expected_head)
    connection.execute(events.insert(), rows)


def _moved(scene_id: str, expected_head: int) -> ConcurrencyConflict:
    """Somebody else appended first: the head is no longer the one this append read."""
    return ConcurrencyConflict(f"scene {scene_id!r}: head is not {expected_head}")
