"""The queue's part of the store contract, on every backend: idempotent submits, admission,
arrival order, fenced completion, retries, leases and dead batches."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import pytest

from service.bootstrap import Container
from service.store.errors import (
    BatchConflict,
    LeaseLost,
)
from service.store.queue_records import (
    Admission,
    BatchRecord,
    Claim,
    NotRequeueable,
    QueueFull,
    QuotaExceeded,
)
from tests.service.minimal_events import added, new_scene

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

    def test_a_claim_carries_its_scene_s_head_at_the_claim(self, container: Container) -> None:
        scene = new_scene(container)
        self.submit(container, scene.id, "b1")
        self.submit(container, scene.id, "b2")
        first = self.claim(container, "w", 30)
        assert first.head_seq == container.log.scene(scene.id).head_seq == 0
        state = container.log.load_state(scene.id)
        with container.uow.begin() as work:
            appended = work.append(scene.id, state, [added("trk-000001")], batch_id="b1")
            work.complete(first, appended.seqs)
        second = self.claim(container, "w", 30)
        assert second.head_seq == 1
        # A claim the queue hands back after its lease lapsed does not know the head.
        later = container.queue.clock() + 60
        container.queue.clock = lambda: later
        assert [(c.batch_id, c.head_seq) for c in container.queue.expired()] == [("b2", None)]

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
