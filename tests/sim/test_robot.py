"""The simulated robot speaks the HTTP API: scene creation, batching, idempotency keys, retries."""

from __future__ import annotations

import base64
import io
import json
from typing import Any

import httpx
import numpy as np
import pytest
from PIL import Image

import sim.robot as robot
from api_schema import BatchIn
from pbdag_client import Client, InvalidRequest
from sim import DEMO_SCENARIO
from sim.detector import FIXTURE_VOCABULARY
from sim.scenario import load_scenario
from sim.stream import simulate, wire_batches

SCENE_ID = "scene-42"


def scene_answer(name: str) -> dict[str, Any]:
    """What the service answers to a new scene."""
    return {"id": SCENE_ID, "name": name, "head_seq": 0, "created_at": 0.0, "params": {}}


def batch_answer(body: dict[str, Any]) -> dict[str, Any]:
    """What the service answers to an accepted batch."""
    return {
        "batch_id": body["batch_id"],
        "scene_id": SCENE_ID,
        "status": "queued",
        "attempts": 0,
        "frame_count": len(body["frames"]),
        "content_sha256": "0" * 64,
        "first_seq": None,
        "last_seq": None,
        "error": None,
        "received_at": 0.0,
        "finished_at": None,
    }


INVALID = {
    "type": "/problems/invalid-observation",
    "title": "Invalid observation",
    "status": 422,
    "detail": "frames[0].pose: last row must be [0, 0, 0, 1]",
    "field": "frames[0].pose",
    "errors": [{"field": "frames[0].pose", "reason": "last row must be [0, 0, 0, 1]"}],
}


class FakeService:
    """Records requests and answers like the real service would (201 / 202 / a problem)."""

    def __init__(self, connect_failures: int = 0, batch_status: int = 202) -> None:
        self.connect_failures = connect_failures
        self.batch_status = batch_status
        self.scene_requests: list[dict[str, object]] = []
        self.batches: list[dict[str, Any]] = []

    def __call__(self, request: httpx.Request) -> httpx.Response:
        if self.connect_failures > 0:
            self.connect_failures -= 1
            raise httpx.ConnectError("service still starting", request=request)
        body = json.loads(request.content)
        if request.method == "POST" and request.url.path == "/v1/scenes":
            self.scene_requests.append(body)
            return httpx.Response(201, json=scene_answer(str(body["name"])))
        if request.method == "POST" and request.url.path == f"/v1/scenes/{SCENE_ID}/batches":
            self.batches.append(body)
            if self.batch_status == 422:
                return httpx.Response(422, json=INVALID)
            return httpx.Response(self.batch_status, json=batch_answer(body))
        return httpx.Response(404, json={"detail": "not found"})


def client_for(service: FakeService) -> Client:
    """A PBD-AG client whose transport is the fake service."""
    return Client("http://robot-test", transport=httpx.MockTransport(service))


def test_run_creates_a_scene_and_posts_every_frame_in_batches() -> None:
    service = FakeService()
    with client_for(service) as client:
        scene_id = robot.run_robot(
            "", scene_name="kitchen", frames=5, frames_per_batch=2, progress=False, client=client
        )
    assert scene_id == SCENE_ID
    assert service.scene_requests == [{"name": "kitchen"}]
    assert [len(batch["frames"]) for batch in service.batches] == [2, 2, 1]
    batch_ids = [batch["batch_id"] for batch in service.batches]
    assert len(set(batch_ids)) == 3
    frames = [frame for batch in service.batches for frame in batch["frames"]]
    # The stream's ids: scenario name, run seed (7 by default) and frame index.
    assert [frame["frame_id"] for frame in frames] == [
        f"demo-s7-f{index:05d}" for index in range(5)
    ]
    assert [frame["timestamp"] for frame in frames] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4])
    first = frames[0]
    depth = np.array(Image.open(io.BytesIO(base64.b64decode(first["depth"]["data"]))))
    assert depth.shape == (480, 640) and (depth > 0).mean() > 0.9
    assert np.array(first["pose"]).shape == (4, 4)
    detections = [detection for frame in frames for detection in frame["detections"]]
    objects = [detection for detection in detections if detection["kind"] == "object"]
    fixtures = [detection for detection in detections if detection["kind"] == "fixture"]
    assert objects, "the demo start looks at the table, so something must be detected"
    assert len(objects) + len(fixtures) == len(detections)
    assert {detection["label"] for detection in objects} <= {"mug", "book", "bowl", "bottle"}
    assert all(len(detection["embedding"]) == 64 for detection in objects)
    # A view may put a confusable class on top (the desk-table pair), never drop the true one.
    assert {"table", "counter"} <= {label for d in fixtures for label in d["class_scores"]}
    for fixture in fixtures:
        assert "embedding" not in fixture and set(fixture["class_scores"]) <= set(
            FIXTURE_VOCABULARY
        )
        assert fixture["score"] == max(fixture["class_scores"].values())
        assert fixture["label"] == max(fixture["class_scores"], key=fixture["class_scores"].get)
    for batch in service.batches:
        BatchIn.model_validate(batch)  # what the service would accept, class_scores included


def test_same_seed_sends_identical_batches_and_another_seed_others() -> None:
    runs = []
    for seed in (3, 3, 4):
        service = FakeService()
        with client_for(service) as client:
            robot.run_robot(
                "", frames=2, frames_per_batch=2, seed=seed, progress=False, client=client
            )
        runs.append(service.batches)
    assert runs[0] == runs[1] and runs[2] != runs[0]


def test_the_robot_posts_the_batches_the_evaluation_reads() -> None:
    service = FakeService()
    with client_for(service) as client:
        robot.run_robot("", frames=6, frames_per_batch=3, seed=5, progress=False, client=client)
    run = simulate(load_scenario(DEMO_SCENARIO, frames=6), seed=5)
    assert service.batches == [batch for _, batch in wire_batches(run, frames_per_batch=3)]


def test_connection_errors_are_retried(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(robot, "FIRST_BACKOFF_SECONDS", 0.0)
    service = FakeService(connect_failures=2)
    with client_for(service) as client:
        robot.run_robot("", frames=1, progress=False, client=client)
    assert len(service.scene_requests) == 1 and len(service.batches) == 1


def test_unreachable_service_gives_up(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(robot, "FIRST_BACKOFF_SECONDS", 0.0)
    service = FakeService(connect_failures=robot.CONNECT_ATTEMPTS)
    with client_for(service) as client, pytest.raises(httpx.ConnectError):
        robot.run_robot("", frames=1, progress=False, client=client)


def test_rejected_batch_is_an_error() -> None:
    service = FakeService(batch_status=422)
    with client_for(service) as client, pytest.raises(InvalidRequest) as raised:
        robot.run_robot("", frames=1, progress=False, client=client)
    assert raised.value.status == 422 and raised.value.field == "frames[0].pose"
