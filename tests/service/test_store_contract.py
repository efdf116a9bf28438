"""One contract for every store backend: the log, the queue, snapshots and rebuild."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
import sqlalchemy as sa

from core.errors import StateConflict
from core.events import Event
from core.params import Params
from core.state import SceneState
from service.bootstrap import Container
from service.commands import create_scene, run_command
from service.settings import Settings
from service.store.append_sql import ONE_STATEMENT_MAX
from service.store.engine import make_engine, write_transaction
from service.store.errors import (
    BatchConflict,
    ConcurrencyConflict,
    LeaseLost,
    SceneNotFound,
    SeqOutOfRange,
)
from service.store.event_log import SceneRecord
from service.store.projection import rebuild_scene
from service.store.queue_records import (
    Admission,
    BatchRecord,
    Claim,
    NotRequeueable,
    QueueFull,
    QuotaExceeded,
)
from service.store.snapshot_codec import SNAPSHOT_VERSION
from service.store.tables import snapshots, tracks
from tests.service.minimal_events import added, append_batch, missed


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    """A snapshot after every append, so that as_of reads exercise snapshot + tail."""
    return Settings(data_dir=tmp_path / "data", snapshot_interval=1, lease_seconds=30.0)


def new_scene(container: Container, name: str = "s", params: Params | None = None) -> SceneRecord:
    """A scene through the one write path."""
    return create_scene(container, name, params or Params())


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


@pytest.mark.parametrize("size", [1, ONE_STATEMENT_MAX, ONE_STATEMENT_MAX + 1, 200])
def test_every_batch_size_stores_the_same_rows_and_conflicts_on_a_stale_head(
    container: Container, size: int
) -> None:
    scene = new_scene(container)
    batch: list[Event] = [added(f"trk-{i:06d}", float(i)) for i in range(1, size + 1)]
    batch[0] = missed("trk-000001", 0.25, 0)  # a row with no observation, in the same batch
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


BOUNDS = Admission(max_queued=100, max_blob_bytes=10**9, retry_after_seconds=2)


class TestQueue:
    def submit(
        self,
        container: Container,
        scene_id: str,
        batch_id: str,
        sha: str = "a" * 64,
        size: int = 100,
        bounds: Admission = BOUNDS,
    ) -> tuple[BatchRecord, bool]:
        blob = f"blob-{batch_id}".encode().ljust(size, b".")
        return container.queue.submit(scene_id, batch_id, sha, blob, 1, bounds)

    def claim(self, container: Container, owner: str, lease_seconds: float) -> Claim:
        """The lease the test expects the queue to hand out."""
        claim = container.queue.claim(owner, lease_seconds)
        assert claim is not None
        return claim

    def record(self, container: Container, scene_id: str, batch_id: str) -> BatchRecord:
        """The queued batch's record, which the test expects to exist."""
        record = container.queue.get(scene_id, batch_id)
        assert record is not None
        return record

    def test_submit_is_idempotent_and_conflicts_on_new_content(self, container: Container) -> None:
        scene = new_scene(container)
        first, created = self.submit(container, scene.id, "b1")
        again, created_again = self.submit(container, scene.id, "b1")
        assert created and not created_again and again.id == first.id
        with pytest.raises(BatchConflict):
            self.submit(container, scene.id, "b1", sha="b" * 64)

    def test_concurrent_posts_of_one_batch_store_it_once(self, container: Container) -> None:
        """Six posts racing: one row, every caller gets it (PostgreSQL's UniqueViolation)."""
        scene = new_scene(container)
        with ThreadPoolExecutor(6) as pool:
            results = list(pool.map(lambda _: self.submit(container, scene.id, "b1"), range(6)))
        assert len({record.id for record, _created in results}) == 1
        assert sum(created for _record, created in results) == 1

    def test_a_full_queue_and_a_full_quota_refuse_new_batches_only(
        self, container: Container
    ) -> None:
        scene = new_scene(container)
        bounds = Admission(max_queued=2, max_blob_bytes=250, retry_after_seconds=3)
        self.submit(container, scene.id, "b1", bounds=bounds)
        self.submit(container, scene.id, "b2", bounds=bounds)
        with pytest.raises(QueueFull) as full:
            self.submit(container, scene.id, "b3", bounds=bounds)
        assert full.value.retry_after == 3
        assert self.submit(container, scene.id, "b2", bounds=bounds)[1] is False  # a re-post
        claim = self.claim(container, "w", 30)
        with container.uow.begin() as work:
            work.complete(claim, None)
        with pytest.raises(QuotaExceeded):  # 200 bytes stored, 100 more exceed 250
            self.submit(container, scene.id, "b3", bounds=bounds)
        assert container.queue.counts(scene.id) == {"done": 1, "queued": 1}

    def test_batches_of_one_scene_are_claimed_in_arrival_order_one_at_a_time(
        self, container: Container
    ) -> None:
        one = new_scene(container, "one")
        two = new_scene(container, "two")
        for batch_id in ("a1", "a2"):
            self.submit(container, one.id, batch_id)
        self.submit(container, two.id, "b1")
        first = self.claim(container, "w1", 30)
        second = self.claim(container, "w2", 30)
        assert (first.batch_id, second.batch_id) == ("a1", "b1")
        assert container.queue.claim("w3", 30) is None  # a2 waits for a1
        with container.uow.begin() as work:
            work.complete(first, None)
        assert self.claim(container, "w3", 30).batch_id == "a2"

    def test_completion_is_fenced_by_the_lease(self, container: Container) -> None:
        scene = new_scene(container)
        self.submit(container, scene.id, "b1")
        claim = self.claim(container, "w1", 30)
        stolen = type(claim)(
            claim.id, claim.scene_id, claim.batch_id, claim.blob_key, "intruder", 1
        )
        state = container.log.load_state(scene.id)
        with pytest.raises(LeaseLost), container.uow.begin() as work:
            appended = work.append(scene.id, state, [added("trk-000001")], batch_id="b1")
            work.complete(stolen, appended.seqs)
        assert container.log.scene(scene.id).head_seq == 0  # the append rolled back with it
        assert self.record(container, scene.id, "b1").status == "running"
        assert not container.queue.renew(stolen, 30) and container.queue.renew(claim, 30)

    def test_a_failed_attempt_waits_for_its_retry(self, container: Container) -> None:
        now = [1000.0]
        container.queue.clock = lambda: now[0]
        scene = new_scene(container)
        self.submit(container, scene.id, "b1")
        claim = self.claim(container, "w", 30)
        container.queue.retry_later(claim, "OperationalError: will retry", 4.0)
        record = self.record(container, scene.id, "b1")
        assert (record.status, record.not_before) == ("failed", 1004.0)
        assert container.queue.claim("w", 30) is None  # not yet due
        now[0] = 1004.5
        assert self.claim(container, "w", 30).attempts == 2

    def test_a_renewed_lease_does_not_expire_and_an_abandoned_one_does(
        self, container: Container
    ) -> None:
        now = [1000.0]
        container.queue.clock = lambda: now[0]
        scene = new_scene(container)
        self.submit(container, scene.id, "b1")
        claim = self.claim(container, "w", 10)
        now[0] = 1008.0
        assert container.queue.renew(claim, 10)
        now[0] = 1015.0  # past the first lease, inside the renewed one
        assert container.queue.expired() == []
        now[0] = 1019.0
        assert [c.batch_id for c in container.queue.expired()] == ["b1"]

    def test_a_dead_batch_is_recorded_in_the_log_and_can_be_requeued(
        self, container: Container
    ) -> None:
        scene = new_scene(container)
        self.submit(container, scene.id, "b1")
        self.submit(container, scene.id, "b2")
        claim = self.claim(container, "w", 30)
        state = container.log.load_state(scene.id)
        with container.uow.begin() as work:
            work.skip(claim, state, "rejected: frames[0].depth: not a PNG")
        [skipped] = container.log.read(scene.id, event_type="batch_skipped")
        assert (skipped.batch_id, skipped.details["reason"]) == (
            "b1",
            "rejected: frames[0].depth: not a PNG",
        )
        record = self.record(container, scene.id, "b1")
        assert record.status == "dead" and record.error == "rejected: frames[0].depth: not a PNG"
        assert self.claim(container, "w", 30).batch_id == "b2"  # the scene moved on
        with pytest.raises(NotRequeueable):
            container.queue.requeue(scene.id, "b2")  # running, not dead
        requeued = container.queue.requeue(scene.id, "b1")
        assert (requeued.status, requeued.attempts, requeued.error) == ("queued", 0, None)


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
