"""Scene params a write token could use to blow up the service's work, and the scene list's
pages: each refused with a 422 naming the field, nothing created."""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient

from core.events import SceneCreated
from core.evolve import fold
from core.params import MAX_CLASS_SCORE_CELLS, Params
from core.state import SceneState


def refused(client: TestClient, params: Any, field: str, reason: str) -> None:
    """POST a scene with `params`: a 422 naming `field` and `reason`, and no scene made."""
    before = len(client.get("/v1/scenes", params={"limit": 1000}).json()["scenes"])
    response = client.post("/v1/scenes", json={"name": "x", "params": params})
    assert response.status_code == 422, response.text[:300]
    problem = response.json()
    assert problem["field"] == field and reason in problem["detail"], problem["detail"]
    assert len(client.get("/v1/scenes", params={"limit": 1000}).json()["scenes"]) == before


def nested(depth: int) -> dict[str, Any]:
    value: dict[str, Any] = {"a": 1}
    for _ in range(depth - 1):
        value = {"a": value}
    return value


@pytest.mark.parametrize("depth", [254, 600])
def test_params_nested_hundreds_of_levels_deep_are_a_422(client: TestClient, depth: int) -> None:
    refused(client, nested(depth), "params.a.a.a.a.a.a", "nested deeper than 6 levels")


def test_an_integer_past_64_bits_in_params_is_a_422(client: TestClient) -> None:
    refused(
        client,
        {"fixtures": {"max_points_per_batch": 2**64 + 1}},
        "params.fixtures.max_points_per_batch",
        "beyond 2^53",
    )


def test_a_params_map_of_500000_keys_is_a_422(client: TestClient) -> None:
    thresholds = {f"class{i}": 0.5 for i in range(500_000)}
    refused(
        client,
        {"fixtures": {"class_thresholds": thresholds}},
        "params.fixtures.class_thresholds",
        "at most 64 keys in one object, got 500000",
    )


@pytest.mark.parametrize(
    ("params", "field", "reason"),
    [
        (
            {"fixtures": {"max_voxels_per_batch": 10_000_000}},
            "params.fixtures.max_voxels_per_batch",
            "less than or equal to 1000000",
        ),
        (
            {"fixtures": {"max_points_per_batch": 100_000_000}},
            "params.fixtures.max_points_per_batch",
            "less than or equal to 10000000",
        ),
        (
            {"fixtures": {"taxonomy": [f"c{i}" for i in range(64)]}},
            "params.fixtures",
            "max_voxels_per_batch: at most 31,250 for a taxonomy of 64 classes",
        ),
    ],
)
def test_work_budgets_past_their_ceilings_are_422s(
    client: TestClient, params: dict[str, Any], field: str, reason: str
) -> None:
    refused(client, params, field, reason)


def test_the_widest_taxonomy_is_accepted_with_a_budget_to_match(client: TestClient) -> None:
    classes = [f"c{i}" for i in range(64)]
    params = {"fixtures": {"taxonomy": classes, "max_voxels_per_batch": 31_250}}
    response = client.post("/v1/scenes", json={"name": "wide", "params": params})
    assert response.status_code == 201, response.text[:300]
    assert response.json()["params"]["fixtures"]["max_voxels_per_batch"] == 31_250


def test_a_scene_recorded_with_a_budget_above_todays_ceiling_replays_clamped() -> None:
    recorded = Params().to_dict()
    recorded["fixtures"].update(
        taxonomy=[f"c{i}" for i in range(64)],
        max_voxels_per_batch=10_000_000,
        max_points_per_batch=100_000_000,
    )
    state = fold(SceneState(), [SceneCreated(name="old", params=recorded)])
    assert state.params.fixtures.max_voxels_per_batch == MAX_CLASS_SCORE_CELLS // 64
    assert state.params.fixtures.max_points_per_batch == 10_000_000
    assert state.params.fixtures.taxonomy == tuple(recorded["fixtures"]["taxonomy"])


def test_the_scene_list_pages_oldest_first(client: TestClient) -> None:
    made = [client.post("/v1/scenes", json={"name": f"s{i}"}).json()["id"] for i in range(5)]
    seen: list[str] = []
    after: str | None = None
    pages = 0
    while True:
        query: dict[str, Any] = {"limit": 2, **({"after": after} if after else {})}
        page = client.get("/v1/scenes", params=query).json()
        seen.extend(scene["id"] for scene in page["scenes"])
        pages += 1
        if page["next_after"] is None:
            break
        after = page["next_after"]
    assert seen == made and pages == 3
    missing = client.get("/v1/scenes", params={"after": "scn-nothere"})
    assert missing.status_code == 404 and missing.json()["field"] == "after"
    assert client.get("/v1/scenes", params={"limit": 1001}).status_code == 422


def test_a_label_in_params_with_a_non_character_is_a_422(client: TestClient) -> None:
    refused(
        client,
        {"fixtures": {"taxonomy": ["table", "desk\uffff"]}},
        "params.fixtures.taxonomy[1]",
        "no control or non-character",
    )
