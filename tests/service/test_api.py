"""The v1 API: bad input changes nothing, idempotent batches, paging, tracks, OpenAPI drift."""

from __future__ import annotations

import base64
import copy
import json
from typing import Any

import pytest
from fastapi.testclient import TestClient

from core.params import Params
from core.profiles import EXTENDED, EXTENSIONS
from service.app import create_app
from service.bootstrap import Container
from service.cli import OPENAPI_PATH
from service.worker import Worker
from tests.clients import local_client
from tests.wire_scenes import batch


@pytest.fixture(scope="module")
def good_batch() -> dict[str, Any]:
    return batch("b-0", 0)


def queue_size(client: TestClient) -> int:
    return sum(client.get("/healthz").json()["batches"].values())


def mutate(body: dict[str, Any], path: list[str | int], value: object) -> dict[str, Any]:
    """Set a nested key (a list of keys/indices) in a deep copy."""
    changed = copy.deepcopy(body)
    target: Any = changed
    for key in path[:-1]:
        target = target[key]
    target[path[-1]] = value
    return changed


BAD_INPUTS = [
    (
        "mask size",
        ["frames", 0, "detections", 0, "mask", "size"],
        [10, 10],
        "frames[0].detections[0].mask",
    ),
    ("depth not base64", ["frames", 0, "depth", "data"], "%%%", "frames[0].depth.data"),
    (
        "depth not png",
        ["frames", 0, "depth", "data"],
        base64.b64encode(b"not a png").decode(),
        "frames[0].depth",
    ),
    (
        "mask undecodable",
        ["frames", 0, "detections", 0, "mask", "counts"],
        "\x7f\x7f",
        "frames[0].detections[0].mask",
    ),
    ("pose not rotation", ["frames", 0, "pose", 0], [2.0, 0.0, 0.0, 0.0], "frames[0].pose"),
    ("pose last row", ["frames", 0, "pose", 3], [0.0, 0.0, 1.0, 1.0], "frames[0].pose"),
    ("pose not finite", ["frames", 0, "pose", 0, 3], "NaN", "frames[0].pose"),
    ("focal length", ["frames", 0, "intrinsics", "fx"], 0.0, "frames[0].intrinsics.fx"),
    ("no frames", ["frames"], [], "frames"),
]


@pytest.mark.parametrize(
    ("case", "path", "value", "field"), BAD_INPUTS, ids=[c[0] for c in BAD_INPUTS]
)
def test_bad_input_names_the_field_and_changes_nothing(
    client: TestClient,
    scene_id: str,
    good_batch: dict[str, Any],
    case: str,
    path: list[str | int],
    value: object,
    field: str,
) -> None:
    body = mutate(good_batch, path, value)
    response = client.post(f"/v1/scenes/{scene_id}/batches", json=body)
    assert response.status_code == 422, response.text
    assert response.headers["content-type"] == "application/problem+json"
    problem = response.json()
    assert problem["status"] == 422
    assert problem["field"].startswith(field), problem
    assert client.get(f"/v1/scenes/{scene_id}").json()["head_seq"] == 0
    assert queue_size(client) == 0


def test_unknown_scene_is_404_and_oversized_body_413(
    container: Container, client: TestClient, good_batch: dict[str, Any]
) -> None:
    response = client.post("/v1/scenes/scn-missing/batches", json=good_batch)
    assert response.status_code == 404 and response.json()["field"] == "scene_id"
    container.settings.max_body_bytes = len(json.dumps(good_batch)) - 1
    with local_client(create_app(container)) as small:
        scene = small.post("/v1/scenes", json={"name": "x"}).json()["id"]
        response = small.post(f"/v1/scenes/{scene}/batches", content=json.dumps(good_batch))
        assert response.status_code == 413
        assert response.headers["content-type"] == "application/problem+json"
    assert queue_size(client) == 0


def test_bad_scene_params_name_the_field(client: TestClient) -> None:
    response = client.post("/v1/scenes", json={"name": "x", "params": {"lifecycle": {"nope": 1}}})
    assert response.status_code == 422
    assert response.json()["field"] == "params.lifecycle.nope"
    assert client.get("/v1/scenes").json()["scenes"] == []


def test_a_scene_runs_the_profile_it_was_created_with(
    container: Container, client: TestClient
) -> None:
    paper = client.post(
        "/v1/scenes",
        json={
            "name": "paper",
            "profile": "paper",
            "params": {"lifecycle": {"move_min_distance_m": 0.4}},
        },
    )
    assert paper.status_code == 201
    recorded = Params.from_dict(paper.json()["params"])
    assert [e.name for e in EXTENSIONS if e.is_on(recorded)] == []  # every extension off
    assert recorded.lifecycle.move_min_distance_m == 0.4  # params on top of the profile
    ours = client.post("/v1/scenes", json={"name": "ours"}).json()
    assert Params.from_dict(ours["params"]) == EXTENDED.params  # the default profile
    # The worker decides each scene's batches under its own profile: five sightings clamp
    # the extended profile's log-odds at 1.5, not the paper's.
    for scene in (paper.json()["id"], ours["id"]):
        for k in range(5):
            client.post(f"/v1/scenes/{scene}/batches", json=batch(f"b-{k}", k))
    Worker(container).drain()
    logodds = {}
    for scene in (paper.json()["id"], ours["id"]):
        [track] = client.get(f"/v1/scenes/{scene}/tracks").json()
        logodds[scene] = track["existence_logodds"]
    assert logodds == {paper.json()["id"]: 5.0, ours["id"]: 1.5}
    unknown = client.post("/v1/scenes", json={"name": "x", "profile": "mine"})
    assert unknown.status_code == 422 and unknown.json()["field"] == "profile"


def test_same_batch_twice_appends_once_and_new_content_conflicts(
    container: Container, client: TestClient, scene_id: str, good_batch: dict[str, Any]
) -> None:
    first = client.post(f"/v1/scenes/{scene_id}/batches", json=good_batch)
    assert first.status_code == 202 and first.json()["status"] == "queued"
    Worker(container).drain()
    again = client.post(f"/v1/scenes/{scene_id}/batches", json=good_batch)
    assert again.status_code == 200
    assert again.json()["status"] == "done" and again.json()["first_seq"] == 1
    Worker(container).drain()
    head = client.get(f"/v1/scenes/{scene_id}").json()["head_seq"]
    assert head == again.json()["last_seq"]
    changed = mutate(good_batch, ["frames", 0, "timestamp"], 99.0)
    conflict = client.post(f"/v1/scenes/{scene_id}/batches", json=changed)
    assert conflict.status_code == 409 and conflict.json()["field"] == "batch_id"
    assert client.get(f"/v1/scenes/{scene_id}").json()["head_seq"] == head


def test_events_page_by_cursor_and_tracks_answer_queries(
    container: Container, client: TestClient, scene_id: str
) -> None:
    for i in range(3):
        assert (
            client.post(f"/v1/scenes/{scene_id}/batches", json=batch(f"b{i}", i)).status_code == 202
        )
    Worker(container).drain()
    seen: list[int] = []
    after: int | None = -1
    while after is not None:
        page = client.get(
            f"/v1/scenes/{scene_id}/events", params={"after": after, "limit": 2}
        ).json()
        seen += [event["seq"] for event in page["events"]]
        after = page["next_after"]
    head = client.get(f"/v1/scenes/{scene_id}").json()["head_seq"]
    assert seen == list(range(0, head + 1))
    adds = client.get(f"/v1/scenes/{scene_id}/events", params={"type": "add"}).json()["events"]
    assert [e["type"] for e in adds] == ["add"]
    track_id = adds[0]["track_id"]
    rows = client.get(
        f"/v1/scenes/{scene_id}/tracks", params={"label": "mug", "state": "confirmed"}
    ).json()
    assert [row["track_id"] for row in rows] == [track_id]
    belief = client.get(f"/v1/scenes/{scene_id}/tracks/{track_id}").json()
    assert belief["batches_observed"] == 3 and len(belief["recent_centers"]) == 3
    assert abs(sum(v * v for v in belief["embedding"]) - 1.0) < 1e-9
    at_add = client.get(
        f"/v1/scenes/{scene_id}/tracks/{track_id}", params={"as_of": adds[0]["seq"]}
    ).json()
    assert at_add["state"] == "tentative"
    assert client.get(f"/v1/scenes/{scene_id}/tracks/trk-999999").status_code == 404
    every = client.get(f"/v1/scenes/{scene_id}/graph", params={"include": "all"}).json()
    assert any(node["id"] == track_id for node in every["nodes"])


def test_openapi_file_matches_the_app(client: TestClient) -> None:
    """api_schema/openapi.json is generated from the app (`pbdag openapi`); it must not drift."""
    assert json.loads(OPENAPI_PATH.read_text()) == client.get("/openapi.json").json()
