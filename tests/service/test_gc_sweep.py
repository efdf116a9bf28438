"""`pbdag gc` interrupted at each step, and blobs no batch names: the next gc sweeps them, and no
row a worker may claim ever points at a deleted blob (on every store backend)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from service.bootstrap import Container
from service.retention import collect
from service.store.blobs import ORPHAN_GRACE_SECONDS, BlobNotFound, FileBlobStore
from service.worker import Worker
from tests.service.invariants import blobs_agree_with_rows, projections_equal_a_replay
from tests.wire_scenes import batch


class Killed(BaseException):
    """The process died here (not an Exception: nothing may catch it on the way out)."""


def posted_and_done(client: TestClient, container: Container, count: int) -> str:
    scene_id = str(client.post("/v1/scenes", json={"name": "gc"}).json()["id"])
    for index in range(count):
        body = batch(f"b{index}", index)
        assert client.post(f"/v1/scenes/{scene_id}/batches", json=body).status_code == 202
    assert Worker(container).drain() == count
    return scene_id


def test_gc_killed_between_marking_and_deleting_is_finished_by_the_next(
    client: TestClient, container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    scene_id = posted_and_done(client, container, 3)
    original = container.blobs.delete
    deleted: list[str] = []

    def killed_after_one(key: str) -> bool:
        if deleted:
            raise Killed
        deleted.append(key)
        return original(key)

    monkeypatch.setattr(container.blobs, "delete", killed_after_one)
    with pytest.raises(Killed):
        collect(container, 0.0, clock=lambda: time.time() + 10)
    monkeypatch.setattr(container.blobs, "delete", original)
    records = container.queue.of_scene(scene_id)
    assert all(r.blob_collected_at is not None for r in records)  # all marked
    assert len(set(container.blobs.keys())) == 2  # but two blobs outlived the kill

    report = collect(container, 0.0, clock=lambda: time.time() + 10)
    assert report.batches == 0 and report.swept_collected == 2 and report.swept_unnamed == 0
    assert blobs_agree_with_rows(container, scene_id) == set()
    assert collect(container, 0.0).swept_collected == 0  # nothing left
    projections_equal_a_replay(container, scene_id)


def test_gc_killed_before_marking_leaves_everything_for_the_next(
    client: TestClient, container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    scene_id = posted_and_done(client, container, 2)

    def killed(ids: list[int]) -> None:
        raise Killed

    monkeypatch.setattr(container.queue, "mark_collected", killed)
    with pytest.raises(Killed):
        collect(container, 0.0, clock=lambda: time.time() + 10)
    monkeypatch.undo()
    assert len(blobs_agree_with_rows(container, scene_id)) == 2  # nothing marked, nothing deleted
    assert collect(container, 0.0, clock=lambda: time.time() + 10).blobs_deleted == 2
    assert blobs_agree_with_rows(container, scene_id) == set()


def store_environment(container: Container, request: pytest.FixtureRequest) -> dict[str, str]:
    """The environment a `pbdag` process needs to open this test's store."""
    env = {**os.environ, "PBDAG_DATA_DIR": str(container.settings.data_dir)}
    if container.engine.dialect.name == "sqlite":
        env["PBDAG_DATABASE_URL"] = str(container.engine.url)
    else:
        url, schema = request.getfixturevalue("postgres_schema_url")
        env["PBDAG_DATABASE_URL"] = f"{url}?options=-csearch_path%3D{schema}"
    return env


@pytest.mark.parametrize("step", ["marking", "deleting", "deleted-one"])
def test_gc_sigkilled_at_each_step_leaves_what_the_next_gc_finishes(
    client: TestClient, container: Container, request: pytest.FixtureRequest, step: str
) -> None:
    scene_id = posted_and_done(client, container, 3)
    killer = [sys.executable, "-m", "tests.service.gc_killer", step]
    env = store_environment(container, request)
    died = subprocess.run(killer, env=env, capture_output=True, text=True, timeout=120)
    assert died.returncode == -signal.SIGKILL, died.stderr[-2000:]
    left = len(set(container.blobs.keys()))
    assert left == {"marking": 3, "deleting": 3, "deleted-one": 2}[step]
    report = collect(container, 0.0, clock=lambda: time.time() + 10)
    assert report.blobs_deleted + report.swept_collected == left
    assert blobs_agree_with_rows(container, scene_id) == set()
    projections_equal_a_replay(container, scene_id)


def test_a_blob_no_row_names_is_swept_once_past_the_grace(
    client: TestClient, container: Container
) -> None:
    scene_id = posted_and_done(client, container, 1)
    assert client.post(f"/v1/scenes/{scene_id}/batches", json=batch("queued", 5)).status_code == 202
    orphan = container.blobs.put(b"a batch whose row never committed")
    young = collect(container, 10**9)  # retention far away: nothing expires
    assert young.swept_unnamed == 0 and container.blobs.get(orphan)
    later = time.time() + ORPHAN_GRACE_SECONDS + 60
    dry = collect(container, 10**9, dry_run=True, clock=lambda: later)
    assert dry.swept_unnamed == 1 and container.blobs.get(orphan)
    report = collect(container, 10**9, clock=lambda: later)
    assert report.swept_unnamed == 1
    with pytest.raises(BlobNotFound):
        container.blobs.get(orphan)
    assert (
        len(blobs_agree_with_rows(container, scene_id)) == 2
    )  # the done and the queued batch's blobs
    assert Worker(container).drain() == 1  # the queued batch still has its body


def test_leftovers_of_interrupted_writes_go_once_past_the_grace(tmp_path: Path) -> None:
    store = FileBlobStore(tmp_path / "blobs")
    key = store.put(b"kept")
    shard = tmp_path / "blobs" / key[:2] / key[2:4]
    old, fresh = shard / ".incoming-old", shard / ".incoming-fresh"
    old.write_bytes(b"half a blob")
    fresh.write_bytes(b"a blob being written")
    long_ago = time.time() - ORPHAN_GRACE_SECONDS - 60
    os.utime(old, (long_ago, long_ago))
    assert store.remove_leftovers(time.time() - ORPHAN_GRACE_SECONDS) == 1
    assert not old.exists() and fresh.exists() and store.get(key) == b"kept"


def test_storing_bytes_again_refreshes_the_blob_for_the_sweep(tmp_path: Path) -> None:
    store = FileBlobStore(tmp_path / "blobs")
    key = store.put(b"posted twice")
    path = tmp_path / "blobs" / key[:2] / key[2:4] / key
    long_ago = time.time() - ORPHAN_GRACE_SECONDS - 60
    os.utime(path, (long_ago, long_ago))
    store.put(b"posted twice")
    stored = store.stored_at(key)
    assert stored is not None and stored > time.time() - 60
