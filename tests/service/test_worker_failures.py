"""How the worker fails: never a poisoned log, short errors, backoff, renewed leases, repair."""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import pytest
import sqlalchemy as sa
from fastapi.testclient import TestClient

from core.errors import StateConflict
from core.events import Event
from core.observation import Batch
from core.state import SceneState
from service.bootstrap import Container
from service.repair import repair_scene
from service.store.projection import rebuild_scene
from service.worker import Worker
from tests.service.minimal_events import an_add, poison_the_log
from tests.wire_bodies import batch_body, frame_body


def post(client: TestClient, scene_id: str, batch_id: str) -> None:
    body = batch_body(frame_body())
    body["batch_id"] = batch_id
    response = client.post(f"/v1/scenes/{scene_id}/batches", json=body)
    assert response.status_code == 202, response.text


def new_scene(client: TestClient) -> str:
    return str(client.post("/v1/scenes", json={"name": "w"}).json()["id"])


def status(client: TestClient, scene_id: str, batch_id: str) -> dict[str, Any]:
    result: dict[str, Any] = client.get(f"/v1/scenes/{scene_id}/batches/{batch_id}").json()
    return result


def test_a_non_finite_event_is_never_stored_and_the_scene_moves_on(
    client: TestClient, container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    scene_id = new_scene(client)
    post(client, scene_id, "poison")
    post(client, scene_id, "fine")
    calls: list[str] = []

    def decide(state: SceneState, batch: Batch) -> list[Event]:
        calls.append(batch.batch_id)
        return [an_add(float("inf") if batch.batch_id == "poison" else 0.1)]

    monkeypatch.setattr("service.worker.decide", decide)
    Worker(container).drain()
    poisoned = status(client, scene_id, "poison")
    assert poisoned["status"] == "dead" and poisoned["attempts"] == 1  # no pointless retries
    assert (
        "non-finite" in poisoned["error"]
        and "details.observations[0].extent[0]" in poisoned["error"]
    )
    assert status(client, scene_id, "fine")["status"] == "done"
    types = [e["type"] for e in client.get(f"/v1/scenes/{scene_id}/events").json()["events"]]
    assert types == ["scene_created", "batch_skipped", "add"]
    assert client.get(f"/v1/scenes/{scene_id}/graph", params={"include": "all"}).status_code == 200
    assert rebuild_scene(container.log, scene_id).identical


def test_a_dead_batch_error_is_short_and_names_nothing_internal(
    client: TestClient, container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    scene_id = new_scene(client)
    post(client, scene_id, "b0")

    def decide(state: SceneState, batch: Batch) -> list[Event]:
        raise sa.exc.IntegrityError(
            "INSERT INTO tracks (belief) VALUES ('" + "secret " * 600 + "')", {}, Exception()
        )

    monkeypatch.setattr("service.worker.decide", decide)
    Worker(container).drain()
    dead = status(client, scene_id, "b0")
    assert dead["status"] == "dead" and len(dead["error"]) <= 300
    assert "INSERT" not in dead["error"] and "secret" not in dead["error"]
    assert "IntegrityError" in dead["error"]


def test_a_passing_failure_backs_off_then_succeeds(
    client: TestClient, container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The database fails once while the worker loads the scene's state (the driver's own
    OperationalError, raised where the driver raises it): the store's adapter translates it,
    and the worker retries."""
    scene_id = new_scene(client)
    post(client, scene_id, "b0")
    dbapi = container.engine.dialect.dbapi
    assert dbapi is not None
    failures: list[Exception] = []
    real_load, reads = container.log.load_state, 0

    def load_failing_once(scene_id: str, as_of: int | None = None) -> Any:
        nonlocal reads
        reads += 1
        if reads == 1:
            failures.append(dbapi.OperationalError("the database is unavailable"))
        return real_load(scene_id, as_of)

    @sa.event.listens_for(container.engine, "before_cursor_execute")
    def fail_when_armed(*_: Any) -> None:
        if failures:
            raise failures.pop()

    monkeypatch.setattr(container.log, "load_state", load_failing_once)
    # The queue's clock stands still, so the retry's backoff (0.3 s) cannot run out within
    # this drain however slowly the machine runs.
    start = time.time()
    monkeypatch.setattr(container.queue, "clock", lambda: start)

    worker = Worker(container, seed=1)
    assert worker.drain() == 1
    failed = status(client, scene_id, "b0")
    assert failed["status"] == "failed"
    assert failed["error"] == "OperationalError: the database or the blob store failed; will retry"
    assert worker.drain() == 0  # not due yet: its retry waits for the backoff
    now = time.time() + 120
    monkeypatch.setattr(container.queue, "clock", lambda: now)
    assert worker.drain() == 1
    done = status(client, scene_id, "b0")
    assert (done["status"], done["attempts"], done["error"]) == ("done", 2, None)


def test_an_untranslated_error_is_no_passing_failure(
    client: TestClient, container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The worker classifies the project's own errors only: an OSError that no adapter
    translated is a bug, and the batch is dead at once rather than retried."""
    scene_id = new_scene(client)
    post(client, scene_id, "b0")

    def unreadable(key: str) -> bytes:
        raise OSError("not through the adapter")

    monkeypatch.setattr(container.blobs, "get", unreadable)
    Worker(container).drain()
    dead = status(client, scene_id, "b0")
    assert (dead["status"], dead["attempts"]) == ("dead", 1)
    assert dead["error"] == "internal error (OSError) while deciding; see the server log"


def test_retry_delays_grow_exponentially_with_jitter_up_to_the_cap(container: Container) -> None:
    worker = Worker(container, seed=3)
    settings = container.settings
    for attempts in range(1, 12):
        nominal = min(settings.retry_max_seconds, settings.retry_base_seconds * 2 ** (attempts - 1))
        assert 0.5 * nominal <= worker.retry_delay(attempts) <= 1.5 * nominal
    assert len({round(worker.retry_delay(3), 6) for _ in range(10)}) > 1  # jittered


def test_the_lease_is_renewed_while_a_slow_batch_runs(
    client: TestClient, container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Long enough that a renewal (every third of it) survives a loaded CI machine.
    container.settings.lease_seconds = 1.5
    scene_id = new_scene(client)
    post(client, scene_id, "slow")
    real_decide = __import__("core.decide", fromlist=["decide"]).decide

    def slow(state: SceneState, batch: Batch) -> list[Event]:
        time.sleep(4.5)  # three leases long
        events: list[Event] = real_decide(state, batch)
        return events

    monkeypatch.setattr("service.worker.decide", slow)
    thief = Worker(container, name="thief")
    first = threading.Thread(target=Worker(container, name="owner").drain)
    first.start()
    stolen = 0
    while first.is_alive():
        time.sleep(0.1)
        thief.settle_expired()  # would requeue the batch if its lease had lapsed
        stolen += container.queue.claim("thief", 1.5) is not None
    first.join()
    done = status(client, scene_id, "slow")
    assert stolen == 0 and (done["status"], done["attempts"]) == ("done", 1)


def test_a_dead_batch_lands_its_gap_on_the_head_a_command_moved_meanwhile(
    client: TestClient, container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The worker records `batch_skipped` through the same retry loop as the commands: an
    append between its read of the head and its write is not lost, the gap comes after it."""
    scene_id = new_scene(client)
    post(client, scene_id, "b0")
    claim = container.queue.claim("w", 30.0)
    assert claim is not None
    real_load, loads = container.log.load_state, 0

    def load_then_a_command_appends(scene: str, *args: Any, **kwargs: Any) -> SceneState:
        nonlocal loads
        state = real_load(scene, *args, **kwargs)
        loads += 1
        if loads == 1:
            with container.uow.begin() as work:
                work.append(scene, state, [an_add(0.1)])
        return state

    monkeypatch.setattr(container.log, "load_state", load_then_a_command_appends)
    Worker(container).skip(claim, "rejected: for the test")
    monkeypatch.undo()
    types = [e["type"] for e in client.get(f"/v1/scenes/{scene_id}/events").json()["events"]]
    assert loads == 2 and types == ["scene_created", "add", "batch_skipped"]
    assert status(client, scene_id, "b0")["status"] == "dead"


def test_an_unreadable_event_is_a_409_and_repair_rebuilds_the_scene(
    client: TestClient, container: Container
) -> None:
    scene_id = new_scene(client)
    post(client, scene_id, "b0")
    Worker(container).drain()
    bad_seq = poison_the_log(container, scene_id)
    post(client, scene_id, "b1")  # accepted before anyone noticed; its worker dies on the state
    response = client.get(f"/v1/scenes/{scene_id}/graph")
    assert response.status_code == 409 and response.json()["type"] == "/problems/scene-needs-repair"
    assert f"event {bad_seq}" in response.json()["detail"]

    report = repair_scene(container, scene_id)
    assert report.bad_seq == bad_seq and report.new_scene_id is not None
    assert (report.batches_done, report.batches_requeued) == (1, 1)
    quarantined = client.get(f"/v1/scenes/{scene_id}/graph")
    assert quarantined.status_code == 409 and report.new_scene_id in quarantined.json()["detail"]
    assert client.get(f"/v1/scenes/{scene_id}/events").status_code == 200  # the evidence stays
    assert client.post(f"/v1/scenes/{scene_id}/baselines").status_code == 409  # no more writes

    Worker(container).drain()
    new = report.new_scene_id
    assert status(client, new, "b0")["status"] == "done"
    assert status(client, new, "b1")["status"] == "done"
    assert client.get(f"/v1/scenes/{new}/graph").status_code == 200
    old_events = client.get(f"/v1/scenes/{scene_id}/events").json()["events"][1:bad_seq]
    new_events = client.get(f"/v1/scenes/{new}/events").json()["events"][1:bad_seq]
    assert [(e["seq"], e["type"], e["details"]) for e in old_events] == [
        (e["seq"], e["type"], e["details"]) for e in new_events
    ]
    assert rebuild_scene(container.log, new).identical
    assert repair_scene(container, new).healthy


@pytest.mark.parametrize(
    ("failure", "traceback"),
    [
        (StateConflict("the pose lies outside the scene's map", "frames[0].pose"), False),
        (ZeroDivisionError("a bug"), True),
    ],
)
def test_a_rejected_batch_is_one_log_line_and_a_bug_keeps_its_traceback(
    client: TestClient,
    container: Container,
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
    failure: Exception,
    traceback: bool,
) -> None:
    scene_id = new_scene(client)
    post(client, scene_id, "b0")

    def decide(state: SceneState, batch: Batch) -> list[Event]:
        raise failure

    monkeypatch.setattr("service.worker.decide", decide)
    with caplog.at_level(logging.INFO, logger="pbdag.worker"):
        Worker(container).drain()
    assert status(client, scene_id, "b0")["status"] == "dead"
    (record,) = [r for r in caplog.records if "failed (attempt 1)" in r.getMessage()]
    assert bool(record.exc_info) is traceback


def test_expired_leases_are_looked_for_once_every_third_of_a_lease(
    client: TestClient, container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    now = [1000.0]
    monkeypatch.setattr(container.queue, "clock", lambda: now[0])
    container.settings.lease_seconds = 30.0
    scene_id = new_scene(client)
    post(client, scene_id, "b0")
    assert container.queue.claim("crashed", 30.0) is not None  # its worker dies holding it
    looked: list[float] = []
    real = container.queue.expired

    def expired() -> list[Any]:
        looked.append(now[0])
        return real()

    monkeypatch.setattr(container.queue, "expired", expired)
    worker = Worker(container, name="alive")
    for at in (1000.0, 1005.0, 1009.9, 1010.0, 1025.0, 1029.0):
        now[0] = at
        assert not worker.run_once()  # b0 is held, by a worker that no longer renews it
    assert looked == [1000.0, 1010.0, 1025.0]
    now[0] = 1035.0  # the lease lapsed at 1030: the next look returns b0 to the queue
    assert not worker.run_once()  # b0 waits for its backoff
    assert looked[-1] == 1035.0
    settled = status(client, scene_id, "b0")
    assert settled["status"] == "failed" and "lease expired" in settled["error"]


def test_a_command_appended_after_the_claim_makes_the_batch_retry_on_the_new_head(
    client: TestClient, container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The claim reads the scene's head, and the worker keeps the state it folded last; a
    rename appended after the claim moves the head, so the batch's append refuses the kept
    state (nothing written), and the retry decides on the new head."""
    scene_id = new_scene(client)
    worker = Worker(container, seed=1)
    post(client, scene_id, "b0")
    assert worker.drain() == 1
    head = container.log.scene(scene_id).head_seq
    post(client, scene_id, "b1")
    claim = container.queue.claim("w", 30)
    assert claim is not None and claim.head_seq == head
    renamed = client.patch(f"/v1/scenes/{scene_id}", json={"name": "after the claim"})
    assert renamed.status_code == 200 and renamed.json()["head_seq"] == head + 1
    worker.process(claim)
    failed = status(client, scene_id, "b1")
    assert failed["status"] == "failed" and "ConcurrencyConflict" in failed["error"]
    assert container.log.scene(scene_id).head_seq == head + 1  # nothing of the batch appended
    now = time.time() + 120
    monkeypatch.setattr(container.queue, "clock", lambda: now)
    assert worker.drain() == 1
    assert status(client, scene_id, "b1")["status"] == "done"
    state = container.log.load_state(scene_id)
    assert state.name == "after the claim" and state.head_seq > head + 1
