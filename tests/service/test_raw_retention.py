"""Raw batch retention and `pbdag gc`, on every store backend: compact blobs, the old JSON blobs,
idempotent re-posts, what gc keeps, what it removes, and what reads a collected batch."""

from __future__ import annotations

import hashlib
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from api_schema import BatchIn
from codec.canonical import canonical_json
from service.app import create_app
from service.auth import create_token
from service.bootstrap import Container, build_container
from service.cli import main
from service.deps import admission
from service.repair import repair_scene
from service.retention import collect
from service.settings import Settings, parse_duration
from service.store.blobs import BlobNotFound
from service.store.engine import write_transaction
from service.store.queue_records import BatchRecord, RawBatchCollected
from service.store.raw_batches import decode_raw_batch, raw_batch_format
from service.worker import Worker
from tests.clients import local_client
from tests.service.minimal_events import poison_the_log
from tests.wire_scenes import batch


class Clock:
    """A settable clock for the queue (when batches finish) and for gc."""

    def __init__(self, now: float) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock(container: Container) -> Clock:
    fake = Clock(1_000.0)
    container.queue.clock = fake
    return fake


@pytest.fixture
def client(container: Container, clock: Clock) -> Iterator[TestClient]:
    with local_client(create_app(container, run_worker=False)) as test_client:
        yield test_client


def new_scene(client: TestClient, name: str = "retention") -> str:
    return str(client.post("/v1/scenes", json={"name": name}).json()["id"])


def post(client: TestClient, scene_id: str, batch_id: str, index: int, *, mug: bool = True) -> int:
    response = client.post(f"/v1/scenes/{scene_id}/batches", json=batch(batch_id, index, mug=mug))
    return int(response.status_code)


def canonical_of(body: dict[str, Any]) -> bytes:
    """The canonical JSON the service hashes (the validated body, defaults filled in)."""
    return canonical_json(BatchIn.model_validate(body).model_dump(mode="json"))


def sha256_of(body: dict[str, Any]) -> str:
    return hashlib.sha256(canonical_of(body)).hexdigest()


def rows(container: Container, scene_id: str) -> dict[str, BatchRecord]:
    return {record.batch_id: record for record in container.queue.of_scene(scene_id)}


def test_posted_batches_are_compact_and_the_worker_reads_them(
    container: Container, client: TestClient
) -> None:
    scene_id = new_scene(client)
    assert post(client, scene_id, "b0", 0) == 202
    record = rows(container, scene_id)["b0"]
    stored = container.blobs.get(record.blob_key)
    canonical = canonical_of(batch("b0", 0))
    assert raw_batch_format(stored) == "compact"
    assert record.blob_bytes == len(stored) < len(canonical)
    assert decode_raw_batch(stored) == canonical
    assert record.content_sha256 == sha256_of(batch("b0", 0))
    assert Worker(container).drain() == 1
    done = rows(container, scene_id)["b0"]
    assert done.status == "done" and done.first_seq is not None


def test_an_old_json_blob_is_still_processed(container: Container, client: TestClient) -> None:
    """A data dir written before the compact format: the blob is the canonical JSON."""
    old_scene, new_scene_id = new_scene(client, "old"), new_scene(client, "new")
    canonical = canonical_of(batch("b0", 0))
    container.queue.submit(
        old_scene, "b0", sha256_of(batch("b0", 0)), canonical, 1, admission(container.settings)
    )
    assert post(client, new_scene_id, "b0", 0) == 202
    assert Worker(container).drain() == 2
    old, new = rows(container, old_scene)["b0"], rows(container, new_scene_id)["b0"]
    assert old.status == new.status == "done"
    assert [e.type for e in container.log.read(old_scene)] == [
        e.type for e in container.log.read(new_scene_id)
    ]
    # Re-posting it is recognised: the hash is over the canonical content in both formats.
    assert post(client, old_scene, "b0", 0) == 200


def test_a_repost_is_recognised_before_and_after_gc(
    container: Container, client: TestClient, clock: Clock
) -> None:
    scene_id = new_scene(client)
    assert post(client, scene_id, "b0", 0) == 202
    assert post(client, scene_id, "b0", 0) == 200
    Worker(container).drain()
    report = collect(container, 60.0, clock=lambda: clock.now + 3600)
    assert [record.batch_id for record in report.expired] == ["b0"]
    collected = rows(container, scene_id)["b0"]
    assert collected.blob_collected_at is not None
    with pytest.raises(BlobNotFound):
        container.blobs.get(collected.blob_key)
    assert post(client, scene_id, "b0", 0) == 200  # still the same batch: 200, not a new one
    with pytest.raises(BlobNotFound):  # and no blob is written again for it
        container.blobs.get(collected.blob_key)
    other = batch("b0", 5)
    assert client.post(f"/v1/scenes/{scene_id}/batches", json=other).status_code == 409
    assert len(container.queue.of_scene(scene_id)) == 1


def test_dry_run_changes_nothing_and_gc_removes_exactly_the_expired(
    container: Container, client: TestClient, clock: Clock
) -> None:
    scene_id = new_scene(client)
    post(client, scene_id, "old", 0)
    Worker(container).drain()  # finishes at 1000
    clock.now = 2_000.0
    post(client, scene_id, "recent", 1)
    Worker(container).drain()  # finishes at 2000
    post(client, scene_id, "queued", 2)  # received at 2000, never processed
    before = rows(container, scene_id)
    blobs_before = {r.batch_id: container.blobs.get(r.blob_key) for r in before.values()}
    at = 2_100.0  # retention 500 s: the cutoff is 1600

    dry = collect(container, 500.0, dry_run=True, clock=lambda: at)
    assert [r.batch_id for r in dry.expired] == ["old"]
    assert dry.bytes_freed == before["old"].blob_bytes and dry.blobs_deleted == 0
    assert rows(container, scene_id) == before
    assert {b: container.blobs.get(r.blob_key) for b, r in before.items()} == blobs_before

    report = collect(container, 500.0, clock=lambda: at)
    assert [r.batch_id for r in report.expired] == ["old"]
    assert report.bytes_freed == before["old"].blob_bytes and report.blobs_deleted == 1
    after = rows(container, scene_id)
    assert after["old"].blob_collected_at == clock.now
    assert after["old"] == replace(before["old"], blob_collected_at=clock.now)
    assert after["recent"] == before["recent"] and after["queued"] == before["queued"]
    with pytest.raises(BlobNotFound):
        container.blobs.get(before["old"].blob_key)
    for kept in ("recent", "queued"):
        assert container.blobs.get(before[kept].blob_key) == blobs_before[kept]
    # Events are kept forever: the collected batch's events still read.
    first_seq = before["old"].first_seq
    assert first_seq is not None and container.log.read(scene_id, after=first_seq - 1)

    # Later, everything finished is expired; a batch not yet done never is.
    again = collect(container, 0.0, clock=lambda: 1e9)
    assert [r.batch_id for r in again.expired] == ["recent"]
    assert container.blobs.get(before["queued"].blob_key) == blobs_before["queued"]
    assert collect(container, 0.0, clock=lambda: 1e9).batches == 0  # nothing left to collect
    assert Worker(container).drain() == 1  # the queued one still runs
    assert rows(container, scene_id)["queued"].status == "done"


def test_without_retention_nothing_is_collected(container: Container, client: TestClient) -> None:
    scene_id = new_scene(client)
    post(client, scene_id, "b0", 0)
    Worker(container).drain()
    assert collect(container, None, clock=lambda: 1e12).batches == 0
    assert rows(container, scene_id)["b0"].blob_collected_at is None


def test_collected_bytes_leave_the_scene_quota(
    container: Container, client: TestClient, clock: Clock
) -> None:
    scene_id = new_scene(client)
    post(client, scene_id, "b0", 0)
    size = rows(container, scene_id)["b0"].blob_bytes
    container.settings.max_scene_blob_bytes = size + size // 2
    assert post(client, scene_id, "b1", 1) == 507
    Worker(container).drain()
    collect(container, 0.0, clock=lambda: clock.now + 1)
    assert post(client, scene_id, "b1", 1) == 202


def test_a_collected_dead_batch_cannot_be_requeued_410(
    container: Container, client: TestClient, clock: Clock
) -> None:
    scene_id = new_scene(client)
    not_a_batch = b"\x00not a batch"  # the worker parks it dead at once
    container.queue.submit(scene_id, "bad", "0" * 64, not_a_batch, 1, admission(container.settings))
    Worker(container).drain()
    assert rows(container, scene_id)["bad"].status == "dead"
    assert "cannot be read" in (rows(container, scene_id)["bad"].error or "")
    collect(container, 0.0, clock=lambda: clock.now + 1)
    admin = create_token(container.engine, "operator", ["read", "write", "admin"]).token
    response = client.post(
        f"/v1/scenes/{scene_id}/batches/bad/requeue",
        headers={"Authorization": f"Bearer {admin}"},
    )
    assert response.status_code == 410, response.text
    problem = response.json()
    assert problem["field"] == "batch_id" and "'bad'" in problem["detail"]
    assert "pbdag gc" in problem["detail"]
    assert rows(container, scene_id)["bad"].status == "dead"  # nothing changed


def test_requeue_and_gc_race_one_of_them_wins(
    container: Container, client: TestClient, clock: Clock
) -> None:
    """gc read the candidates, then an operator requeued the batch: gc must not collect it."""
    scene_id = new_scene(client)
    not_a_batch = b"\x00not a batch"
    container.queue.submit(scene_id, "bad", "0" * 64, not_a_batch, 1, admission(container.settings))
    key = rows(container, scene_id)["bad"].blob_key
    Worker(container).drain()
    candidates = container.queue.finished_before(clock.now + 1)
    assert [r.batch_id for r in candidates] == ["bad"]
    container.queue.requeue(scene_id, "bad")
    marked, deletable = container.queue.mark_collected([r.id for r in candidates])
    assert marked == [] and deletable == set()
    assert container.blobs.get(key) == b"\x00not a batch"


def test_a_blob_held_by_another_uncollected_row_stays(
    container: Container, client: TestClient, clock: Clock
) -> None:
    """Old JSON blobs were shared by identical batches of two scenes (and `pbdag repair` copies
    rows): the blob goes only with the last row holding it."""
    first, second = new_scene(client, "a"), new_scene(client, "b")
    canonical = canonical_of(batch("b0", 0))
    bounds = admission(container.settings)
    for scene_id in (first, second):  # the same bytes: one blob, two rows
        container.queue.submit(scene_id, "b0", sha256_of(batch("b0", 0)), canonical, 1, bounds)
    key = rows(container, first)["b0"].blob_key
    assert rows(container, second)["b0"].blob_key == key
    worker = Worker(container)
    assert worker.drain() == 2
    one = rows(container, first)["b0"]
    marked, deletable = container.queue.mark_collected([one.id])
    assert [m.id for m in marked] == [one.id] and deletable == set()
    assert container.blobs.get(key) == canonical
    report = collect(container, 0.0, clock=lambda: clock.now + 1)
    assert [r.scene_id for r in report.expired] == [second] and report.blobs_deleted == 1
    with pytest.raises(BlobNotFound):
        container.blobs.get(key)


def test_a_worker_given_a_collected_batch_skips_it_naming_gc(
    container: Container, client: TestClient, clock: Clock
) -> None:
    """`pbdag repair` queues again a copy of a batch whose raw body was collected."""
    source, target = new_scene(client, "source"), new_scene(client, "target")
    post(client, source, "b0", 0)
    Worker(container).drain()
    collect(container, 0.0, clock=lambda: clock.now + 1)
    record = rows(container, source)["b0"]
    with write_transaction(container.engine) as connection:
        container.queue.copy_into(connection, target, record, done=False)
    copy = rows(container, target)["b0"]
    assert copy.status == "queued" and copy.blob_collected_at == record.blob_collected_at
    Worker(container).drain()
    dead = rows(container, target)["b0"]
    assert dead.status == "dead" and "pbdag gc" in (dead.error or "")
    skipped = container.log.read(target, event_type="batch_skipped")
    assert len(skipped) == 1


def test_a_missing_blob_parks_the_batch_dead_naming_it(
    container: Container, client: TestClient
) -> None:
    scene_id = new_scene(client)
    post(client, scene_id, "b0", 0)
    record = rows(container, scene_id)["b0"]
    container.blobs.delete(record.blob_key)
    Worker(container).drain()
    dead = rows(container, scene_id)["b0"]
    assert dead.status == "dead" and "is missing" in (dead.error or "")
    with pytest.raises(RawBatchCollected):
        raise RawBatchCollected("x", 0.0)


@pytest.mark.parametrize(
    ("text", "seconds"),
    [("7d", 604_800.0), ("12h", 43_200.0), ("90m", 5_400.0), ("30s", 30.0), ("3600", 3_600.0)],
)
def test_retention_durations(text: str, seconds: float) -> None:
    assert parse_duration(text) == seconds
    assert Settings(raw_retention=text).raw_retention == seconds


@pytest.mark.parametrize("text", ["7w", "-1d", "nan", "inf", "d"])
def test_a_bad_retention_is_refused_naming_the_setting(text: str) -> None:
    with pytest.raises(ValueError, match="raw_retention"):
        Settings(raw_retention=text)


def test_pbdag_gc_dry_run_then_gc(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("PBDAG_DATA_DIR", str(tmp_path))
    monkeypatch.delenv("PBDAG_DATABASE_URL", raising=False)
    monkeypatch.delenv("PBDAG_RAW_RETENTION", raising=False)
    container = build_container(Settings(allow_anonymous_local=True))
    with local_client(create_app(container, run_worker=False)) as client:
        scene_id = new_scene(client)
        for i in range(3):
            assert post(client, scene_id, f"b{i}", i) == 202
    assert main(["worker", "--drain"]) == 0
    capsys.readouterr()
    size = sum(record.blob_bytes for record in container.queue.of_scene(scene_id))
    assert main(["gc"]) == 0
    assert "PBDAG_RAW_RETENTION is unset" in capsys.readouterr().out
    assert main(["gc", "--retention", "bogus"]) == 2
    assert "not a duration" in capsys.readouterr().err
    monkeypatch.setenv("PBDAG_RAW_RETENTION", "0")
    assert main(["gc", "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert f"would remove the raw bodies of 3 batches, {size} bytes" in out
    assert f"{scene_id}/b1" in out
    assert all(r.blob_collected_at is None for r in container.queue.of_scene(scene_id))
    assert main(["gc", "--retention", "1d"]) == 0  # nothing is a day old
    assert "removed the raw bodies of 0 batches, 0 bytes" in capsys.readouterr().out
    assert main(["gc"]) == 0
    out = capsys.readouterr().out
    assert f"removed the raw bodies of 3 batches, {size} bytes" in out
    assert "3 blobs deleted" in out
    assert all(r.blob_collected_at is not None for r in container.queue.of_scene(scene_id))


def test_gc_keeps_an_unreadable_scene_whole_and_after_repair_keeps_what_the_copy_needs(
    container: Container, client: TestClient, clock: Clock
) -> None:
    scene_id = new_scene(client)
    post(client, scene_id, "b0", 0)
    Worker(container).drain()
    poison_the_log(container, scene_id)
    post(client, scene_id, "b1", 1)  # accepted; it waits, as no state can be read
    report = collect(container, 0.0, clock=lambda: clock.now + 1)
    assert report.batches == 0 and list(report.unreadable_scenes) == [scene_id]
    assert "cannot be read" in report.unreadable_scenes[scene_id]

    repaired = repair_scene(container, scene_id).new_scene_id
    assert repaired is not None
    old, new = rows(container, scene_id), rows(container, repaired)
    assert (old["b1"].status, new["b0"].status, new["b1"].status) == ("dead", "done", "queued")
    assert old["b1"].blob_key == new["b1"].blob_key  # the copy holds the same blob
    report = collect(container, 0.0, clock=lambda: clock.now + 1)
    # b0 in both scenes, and the old scene's dead b1; the queued copy of b1 is not touched.
    assert sorted((r.scene_id == repaired, r.batch_id) for r in report.expired) == [
        (False, "b0"),
        (False, "b1"),
        (True, "b0"),
    ]
    assert report.blobs_deleted == 1  # b0's; b1's blob is still held by its queued copy
    assert Worker(container).drain() == 1
    assert rows(container, repaired)["b1"].status == "done"


def test_the_batch_status_says_when_its_raw_body_was_collected(
    container: Container, client: TestClient, clock: Clock
) -> None:
    scene_id = new_scene(client)
    post(client, scene_id, "b0", 0)
    Worker(container).drain()
    url = f"/v1/scenes/{scene_id}/batches/b0"
    assert client.get(url).json()["raw_collected_at"] is None
    clock.now = 5_000.0
    collect(container, 0.0, clock=lambda: clock.now)
    assert client.get(url).json()["raw_collected_at"] == 5_000.0


def test_gc_running_beside_posts_and_a_worker_never_takes_a_needed_blob(
    container: Container, client: TestClient
) -> None:
    """gc with a retention of zero, in a loop, while batches are posted and worked on: every
    batch is done (none found its blob gone), and in the end every raw body is collected."""
    container.queue.clock = time.time
    stop = threading.Event()
    failures: list[BaseException] = []

    def run(step: Callable[[], object]) -> None:
        try:
            while not stop.is_set():
                step()
        except BaseException as error:  # reported by the test thread
            failures.append(error)

    worker = Worker(container)
    threads = [
        threading.Thread(target=run, args=(worker.run_once,)),
        threading.Thread(target=run, args=(lambda: collect(container, 0.0),)),
    ]
    scene_id = new_scene(client)
    for thread in threads:
        thread.start()
    try:
        for i in range(30):
            assert post(client, scene_id, f"b{i}", i, mug=i % 3 != 2) == 202
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and any(
            r.status != "done" for r in container.queue.of_scene(scene_id)
        ):
            time.sleep(0.05)
    finally:
        stop.set()
        for thread in threads:
            thread.join(timeout=30)
    assert failures == []
    final = collect(container, 0.0)
    records = container.queue.of_scene(scene_id)
    assert [r.status for r in records] == ["done"] * 30
    # No fixture in this scene, so nothing is referenced: every raw body is collected.
    assert final.kept_referenced == []
    assert all(r.blob_collected_at is not None for r in records)
    for record in records:
        with pytest.raises(BlobNotFound):
            container.blobs.get(record.blob_key)
