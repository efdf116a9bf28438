"""Minimal events for store tests, a scene made through the one write path, and a log row as an
older version wrote it."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import orjson
import sqlalchemy as sa

from core.events import Event, ObjectAdded, VisibleMiss
from core.params import Params
from core.values import Observation
from service.bootstrap import Container
from service.commands import create_scene
from service.store.engine import write_transaction
from service.store.event_log import SceneRecord
from service.store.tables import events as events_table
from service.store.tables import scenes as scenes_table


def added(track_id: str, x: float = 0.0) -> ObjectAdded:
    """A minimal add event."""
    return ObjectAdded(
        track_id=track_id,
        state="tentative",
        frame_id="f",
        observations=(
            Observation(
                frame_id="f",
                label="mug",
                score=0.9,
                center=(x, 0.0, 1.0),
                extent=(0.1, 0.1, 0.1),
                valid_pixels=100,
                parent=None,
            ),
        ),
        embedding_sum=None,
        embedding_count=0,
        timestamp=1.0,
        existence_logodds=1.0,
        p_exist=0.73,
        batches_observed=1,
        parent_evidence={},
    )


def an_add(extent_x: float) -> ObjectAdded:
    """A minimal add whose box is `extent_x` wide."""
    return replace(
        added("trk-000001"),
        observations=(replace(added("trk-000001").observations[0], extent=(extent_x, 0.1, 0.1)),),
    )


def poison_the_log(container: Container, scene_id: str) -> int:
    """Append an event as an older version stored it: NaN written as null."""
    record = orjson.loads(orjson.dumps(an_add(0.1).details()))
    record["observations"][0]["extent"] = [None, None, None]
    with write_transaction(container.engine) as connection:
        head = connection.execute(
            sa.select(scenes_table.c.head_seq).where(scenes_table.c.id == scene_id)
        ).scalar_one()
        connection.execute(
            events_table.insert().values(
                scene_id=scene_id,
                seq=head + 1,
                type="add",
                track_id="trk-000099",
                state="tentative",
                batch_id="old-poison",
                frame_id="f0",
                recorded_at=0.0,
                details=orjson.dumps(record).decode(),
            )
        )
        connection.execute(
            sa.update(scenes_table).where(scenes_table.c.id == scene_id).values(head_seq=head + 1)
        )
    return int(head + 1)


def missed(track_id: str, logodds: float, misses: int) -> VisibleMiss:
    """A visible-miss update."""
    return VisibleMiss(
        track_id=track_id,
        state="tentative",
        frame_id="f",
        samples_passed=9,
        samples_total=27,
        existence_logodds=logodds,
        p_exist=0.5,
        visible_misses=misses,
    )


def append_batch(
    container: Container,
    scene_id: str,
    events: Sequence[Event],
    batch_id: str | None = None,
    batch_time: float | None = None,
) -> tuple[int, int] | None:
    """Append at the current head through the one write path, as the worker does (with the
    batch's time on the robot's clock when given)."""
    state = container.log.load_state(scene_id)
    with container.uow.begin() as work:
        return work.append(scene_id, state, events, batch_id=batch_id, batch_time=batch_time).seqs


def new_scene(container: Container, name: str = "s", params: Params | None = None) -> SceneRecord:
    """A scene through the one write path."""
    return create_scene(container, name, params or Params())
