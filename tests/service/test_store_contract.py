"""One contract for every store backend: the log, snapshots, migrations, commands and rebuild
(the queue's: tests/service/test_queue_contract.py)."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path

import orjson
import pytest
import sqlalchemy as sa

from core.errors import StateConflict
from core.events import Event, ObjectAdded
from core.params import Params
from core.state import SceneState
from service.bootstrap import Container
from service.commands import run_command
from service.settings import Settings
from service.store.engine import make_engine, write_transaction
from service.store.errors import (
    ConcurrencyConflict,
    SceneNotFound,
    SeqOutOfRange,
)
from service.store.projection import rebuild_scene
from service.store.snapshot_codec import SNAPSHOT_VERSION
from service.store.tables import events, snapshots, tracks
from tests.service.minimal_events import added, append_batch, missed, new_scene


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    """A snapshot after every append, so that as_of reads exercise snapshot + tail."""
    return Settings(data_dir=tmp_path / "data", snapshot_interval=1, lease_seconds=30.0)


def test_scene_starts_at_seq_zero_with_its_params_in_the_log(container: Container) -> None:
    params = Params.from_dict({"lifecycle": {"move_min_distance_m": 0.5}})
    scene = new_scene(container, "kitchen", params)
    assert scene.head_seq == 0
    [created] = container.log.read(scene.id)
    assert (created.seq, created.type) == (0, "scene_created")
    assert created.details["params"]["lifecycle"]["move_min_distance_m"] == 0.5
    assert container.log.load_state(scene.id).params == params
    with pytest.raises(SceneNotFound):
        container.log.scene("scn-nope")


def test_append_is_gapless_and_conflicts_on_a_stale_head(container: Container) -> None:
    scene = new_scene(container)
    assert append_batch(container, scene.id, [added("trk-000001"), added("trk-000002", 1.0)]) == (
        1,
        2,
    )
    assert append_batch(container, scene.id, [missed("trk-000001", 0.3, 1)]) == (3, 3)
    stale = container.log.load_state(scene.id, as_of=1)
    with pytest.raises(ConcurrencyConflict), container.uow.begin() as work:
        work.append(scene.id, stale, [missed("trk-000002", 0.3, 1)])
    assert container.log.scene(scene.id).head_seq == 3
    assert [e.seq for e in container.log.read(scene.id)] == [0, 1, 2, 3]


@pytest.mark.parametrize("size", [1, 20, 500])
def test_every_batch_size_stores_the_same_rows_and_conflicts_on_a_stale_head(
    container: Container, size: int
) -> None:
    scene = new_scene(container)
    batch: list[Event] = [added(f"trk-{i:06d}", float(i)) for i in range(1, size + 1)]
    batch[0] = missed("trk-000001", 0.25, 0)  # a row with no observation, in the same batch
    # Text that JSON and SQL both escape, and text beyond ASCII, in a column and in details.
    tricky = 'f "1" \\ \u00e9\u2713\n\t[null]'
    last = batch[-1]
    if isinstance(last, ObjectAdded):
        last = replace(last, observations=(replace(last.observations[0], frame_id=tricky),))
    batch[-1] = replace(last, frame_id=tricky)
    clock = container.log.clock
    with write_transaction(container.engine) as connection:
        assert container.log.append(connection, scene.id, 0, batch, "b-1") == (1, size)
    with (
        pytest.raises(ConcurrencyConflict),
        write_transaction(container.engine) as connection,
    ):
        container.log.append(connection, scene.id, 0, batch, "b-2")
    stored = container.log.read(scene.id)
    assert [row.seq for row in stored] == list(range(size + 1))
    assert container.log.scene(scene.id).head_seq == size
    for row, event in zip(stored[1:], batch, strict=True):
        assert (row.type, row.track_id, row.state, row.frame_id, row.batch_id) == (
            event.type,
            event.track_id,
            event.state,
            event.frame_id,
            "b-1",
        )
        assert row.details == event.details()
        assert row.to_core() == event
        assert abs(row.recorded_at - clock()) < 60
    # The details column holds the event's JSON text exactly.
    with container.engine.connect() as connection:
        text = connection.execute(
            sa.select(events.c.details).where(events.c.scene_id == scene.id, events.c.seq == size)
        ).scalar_one()
    assert text == orjson.dumps(batch[-1].details()).decode()
    assert size == 1 or orjson.dumps(tricky).decode() in text


def test_two_writers_at_one_head_one_waits_then_conflicts(container: Container) -> None:
    scene = new_scene(container)
    log = container.log
    with write_transaction(container.engine) as first:
        assert log.append(first, scene.id, 0, [added("trk-000001")]) == (1, 1)

        def second() -> tuple[int, int] | None:
            with write_transaction(container.engine) as connection:
                return log.append(connection, scene.id, 0, [added("trk-000002")])

        with ThreadPoolExecutor(1) as pool:
            waiting = pool.submit(second)  # blocks on the first writer until it commits
            with pytest.raises(TimeoutError):
                waiting.result(timeout=0.5)
            first.commit()
            with pytest.raises(ConcurrencyConflict):
                waiting.result(timeout=30)
    assert [row.track_id for row in log.read(scene.id)] == [None, "trk-000001"]


def test_rollback_leaves_no_gap_and_no_rows(container: Container) -> None:
    scene = new_scene(container)
    state = container.log.load_state(scene.id)
    with pytest.raises(RuntimeError), container.uow.begin() as work:
        work.append(scene.id, state, [added("trk-000001")])
        raise RuntimeError("crash before commit")
    assert container.log.scene(scene.id).head_seq == 0
    assert append_batch(container, scene.id, [added("trk-000001")]) == (1, 1)


def test_read_filters_and_pages(container: Container) -> None:
    scene = new_scene(container)
    append_batch(container, scene.id, [added(f"trk-{i:06d}", float(i)) for i in range(1, 8)])
    page = container.log.read(scene.id, after=2, limit=3)
    assert [e.seq for e in page] == [3, 4, 5]
    assert [e.seq for e in container.log.read(scene.id, track_id="trk-000004")] == [4]
    assert len(container.log.read(scene.id, event_type="add")) == 7


def test_as_of_snapshot_plus_tail_equals_replay_and_is_stable(container: Container) -> None:
    scene = new_scene(container)
    append_batch(container, scene.id, [added("trk-000001"), added("trk-000002", 2.0)])
    before = container.log.load_state(scene.id, as_of=2).to_dict()
    append_batch(container, scene.id, [missed("trk-000001", 0.3, 1), missed("trk-000002", 0.3, 1)])
    append_batch(container, scene.id, [missed("trk-000001", -0.4, 2)])
    assert container.log.load_state(scene.id, as_of=2).to_dict() == before
    for seq in range(0, 6):
        assert (
            container.log.load_state(scene.id, as_of=seq).to_dict()
            == container.log.replay(scene.id, up_to=seq).to_dict()
        )
    with pytest.raises(SeqOutOfRange):
        container.log.load_state(scene.id, as_of=6)


def test_snapshot_in_another_format_is_ignored(container: Container) -> None:
    scene = new_scene(container)
    append_batch(container, scene.id, [added("trk-000001")])
    with container.engine.begin() as connection:
        connection.execute(sa.text("UPDATE snapshots SET format_version = 999"))
    assert container.log.load_state(scene.id).to_dict() == container.log.replay(scene.id).to_dict()


def test_rebuild_rewrites_snapshots_of_an_older_format_without_a_difference(
    container: Container,
) -> None:
    scene = new_scene(container)
    append_batch(container, scene.id, [added("trk-000001"), added("trk-000002", 2.0)])
    append_batch(container, scene.id, [missed("trk-000001", 0.3, 1)])
    seqs = container.log.snapshot_seqs(scene.id)
    assert seqs
    with container.engine.begin() as connection:
        connection.execute(sa.update(snapshots).values(format_version=SNAPSHOT_VERSION - 1))
    report = rebuild_scene(container.log, scene.id)
    assert report.identical and report.snapshots_reencoded == len(seqs)
    with container.engine.begin() as connection:
        formats = connection.execute(
            sa.select(snapshots.c.seq, snapshots.c.format_version).where(
                snapshots.c.scene_id == scene.id
            )
        ).all()
    assert sorted(formats) == [(seq, SNAPSHOT_VERSION) for seq in seqs]
    report = rebuild_scene(container.log, scene.id)
    assert report.identical and report.snapshots_reencoded == 0


def test_rebuild_reports_no_difference_then_detects_a_tampered_projection(
    container: Container,
) -> None:
    scene = new_scene(container)
    append_batch(container, scene.id, [added("trk-000001"), added("trk-000002", 2.0)])
    append_batch(container, scene.id, [missed("trk-000001", 0.3, 1)])
    report = rebuild_scene(container.log, scene.id)
    assert report.identical and report.events == 4
    with container.engine.begin() as connection:
        connection.execute(
            sa.update(tracks).where(tracks.c.track_id == "trk-000002").values(label="bowl")
        )
    report = rebuild_scene(container.log, scene.id)
    assert report.tracks_differ == ["trk-000002"]
    assert rebuild_scene(container.log, scene.id).identical  # the rebuild repaired it


def test_initial_state_is_empty(container: Container) -> None:
    scene = new_scene(container)
    state = container.log.load_state(scene.id)
    assert state.head_seq == 0 and state.tracks == {} and isinstance(state, SceneState)


def test_concurrent_migrations_are_serialized(
    backend: str, tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    """API and workers all run `pbdag migrate` work at startup; on a fresh database they must not race."""
    import os
    import subprocess
    import sys

    if backend == "sqlite":
        url = f"sqlite:///{tmp_path / 'fresh.db'}"
    else:
        base, schema = request.getfixturevalue("postgres_schema_url")
        url = f"{base}?options=-csearch_path%3D{schema}"
    env = {**os.environ, "PBDAG_DATABASE_URL": url, "PBDAG_DATA_DIR": str(tmp_path / "data")}
    processes = [
        subprocess.Popen(
            [sys.executable, "-m", "service.cli", "migrate"], env=env, stderr=subprocess.PIPE
        )
        for _ in range(4)
    ]
    errors = [process.communicate(timeout=120)[1].decode() for process in processes]
    assert [process.returncode for process in processes] == [0, 0, 0, 0], errors
    engine = make_engine(url)
    try:
        with engine.connect() as connection:
            assert (
                connection.exec_driver_sql("select version_num from alembic_version").scalar()
                == newest_revision()
            )
    finally:
        engine.dispose()


def test_a_command_is_decided_again_when_the_head_moved(container: Container) -> None:
    """Verdicts and freezes race with the worker: the expected-head append retries on a new head."""
    scene = new_scene(container)
    calls: list[int] = []

    def decide_command(state: SceneState) -> list[Event]:
        calls.append(state.head_seq)
        if len(calls) == 1:  # somebody appends between our read and our append
            append_batch(container, scene.id, [added("trk-000001")])
        return (
            [missed("trk-000001", 0.3, 1)]
            if "trk-000001" in state.tracks
            else [added("trk-000002", 3.0)]
        )

    events, appended = run_command(container, scene.id, decide_command)
    assert calls == [0, 1] and appended.seqs == (2, 2) and events[0].type == "update"


def test_a_head_that_keeps_moving_is_a_conflict_and_a_refused_command_writes_nothing(
    container: Container,
) -> None:
    scene = new_scene(container)
    calls: list[int] = []

    def always_overtaken(state: SceneState) -> list[Event]:
        calls.append(state.head_seq)
        append_batch(container, scene.id, [added(f"trk-{len(calls):06d}")])
        return [added("trk-999999")]

    with pytest.raises(ConcurrencyConflict) as moving:
        run_command(container, scene.id, always_overtaken)
    assert calls == [0, 1, 2, 3, 4]  # decided on each new head, ATTEMPTS times
    assert (moving.value.detail, moving.value.field) == (
        f"scene {scene.id!r} kept changing; try again",
        "scene_id",
    )

    def refused(state: SceneState) -> list[Event]:
        raise StateConflict("the fixture is not confirmed")

    with pytest.raises(StateConflict):
        run_command(container, scene.id, refused)
    assert container.log.scene(scene.id).head_seq == 5  # the five appends of the other writer


def newest_revision() -> str:
    """The head of the Alembic revisions under migrations/ (one head: a fork fails here)."""
    from alembic.config import Config
    from alembic.script import ScriptDirectory

    from service.store.engine import MIGRATIONS_DIR

    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    head = ScriptDirectory.from_config(config).get_current_head()
    assert head is not None
    return head
