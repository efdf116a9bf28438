"""Deleting and renaming scenes over HTTP, on every store backend: every row of the deleted scene
goes and nothing of another scene; the raw batches no other scene names go with it; a worker
holding one of its batches drops it; a rename is an event that replay and `pbdag rebuild` keep."""

from __future__ import annotations

import logging
import time
from typing import Any

import pytest
import sqlalchemy as sa
from fastapi.testclient import TestClient

from core.decide import decide
from core.state import SceneState
from service.app import create_app
from service.bootstrap import Container
from service.store import scene_deletion
from service.store.blobs import ORPHAN_GRACE_SECONDS, BlobNotFound
from service.store.engine import write_transaction
from service.store.projection import rebuild_scene
from service.store.scene_deletion import delete_scene
from service.store.tables import baselines, batches, scenes
from service.worker import Worker
from tests.clients import local_client
from tests.service.scene_rows import bearer, blob_keys_of, rows_of
from tests.wire_scenes import batch

NOTHING = {"events": 0, "tracks": 0, "snapshots": 0, "baselines": 0, "batches": 0, "scenes": 0}


def filled_scene(client: TestClient, container: Container, name: str, prefix: str) -> str:
    """A scene with two processed batches, a queued one, a snapshot and a baseline row."""
    scene_id = str(client.post("/v1/scenes", json={"name": name}).json()["id"])
    for index in range(3):
        posted = client.post(
            f"/v1/scenes/{scene_id}/batches", json=batch(f"{prefix}{index}", index)
        )
        assert posted.status_code == 202, posted.text
        if index < 2:
            Worker(container).drain()
    state = container.log.load_state(scene_id)
    with write_transaction(container.engine) as connection:
        if state.head_seq not in container.log.snapshot_seqs(scene_id):
            container.log.save_snapshot(connection, scene_id, state)
        # A package row as a freeze writes it (the wire scene holds no fixture to freeze).
        connection.execute(
            baselines.insert().values(
                scene_id=scene_id, version=1, seq=state.head_seq, sha256="0" * 64, body=b"{}"
            )
        )
    return scene_id


def delete(client: TestClient, container: Container, scene_id: str, **query: str) -> Any:
    return client.delete(f"/v1/scenes/{scene_id}", params=query, headers=bearer(container, "admin"))


def an_hour_later(monkeypatch: pytest.MonkeyPatch, container: Container) -> None:
    """Judge the blob files as `pbdag gc` would an hour and a minute from now (a file younger
    than the grace may be a batch of another scene being queued, and is left to the sweep)."""
    if not container.blobs.joins_transaction:
        later = time.time() + ORPHAN_GRACE_SECONDS + 60
        monkeypatch.setattr(scene_deletion, "clock", lambda: later)


def test_delete_removes_every_row_of_the_scene_and_nothing_of_another(
    client: TestClient, container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    an_hour_later(monkeypatch, container)
    doomed = filled_scene(client, container, "sim-demo", "b")
    kept = filled_scene(client, container, "kitchen", "k")
    # `pbdag repair` copies a batch's row into another scene with the same blob: shared.
    shared = container.queue.of_scene(kept)[0]
    with write_transaction(container.engine) as connection:
        container.queue.copy_into(connection, doomed, shared, done=True)
    own = blob_keys_of(container.engine, doomed) - {shared.blob_key}
    before, other_before = rows_of(container.engine, doomed), rows_of(container.engine, kept)
    assert all(before.values()) and len(own) == 3
    own_bytes = sum(r.blob_bytes for r in container.queue.of_scene(doomed) if r.blob_key in own)

    answer = delete(client, container, doomed, confirm=doomed)
    assert answer.status_code == 200, answer.text
    assert answer.json() == {
        "scene_id": doomed,
        "events": before["events"],
        "tracks": before["tracks"],
        "snapshots": before["snapshots"],
        "baselines": 1,
        "batches": 4,
        "blobs": 3,
        "bytes": own_bytes,
    }
    assert rows_of(container.engine, doomed) == NOTHING
    assert rows_of(container.engine, kept) == other_before
    for key in own:
        with pytest.raises(BlobNotFound):
            container.blobs.get(key)
    assert container.blobs.get(shared.blob_key)  # the other scene's batch still names it
    # The other scene goes on: its queued batch is processed.
    assert Worker(container).drain() == 1
    assert client.get(f"/v1/scenes/{kept}/batches/k2").json()["status"] == "done"


def test_after_a_delete_the_scene_and_its_cached_states_are_404(
    client: TestClient, container: Container, scene_id: str
) -> None:
    client.post(f"/v1/scenes/{scene_id}/batches", json=batch("b0", 0))
    Worker(container).drain()
    assert client.get(f"/v1/scenes/{scene_id}/graph").status_code == 200  # a cached state now
    assert delete(client, container, scene_id, confirm=scene_id).status_code == 200
    for path in ("", "/graph", "/events", "/tracks", "/batches/b0"):
        answer = client.get(f"/v1/scenes/{scene_id}{path}")
        assert answer.status_code == 404, (path, answer.text)
    assert scene_id not in [s["id"] for s in client.get("/v1/scenes").json()["scenes"]]
    again = delete(client, container, scene_id, confirm=scene_id)
    assert again.status_code == 404 and again.json()["field"] == "scene_id"


@pytest.mark.parametrize("scopes", [("read",), ("write",), ("read", "write")])
def test_a_token_without_the_admin_scope_gets_403_and_nothing_is_deleted(
    client: TestClient, container: Container, scene_id: str, scopes: tuple[str, ...]
) -> None:
    before = rows_of(container.engine, scene_id)
    answer = client.delete(
        f"/v1/scenes/{scene_id}",
        params={"confirm": scene_id},
        headers=bearer(container, *scopes),
    )
    assert answer.status_code == 403, answer.text
    assert "scope" in answer.json()["detail"]  # a read token lacks 'write' already
    assert rows_of(container.engine, scene_id) == before
    # Anonymous local access writes, but never administers.
    anonymous = client.delete(f"/v1/scenes/{scene_id}", params={"confirm": scene_id})
    assert anonymous.status_code == 403 and "'admin' scope" in anonymous.json()["detail"]


@pytest.mark.parametrize("confirm", [None, "", "scn-000000000000", "yes"])
def test_a_missing_or_wrong_confirm_is_422_naming_it_and_deletes_nothing(
    client: TestClient, container: Container, confirm: str | None
) -> None:
    scene_id = filled_scene(client, container, "hall", "b")
    before, keys = rows_of(container.engine, scene_id), blob_keys_of(container.engine, scene_id)
    answer = delete(
        client, container, scene_id, **({} if confirm is None else {"confirm": confirm})
    )
    assert answer.status_code == 422, answer.text
    assert answer.headers["content-type"] == "application/problem+json"
    assert answer.json()["field"] == "confirm" and "nothing was deleted" in answer.json()["detail"]
    assert rows_of(container.engine, scene_id) == before
    assert all(container.blobs.get(key) for key in keys)


def test_a_quarantined_scene_can_be_deleted(
    client: TestClient, container: Container, scene_id: str
) -> None:
    with write_transaction(container.engine) as connection:
        container.log.quarantine(connection, scene_id, "event 3 cannot be read")
    assert client.get(f"/v1/scenes/{scene_id}/graph").status_code == 409
    assert delete(client, container, scene_id, confirm=scene_id).status_code == 200
    assert rows_of(container.engine, scene_id) == NOTHING


def test_a_worker_holding_a_batch_of_a_deleted_scene_drops_it(
    client: TestClient,
    container: Container,
    scene_id: str,
    caplog: pytest.LogCaptureFixture,
) -> None:
    client.post(f"/v1/scenes/{scene_id}/batches", json=batch("b0", 0))
    worker = Worker(container)
    claim = container.queue.claim(worker.name, 30.0)
    assert claim is not None and claim.scene_id == scene_id
    delete_scene(container.engine, container.blobs, scene_id)
    with caplog.at_level(logging.INFO, logger="pbdag.worker"):
        worker.process(claim)
    lines = [r.getMessage() for r in caplog.records if r.name == "pbdag.worker"]
    assert lines == [f"batch b0 dropped: its scene {scene_id} was deleted"]
    assert worker.health.healthy and worker.unrecorded == 0
    assert rows_of(container.engine, scene_id) == NOTHING


def test_a_scene_deleted_while_the_worker_decides_its_batch_is_not_resurrected(
    client: TestClient,
    container: Container,
    scene_id: str,
    caplog: pytest.LogCaptureFixture,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    other = str(client.post("/v1/scenes", json={"name": "other"}).json()["id"])
    client.post(f"/v1/scenes/{scene_id}/batches", json=batch("b0", 0))
    decided: list[str] = []

    def deleted_meanwhile(state: SceneState, observed: Any) -> Any:
        events = decide(state, observed)
        delete_scene(container.engine, container.blobs, scene_id)  # what an admin does now
        decided.append(observed.batch_id)
        return events

    monkeypatch.setattr("service.worker.decide", deleted_meanwhile)
    worker = Worker(container)
    with caplog.at_level(logging.INFO, logger="pbdag.worker"):
        assert worker.drain() == 1
    assert decided == ["b0"]
    lines = [r.getMessage() for r in caplog.records if r.levelno >= logging.INFO]
    assert f"batch b0 dropped: its scene {scene_id} was deleted" in lines
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert worker.health.healthy and worker.unrecorded == 0
    assert rows_of(container.engine, scene_id) == NOTHING
    monkeypatch.undo()
    # The worker goes on with other scenes.
    client.post(f"/v1/scenes/{other}/batches", json=batch("o0", 0))
    assert worker.drain() == 1
    assert client.get(f"/v1/scenes/{other}/batches/o0").json()["status"] == "done"


def test_a_rename_is_an_event_that_lists_replays_and_survives_rebuild(
    client: TestClient, container: Container, scene_id: str
) -> None:
    client.post(f"/v1/scenes/{scene_id}/batches", json=batch("b0", 0))
    Worker(container).drain()
    head = client.get(f"/v1/scenes/{scene_id}").json()["head_seq"]
    renamed = client.patch(f"/v1/scenes/{scene_id}", json={"name": "kitchen, upstairs"})
    assert renamed.status_code == 200, renamed.text
    assert renamed.json()["name"] == "kitchen, upstairs" and renamed.json()["head_seq"] == head + 1
    listed = {s["id"]: s["name"] for s in client.get("/v1/scenes").json()["scenes"]}
    assert listed[scene_id] == "kitchen, upstairs"
    last = client.get(f"/v1/scenes/{scene_id}/events", params={"after": head}).json()["events"]
    assert [(e["type"], e["topic"], e["details"]) for e in last] == [
        ("scene_renamed", "scene_renamed", {"name": "kitchen, upstairs"})
    ]
    assert container.log.replay(scene_id).name == "kitchen, upstairs"
    # The same name again appends nothing.
    assert client.patch(f"/v1/scenes/{scene_id}", json={"name": "kitchen, upstairs"}).json()[
        "head_seq"
    ] == (head + 1)
    report = rebuild_scene(container.log, scene_id)
    assert report.identical and container.log.scene(scene_id).name == "kitchen, upstairs"
    # A row changed behind the log's back is a difference, and the rebuild restores the log's.
    with write_transaction(container.engine) as connection:
        connection.execute(sa.update(scenes).where(scenes.c.id == scene_id).values(name="x"))
    report = rebuild_scene(container.log, scene_id)
    assert report.name_differs and not report.identical
    assert container.log.scene(scene_id).name == "kitchen, upstairs"


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"name": ""}, "name"),
        ({"name": "a" * 201}, "name"),
        ({"name": "bad\u0000name"}, "name"),
        ({"name": "fine", "params": {}}, "params"),
        ({}, "name"),
    ],
)
def test_a_rename_the_text_rule_refuses_is_422_naming_the_field_and_changes_nothing(
    client: TestClient, scene_id: str, body: dict[str, Any], field: str
) -> None:
    answer = client.patch(f"/v1/scenes/{scene_id}", json=body)
    assert answer.status_code == 422, answer.text
    assert answer.json()["field"] == field
    scene = client.get(f"/v1/scenes/{scene_id}").json()
    assert (scene["name"], scene["head_seq"]) == ("hall", 0)


def test_rename_needs_write_a_live_scene_and_an_existing_one(
    client: TestClient, container: Container, scene_id: str
) -> None:
    path = f"/v1/scenes/{scene_id}"
    read_only = client.patch(path, json={"name": "x"}, headers=bearer(container, "read"))
    assert read_only.status_code == 403
    written = client.patch(path, json={"name": "hall 2"}, headers=bearer(container, "write"))
    assert written.status_code == 200 and written.json()["name"] == "hall 2"
    assert client.patch("/v1/scenes/scn-000000000000", json={"name": "x"}).status_code == 404
    with write_transaction(container.engine) as connection:
        container.log.quarantine(connection, scene_id, "event 3 cannot be read")
    assert client.patch(path, json={"name": "x"}).status_code == 409
    assert container.log.scene(scene_id).name == "hall 2"


def test_a_queue_row_of_a_deleted_scene_cannot_be_written(
    client: TestClient, container: Container, scene_id: str
) -> None:
    """Every table that names a scene has a foreign key to it: nothing brings it back."""
    assert delete(client, container, scene_id, confirm=scene_id).status_code == 200
    with pytest.raises(sa.exc.IntegrityError), write_transaction(container.engine) as connection:
        connection.execute(
            batches.insert().values(
                scene_id=scene_id,
                batch_id="late",
                content_sha256="0" * 64,
                blob_key="0" * 64,
                frame_count=1,
                status="queued",
                received_at=0.0,
            )
        )


def test_a_batch_posted_while_its_scene_is_deleted_is_404_and_stores_nothing(
    client: TestClient, container: Container, scene_id: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The route found the scene; an admin deletes it before the queue row is written. The
    foreign key refuses the row, and the answer is the scene's 404, not a 500."""
    submit = container.queue.submit

    def deleted_first(*args: Any, **kwargs: Any) -> Any:
        delete_scene(container.engine, container.blobs, scene_id)
        return submit(*args, **kwargs)

    monkeypatch.setattr(container.queue, "submit", deleted_first)
    response = client.post(f"/v1/scenes/{scene_id}/batches", json=batch("late", 0))
    assert response.status_code == 404, response.text
    problem = response.json()
    assert problem["field"] == "scene_id" and scene_id in problem["detail"]
    assert rows_of(container.engine, scene_id) == NOTHING


def test_scenes_started_from_a_deleted_scenes_baseline_keep_working(
    old_database: tuple[str, Container, list[str]],
) -> None:
    _url, container, scene_ids = old_database
    source, session = scene_ids[1], scene_ids[2]
    assert container.log.load_state(session).source_baseline is not None
    reference = {"scene_id": source, "version": 1}
    with local_client(create_app(container)) as client:
        later = client.post("/v1/scenes", json={"name": "later", "baseline": reference}).json()
        graphs = {s: client.get(f"/v1/scenes/{s}/graph").json() for s in (session, later["id"])}
        deleted = delete(client, container, source, confirm=source)
        assert deleted.status_code == 200 and deleted.json()["baselines"] == 1
        for scene, graph in graphs.items():  # what they loaded is theirs: the same graphs
            assert client.get(f"/v1/scenes/{scene}/graph").json() == graph
            assert rebuild_scene(container.log, scene).identical
        assert graphs[later["id"]]["nodes"]  # the package's fixtures
        assert (
            client.post(f"/v1/scenes/{later['id']}/batches", json=batch("b0", 0)).status_code == 202
        )
        assert Worker(container).drain() == 1
        assert client.get(f"/v1/scenes/{later['id']}/batches/b0").json()["status"] == "done"
        # A new scene cannot start from the deleted package: the source is gone.
        again = client.post("/v1/scenes", json={"name": "too late", "baseline": reference})
        assert again.status_code == 404


def test_blob_files_stored_within_the_grace_are_left_to_gc_and_table_blobs_go_at_once(
    client: TestClient, container: Container
) -> None:
    scene_id = filled_scene(client, container, "hall", "b")
    keys = blob_keys_of(container.engine, scene_id)
    answer = delete(client, container, scene_id, confirm=scene_id)
    assert answer.status_code == 200
    if container.blobs.joins_transaction:  # the PostgreSQL table: in the deletion's transaction
        assert answer.json()["blobs"] == len(keys)
        assert not any(key in set(container.blobs.keys()) for key in keys)
    else:  # a file may be another scene's batch being queued: the sweep's, once an hour old
        assert answer.json()["blobs"] == 0
        assert all(container.blobs.get(key) for key in keys)
