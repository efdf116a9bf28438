"""A worker that cannot write (a full disk, a read-only database): it keeps the failure it
could not record and records it once writing works, claims nothing meanwhile, says so in its
health, and `pbdag worker --drain` exits non-zero while work is left undone."""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import pytest
import sqlalchemy as sa
from fastapi.testclient import TestClient

from service.app import create_app
from service.bootstrap import Container, build_container
from service.settings import Settings
from service.store.errors import StoreUnavailable
from service.worker import Worker
from tests.clients import local_client
from tests.service.invariants import blobs_agree_with_rows, projections_equal_a_replay
from tests.wire_scenes import batch

DISK_FULL = StoreUnavailable("writing", OSError(28, "No space left on device"))


def queued(client: TestClient, count: int) -> str:
    scene_id = str(client.post("/v1/scenes", json={"name": "full disk"}).json()["id"])
    for index in range(count):
        body = batch(f"b{index}", index)
        assert client.post(f"/v1/scenes/{scene_id}/batches", json=body).status_code == 202
    return scene_id


def test_a_failure_that_cannot_be_recorded_is_recorded_once_writing_works(
    client: TestClient, container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    scene_id = queued(client, 2)
    worker = Worker(container, seed=0)

    def cannot_write(*_args: object, **_kwargs: object) -> None:
        raise DISK_FULL

    with monkeypatch.context() as broken:
        broken.setattr(container.uow, "begin", cannot_write)  # the append fails
        broken.setattr(container.queue, "retry_later", cannot_write)  # and so does its record
        assert worker.run_once()
        assert worker.unrecorded == 1 and not worker.health.healthy
        assert "cannot record the failure of batch b0" in (worker.health.problem or "")
        assert "No space left on device" in (worker.health.problem or "")
        assert not worker.run_once()  # nothing else is claimed while the failure is held
        assert container.queue.counts(scene_id) == {"running": 1, "queued": 1}
    assert not worker.run_once()  # writing works: the failure is recorded, then b0 waits
    assert worker.unrecorded == 0 and worker.health.healthy
    record = container.queue.get(scene_id, "b0")
    assert record.status == "failed" and "will retry" in (record.error or "")
    container.engine.dispose()
    with container.engine.begin() as connection:  # the retry is due now
        connection.execute(sa.text("UPDATE batches SET not_before = 0"))
    assert worker.drain() == 2
    assert container.queue.counts(scene_id) == {"done": 2}
    assert len(blobs_agree_with_rows(container, scene_id)) == 2
    projections_equal_a_replay(container, scene_id)


def test_drain_exits_non_zero_when_the_disk_is_full_and_zero_once_it_is_not(
    tmp_path: Path,
) -> None:
    settings = Settings(data_dir=tmp_path / "data", allow_anonymous_local=True)
    with local_client(create_app(build_container(settings))) as client:
        scene_id = queued(client, 3)
    env = {
        **os.environ,
        "PBDAG_DATA_DIR": str(settings.data_dir),
        "PBDAG_LEASE_SECONDS": "1",
        "PBDAG_RETRY_BASE_SECONDS": "0.1",
    }
    env.pop("PBDAG_DATABASE_URL", None)

    def full_disk() -> None:  # no file may grow past 512 bytes: every write of SQLite fails
        resource.setrlimit(resource.RLIMIT_FSIZE, (512, 512))

    drain = [sys.executable, "-m", "service.cli", "worker", "--drain"]
    failed = subprocess.run(
        drain, env=env, capture_output=True, text=True, preexec_fn=full_disk, timeout=120
    )
    assert failed.returncode == 1, failed.stderr[-2000:]
    last = failed.stderr.strip().splitlines()[-1]
    assert "pbdag worker:" in last and ("left undone" in last or "queue failed" in last), last
    assert "Traceback" not in failed.stderr, failed.stderr[-3000:]
    time.sleep(1.5)  # past any lease the full-disk worker may have held
    done = subprocess.run(drain, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert build_container(settings).queue.counts(scene_id) == {"done": 3}


def test_healthz_shows_the_in_process_worker_degraded_while_it_cannot_write(
    container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    def cannot_write(*_args: object, **_kwargs: object) -> None:
        raise DISK_FULL

    def health_when(client: TestClient, wanted: str) -> dict[str, object]:
        for _ in range(200):
            health: dict[str, object] = client.get("/healthz").json()
            if health["status"] == wanted:
                return health
            time.sleep(0.05)
        raise AssertionError(f"/healthz never said {wanted}: {health}")

    with local_client(create_app(container, run_worker=True)) as client:
        assert client.get("/healthz").json()["worker"]["healthy"] is True
        scene_id = client.post("/v1/scenes", json={"name": "full disk"}).json()["id"]
        with monkeypatch.context() as broken:
            broken.setattr(container.uow, "begin", cannot_write)  # the append and its record
            broken.setattr(container.queue, "retry_later", cannot_write)
            posted = client.post(f"/v1/scenes/{scene_id}/batches", json=batch("b0", 0))
            assert posted.status_code == 202
            degraded = health_when(client, "degraded")
            worker = degraded["worker"]
            assert isinstance(worker, dict) and worker["healthy"] is False
            assert "No space left on device" in str(worker["problem"])
        ok = health_when(client, "ok")
        assert ok["worker"] == {"healthy": True, "problem": None, "since": None}
        metrics = client.get("/metrics").text
        assert "pbdag_worker_healthy 1.0" in metrics
