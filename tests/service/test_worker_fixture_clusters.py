"""The worker keeps a scene's fixture clusters from batch to batch, commands in between."""

from __future__ import annotations

from fastapi.testclient import TestClient

from service.bootstrap import Container
from service.worker import Worker
from tests.service.minimal_events import added
from tests.wire_bodies import batch_body, frame_body


def test_a_command_between_batches_keeps_the_fixture_clusters(
    client: TestClient, container: Container
) -> None:
    scene_id = str(client.post("/v1/scenes", json={"name": "w"}).json()["id"])
    body = batch_body(frame_body())  # an object mask and a fixture mask
    assert client.post(f"/v1/scenes/{scene_id}/batches", json=body).status_code == 202
    worker = Worker(container)
    assert worker.run_once()
    after_batch = worker._state(scene_id)
    voxels = after_batch.voxels
    assert len(voxels) > 0 and "clusters" in voxels.cache  # decide built them, the fold kept them
    # A command appends meanwhile (any event but fixture evidence; here an object's add).
    with container.uow.begin() as work:
        work.append(scene_id, container.log.load_state(scene_id), [added("trk-000900")])
    state = worker._state(scene_id)
    assert state.head_seq == after_batch.head_seq + 1 and "trk-000900" in state.tracks
    assert state.voxels is voxels  # the same map, its clusters with it
    assert state.to_dict() == container.log.load_state(scene_id).to_dict()
