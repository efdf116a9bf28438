"""`pbdag rebuild` beside a worker that appends: the rebuilt projections hold every event, and
the report never calls projections identical that are not (on both backends)."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import sqlalchemy as sa

from core.params import Params
from service.bootstrap import Container
from service.commands import create_scene
from service.settings import Settings
from service.store import projection
from service.store.engine import write_transaction
from service.store.projection import rebuild_scene
from service.store.tables import tracks
from tests.service.minimal_events import added, append_batch, missed


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    """Snapshots every other append, so that appends during a rebuild write snapshots too."""
    return Settings(data_dir=tmp_path / "data", snapshot_interval=2, lease_seconds=30.0)


def track_ids(container: Container, scene_id: str) -> list[str]:
    with container.engine.connect() as connection:
        rows = connection.execute(sa.select(tracks.c.track_id).where(tracks.c.scene_id == scene_id))
        return sorted(rows.scalars())


def test_a_batch_appended_between_the_replay_and_the_write_is_in_the_projections(
    container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    scene = create_scene(container, "live", Params())
    append_batch(container, scene.id, [added("trk-000001"), added("trk-000002", 2.0)])
    append_batch(container, scene.id, [missed("trk-000001", 0.3, 1)])
    original = write_transaction

    @contextmanager
    def after_a_worker_appended(engine: sa.Engine) -> Iterator[sa.Connection]:
        # The replay has ended; a worker finishes a batch before the rebuild writes.
        append_batch(container, scene.id, [added("trk-000003", 4.0)], batch_id="late")
        with original(engine) as connection:
            yield connection

    monkeypatch.setattr(projection, "write_transaction", after_a_worker_appended)
    report = rebuild_scene(container.log, scene.id)
    monkeypatch.setattr(projection, "write_transaction", original)
    assert report.events == 5 and report.identical, report
    assert track_ids(container, scene.id) == ["trk-000001", "trk-000002", "trk-000003"]
    assert rebuild_scene(container.log, scene.id).identical


def test_rebuilds_during_a_stream_of_appends_report_identical_and_lose_nothing(
    container: Container,
) -> None:
    scene = create_scene(container, "stream", Params())
    appended = 40
    failures: list[BaseException] = []

    def worker() -> None:
        try:
            for k in range(appended):
                append_batch(container, scene.id, [added(f"trk-{k:06d}", float(k))], f"b{k}")
        except BaseException as error:  # reported by the test below
            failures.append(error)

    thread = threading.Thread(target=worker)
    thread.start()
    reports = []
    while thread.is_alive():
        reports.append(rebuild_scene(container.log, scene.id))
    thread.join()
    reports.append(rebuild_scene(container.log, scene.id))
    assert not failures, failures
    assert len(reports) >= 2
    assert all(report.identical for report in reports), [r for r in reports if not r.identical]
    assert reports[-1].events == appended + 1
    assert track_ids(container, scene.id) == [f"trk-{k:06d}" for k in range(appended)]
    logged = [event.seq for event in container.log.read(scene.id)]
    assert logged == list(range(appended + 1)), "an event lost or duplicated"
