"""Issue 9 (phase 1) through the HTTP API: the occupancy map and the plan, with time travel."""

from __future__ import annotations

import io
from collections.abc import Iterator
from typing import Any

import numpy as np
import orjson
import pytest
from fastapi.testclient import TestClient
from PIL import Image

from core.occupancy import CODE_FREE, CODE_OCCUPIED, CODE_UNKNOWN
from service.app import create_app
from service.bootstrap import Container
from service.store.projection import rebuild_scene
from service.worker import Worker
from tests.clients import local_client
from tests.eval_extra import require_eval_extra

require_eval_extra()  # the simulator renders this test's world

from tests.e2e.fixture_world import AWAY_VIEW, DISCOVERY, ROOM, wire_batches, wire_frame  # noqa: E402

Api = tuple[TestClient, Worker, Container]
ROBOT = {"x": 1.02, "y": 0.92, "yaw": 0.0}  # in front of the table, clear of everything


@pytest.fixture
def api(container: Container) -> Iterator[Api]:
    with local_client(create_app(container)) as client:
        yield client, Worker(container), container


@pytest.fixture
def house(api: Api) -> str:
    """A scene that saw the room's table and counter from six views, twice."""
    client, worker, _ = api
    scene_id: str = client.post("/v1/scenes", json={"name": "house"}).json()["id"]
    for body in wire_batches(ROOM, DISCOVERY, "d"):
        assert client.post(f"/v1/scenes/{scene_id}/batches", json=body).status_code == 202
    assert worker.drain() == len(DISCOVERY)
    return scene_id


def head(client: TestClient, scene_id: str) -> int:
    seq: int = client.get(f"/v1/scenes/{scene_id}").json()["head_seq"]
    return seq


def decoded(occupancy: dict[str, Any]) -> np.ndarray:
    """The map's codes from its (code, count) runs, (rows, cols)."""
    runs = np.asarray(occupancy["cells"], dtype=np.int64).reshape(-1, 2)
    flat = np.repeat(runs[:, 0], runs[:, 1])
    return flat.reshape(occupancy["shape"])


def code_at(occupancy: dict[str, Any], x: float, y: float) -> int:
    res = occupancy["resolution_m"]
    col = int((x - occupancy["origin"][0]) // res)
    row = int((y - occupancy["origin"][1]) // res)
    return int(decoded(occupancy)[row, col])


def test_occupancy_as_json_and_png_now_and_at_any_seq(api: Api, house: str) -> None:
    client, _, container = api
    url = f"/v1/scenes/{house}/occupancy"
    now = client.get(url).json()
    codes = decoded(now)
    assert codes.size == now["shape"][0] * now["shape"][1] == sum(now["counts"].values())
    assert now["counts"]["free"] > 1000 and now["counts"]["occupied"] > 100
    assert now["resolution_m"] == 0.05 and now["encoding"] == "rle"
    # The table (x 1.3-2.7, y 1.6-2.4) is occupied where the views saw its edge; the floor
    # between the first view's camera (1.2, 0.9) and the table is free.
    assert code_at(now, 1.6, 1.62) == CODE_OCCUPIED
    assert code_at(now, 1.4, 1.2) == CODE_FREE
    assert now["frontiers"] and all(f["size"] >= 5 for f in now["frontiers"])
    # The PNG is the same map, north up.
    png = client.get(url, params={"format": "png"})
    assert png.status_code == 200 and png.headers["content-type"] == "image/png"
    assert png.headers["x-map-resolution"] == "0.05"
    pixels = np.asarray(Image.open(io.BytesIO(png.content)))
    assert pixels.shape == codes.shape
    levels = {CODE_UNKNOWN: 205, CODE_FREE: 254, CODE_OCCUPIED: 0}
    assert np.array_equal(pixels, np.vectorize(levels.get)(codes)[::-1])
    assert client.get(url, headers={"accept": "image/png"}).content == png.content
    assert client.get(url, headers={"accept": "application/json"}).json() == now
    # Time travel: at seq 0 nothing is known; after the first batch, less than now.
    assert client.get(url, params={"as_of": 0}).json()["shape"] == [0, 0]
    first = container.log.read(house, event_type="occupancy_evidence", limit=1)[0].seq
    early = client.get(url, params={"as_of": first}).json()
    assert early["seq"] == first
    assert 0 < early["counts"]["free"] < now["counts"]["free"]
    # Every seq's map is the replay's (snapshots every 25 events, plus tails), bit for bit.
    for seq in (first, 25, 26, head(client, house)):
        state = container.log.load_state(house, seq)
        assert state.occupancy == container.log.replay(house, up_to=seq).occupancy
    assert client.get(url, params={"format": "gif"}).json()["field"] == "format"
    assert client.get(url, params={"as_of": 10**6}).status_code == 404


def test_rebuild_reproduces_the_map_bit_for_bit(api: Api, house: str) -> None:
    _, _, container = api
    assert container.log.snapshot_seqs(house)  # snapshots hold the map
    report = rebuild_scene(container.log, house)
    assert report.identical
    # Occupancy evidence is compact: a 320 x 240 frame's cells in at most 2 KB per batch.
    sizes = [
        len(orjson.dumps(e.details))
        for e in container.log.read(house, event_type="occupancy_evidence")
    ]
    assert len(sizes) == len(DISCOVERY) and max(sizes) < 2500


def test_the_plan_locks_once_and_is_reproduced_from_the_log_at_its_seq(
    api: Api, house: str
) -> None:
    client, _, container = api
    before = head(client, house)
    decided = client.post(f"/v1/scenes/{house}/plan", json={"robot_pose": ROBOT}).json()
    assert decided["decision"] == "inspect" and decided["lock"] == "new"
    assert decided["seq"] == before and decided["event_seq"] == before + 1
    target = decided["target"]
    assert set(target["uncertainty"]["terms"]) == {
        "existence",
        "class",
        "parent",
        "position",
        "age",
        "confirmation",
    }
    assert target["view"]["cost"] == pytest.approx(sum(target["view"]["cost_terms"].values()))
    assert decided["queue"][0]["fixture_id"] == target["fixture_id"]
    # The lock is one event, saying why: u_i, its terms, Prox, the score, the view and J.
    [stored] = container.log.read(house, event_type="inspection_targeted")
    assert stored.seq == before + 1 and stored.track_id == target["fixture_id"]
    assert stored.details["view"] == {k: target["view"][k] for k in ("x", "y", "yaw")}
    assert stored.details["uncertainty_terms"] == target["uncertainty"]["terms"]
    assert stored.details["cost_terms"] == target["view"]["cost_terms"]
    explained = client.get(
        f"/v1/scenes/{house}/tracks/{target['fixture_id']}/explain", params={"events": "true"}
    ).json()
    assert "inspection_targeted" in [e["type"] for e in explained["events"]]
    # The plan decided at seq n, reproduced from the log at n: the same target, view and terms.
    query = {**ROBOT, "as_of": decided["seq"]}
    replayed = client.get(f"/v1/scenes/{house}/plan", params=query).json()
    assert replayed["target"] == target and replayed["lock"] == "new"
    assert replayed["queue"] == decided["queue"] and replayed["event_seq"] is None
    # Now the lock holds, from anywhere; asking again appends nothing.
    elsewhere = {"x": 1.3, "y": 1.1, "yaw": 1.0}
    held = client.post(f"/v1/scenes/{house}/plan", json={"robot_pose": elsewhere}).json()
    assert held["lock"] == "held" and held["event_seq"] is None
    assert held["target"]["fixture_id"] == target["fixture_id"]
    assert {k: held["target"]["view"][k] for k in ("x", "y")} == {
        k: target["view"][k] for k in ("x", "y")
    }
    preview = client.get(f"/v1/scenes/{house}/plan", params=elsewhere).json()
    assert preview["lock"] == "held"
    assert head(client, house) == before + 1


def test_a_failed_capture_records_the_locked_view_and_the_fixture_cools_down(
    api: Api, house: str
) -> None:
    client, _, _ = api
    decided = client.post(f"/v1/scenes/{house}/plan", json={"robot_pose": ROBOT}).json()
    fixture_id = decided["target"]["fixture_id"]
    view = {k: decided["target"]["view"][k] for k in ("x", "y", "yaw")}
    body = {"fixture_id": fixture_id, "frames": [wire_frame(ROOM, AWAY_VIEW, "away-0")]}
    capture = client.post(f"/v1/scenes/{house}/inspections", json=body).json()
    assert capture["outcome"] == "support_not_visible" and capture["view"] == view
    queue = client.get(f"/v1/scenes/{house}/inspection-queue").json()["fixtures"]
    assert {f["fixture_id"]: f["status"] for f in queue}[fixture_id] == "retry_cooldown"
    after = client.post(f"/v1/scenes/{house}/plan", json={"robot_pose": ROBOT}).json()
    assert after["lock"] == "new" and after["target"]["fixture_id"] != fixture_id
    assert fixture_id not in [q["fixture_id"] for q in after["queue"]]


BAD_PLANS = [
    ({}, "robot_pose"),
    ({"robot_pose": {"x": 1.0, "y": 1.0}}, "robot_pose.yaw"),
    ({"robot_pose": {"x": "1", "y": 1.0, "yaw": 0.0}}, "robot_pose.x"),
    ({"robot_pose": {"x": 1e5, "y": 1.0, "yaw": 0.0}}, "robot_pose.x"),
    ({"robot_pose": {"x": 1.0, "y": 1.0, "yaw": 99.0}}, "robot_pose.yaw"),
    ({"robot_pose": {**ROBOT, "z": 1.0}}, "robot_pose.z"),
    ({"robot_pose": ROBOT, "as_of": 3}, "as_of"),
    ({"robot_pose": {"x": 500.0, "y": 1.0, "yaw": 0.0}}, "robot_pose.x"),  # beyond any map
]


def test_bad_plan_input_is_a_422_naming_the_field_and_appends_nothing(api: Api, house: str) -> None:
    client, _, _ = api
    before = head(client, house)
    for body, field in BAD_PLANS:
        response = client.post(f"/v1/scenes/{house}/plan", json=body)
        assert response.status_code == 422, (body, response.text)
        assert response.headers["content-type"] == "application/problem+json"
        assert response.json()["field"] == field, body
    response = client.post(
        f"/v1/scenes/{house}/plan",
        content=b'{"robot_pose": {"x": NaN, "y": 0, "yaw": 0}}',
        headers={"content-type": "application/json"},
    )
    assert response.status_code == 422
    queries: list[tuple[dict[str, str | float], str]] = [
        ({"x": "nan", "y": 0}, "x"),
        ({"x": 0}, "y"),
        ({"x": 0, "y": "a"}, "y"),
    ]
    for params, field in queries:
        response = client.get(f"/v1/scenes/{house}/plan", params=params)
        assert response.status_code == 422 and response.json()["field"] == field
    assert client.post("/v1/scenes/scn-none/plan", json={"robot_pose": ROBOT}).status_code == 404
    # A pose any map could hold, outside this scene's (100 m): a conflict with its parameters.
    outside = client.post(
        f"/v1/scenes/{house}/plan", json={"robot_pose": {"x": 150.0, "y": 1.0, "yaw": 0.0}}
    )
    assert outside.status_code == 409 and outside.json()["field"] == "robot_pose"
    assert "occupancy.half_extent_m" in outside.json()["detail"]
    assert head(client, house) == before
