"""The robot's clock in the log (events.batch_time) and `as_of_time` resolved against it, on
every backend: the last seq a batch appended at or before a time."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import sqlalchemy as sa
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.config import Config
from alembic.migration import MigrationContext

from core.params import Params
from service.bootstrap import Container
from service.commands import create_scene
from service.store.engine import MIGRATIONS_DIR, make_engine
from service.store.errors import NonFiniteEvent
from service.store.tables import events, metadata
from tests.service.minimal_events import added, append_batch, missed


def batch_times(container: Container, scene_id: str) -> list[tuple[int, float | None]]:
    with container.engine.connect() as connection:
        rows = connection.execute(
            sa.select(events.c.seq, events.c.batch_time)
            .where(events.c.scene_id == scene_id)
            .order_by(events.c.seq)
        ).all()
    return [(int(seq), time) for seq, time in rows]


def test_a_batchs_events_carry_its_time_and_commands_none(container: Container) -> None:
    scene = create_scene(container, "clock", Params())
    assert append_batch(
        container, scene.id, [added("trk-000001"), added("trk-000002", 2.0)], "b1", 10.0
    ) == (1, 2)
    assert append_batch(container, scene.id, [missed("trk-000001", 0.2, 1)], None) == (3, 3)
    many = [added(f"trk-{i:06d}", float(i)) for i in range(3, 43)]
    first, last = append_batch(container, scene.id, many, "b2", 20.0) or (0, 0)
    assert batch_times(container, scene.id) == [
        (0, None),
        (1, 10.0),
        (2, 10.0),
        (3, None),
        *((seq, 20.0) for seq in range(first, last + 1)),
    ]
    stored = container.log.read(scene.id, after=0, limit=1)
    assert stored[0].batch_time == 10.0


def test_seq_at_time_is_the_last_seq_a_batch_appended_at_or_before_it(
    container: Container,
) -> None:
    scene = create_scene(container, "clock", Params())
    append_batch(container, scene.id, [added("trk-000001"), added("trk-000002", 2.0)], "b1", 10.0)
    append_batch(container, scene.id, [missed("trk-000001", 0.2, 1)], "b2", 20.0)
    append_batch(container, scene.id, [missed("trk-000002", 0.2, 1)], "b3", 15.0)  # stepped back
    append_batch(container, scene.id, [missed("trk-000001", 0.1, 2)], None)  # a command: no time
    at = container.log.seq_at_time
    assert at(scene.id, 9.999) is None
    assert [at(scene.id, t) for t in (10.0, 14.9, 15.0, 19.0, 20.0, 1e9)] == [2, 2, 4, 4, 4, 4]
    assert at("no-such-scene", 1e9) is None


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_a_non_finite_batch_time_appends_nothing(container: Container, bad: float) -> None:
    scene = create_scene(container, "clock", Params())
    with pytest.raises(NonFiniteEvent) as raised:
        append_batch(container, scene.id, [added("trk-000001")], "b1", bad)
    assert raised.value.field == "batch_time"
    assert container.log.scene(scene.id).head_seq == 0


def test_migration_0007_leaves_older_rows_without_a_time(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'old.db'}"
    engine = make_engine(url)
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    try:
        with engine.begin() as connection:
            config.attributes["connection"] = connection
            command.upgrade(config, "0006")
            connection.exec_driver_sql(
                "INSERT INTO scenes (id, name, params, head_seq, created_at) "
                "VALUES ('s', 's', '{}', 1, 0)"
            )
            connection.exec_driver_sql(
                "INSERT INTO events (scene_id, seq, type, batch_id, recorded_at, details) "
                "VALUES ('s', 1, 'fixture_evidence', 'b', 0, '{}')"
            )
        with engine.begin() as connection:
            config.attributes["connection"] = connection
            command.upgrade(config, "head")
        with engine.connect() as connection:
            assert connection.exec_driver_sql("SELECT batch_time FROM events").all() == [(None,)]
            diffs = compare_metadata(MigrationContext.configure(connection), metadata)
        assert [d for d in diffs if "events" in repr(d)] == []
    finally:
        engine.dispose()
