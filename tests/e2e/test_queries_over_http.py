"""Questions in the robot's terms over the HTTP API, on scenes the simulator renders: where is
the mug, what is on the counter, what changed, what is near a point, what looks like this, where
was the carried mug, and the scene at a time on the robot's clock."""

from __future__ import annotations

import itertools
import math
from datetime import UTC, datetime
from typing import Any

import numpy as np
import pytest

from tests.core.rendered import COUNTER_VIEWS, TABLE_VIEWS
from tests.eval_extra import require_eval_extra

require_eval_extra()  # the simulator renders this test's world

from sim.detector import object_embedding  # noqa: E402
from tests.e2e.fixture_api import Api, api, feed, fixture_ids  # noqa: E402
from tests.e2e.fixture_world import COUNTER, MUG, ROOM, wire_batches  # noqa: E402
from tests.e2e.query_world import (  # noqa: E402
    BOWL,
    FIVE_MUGS,
    KITCHEN,
    MUGS,
    START,
    discovered_at,
    timed,
)

__all__ = ["api"]  # the fixture, used by name


def objects(client: Any, scene_id: str, **params: Any) -> dict[str, Any]:
    response = client.get(f"/v1/scenes/{scene_id}/objects", params=params)
    assert response.status_code == 200, response.text
    answer: dict[str, Any] = response.json()
    return answer


def labels(answer: dict[str, Any]) -> list[str]:
    return [item["label"] for item in answer["objects"]]


def test_where_is_the_mug_and_what_is_on_the_counter(api: Api) -> None:
    client, worker, _ = api
    scene_id, _bodies = discovered_at(client, worker, KITCHEN)
    ids = fixture_ids(client, scene_id)
    [mug] = objects(client, scene_id, label="mug")["objects"]
    assert mug["parent"] == ids["table"] and mug["parent_label"] == "table"
    assert mug["state"] == "confirmed" and mug["class_probabilities"]["mug"] > 0.5
    assert math.dist(mug["center"], MUG.center) < 0.15
    # The mug is seen from the table views only: the tour's last one is batch 8 (of 12).
    assert mug["last_observed_frame"] == "d8" and mug["last_observed"] == START + 8
    on_counter = objects(client, scene_id, on=ids["counter"])
    assert labels(on_counter) == ["bowl"]
    [bowl] = on_counter["objects"]
    assert bowl["parent_label"] == "counter" and math.dist(bowl["center"], BOWL.center) < 0.15
    assert bowl["last_observed_frame"] == "d11"
    assert labels(objects(client, scene_id, on=ids["table"])) == ["mug"]
    # Fixtures are never objects; a class nobody saw answers nothing.
    assert labels(objects(client, scene_id)) == ["mug", "bowl"]  # by track id
    assert objects(client, scene_id, label="table")["objects"] == []
    assert objects(client, scene_id, state="removed")["objects"] == []


def test_what_changed_since_a_seq_or_a_time(api: Api) -> None:
    client, worker, _ = api
    scene_id, _bodies = discovered_at(client, worker, KITCHEN)
    head = client.get(f"/v1/scenes/{scene_id}").json()["head_seq"]
    assert objects(client, scene_id, changed_since=head)["objects"] == []
    # The robot looks at the table again, later, from the two views that do not reach the
    # counter (the first one does): the mug is seen, the bowl is not.
    again = timed(wire_batches(KITCHEN, TABLE_VIEWS[1:], "t"), START + 100)
    feed(client, worker, scene_id, again)
    changed = objects(client, scene_id, changed_since=head)
    assert labels(changed) == ["mug"] and changed["objects"][0]["changed_seq"] > head
    by_time = objects(client, scene_id, changed_since_time=START + 50)
    assert by_time["objects"] == changed["objects"]
    assert labels(objects(client, scene_id, changed_since=0)) == ["mug", "bowl"]


def test_objects_within_a_metre_of_a_point_by_distance_and_paged(api: Api) -> None:
    client, worker, _ = api
    scene_id, _bodies = discovered_at(client, worker, KITCHEN)
    near_mug = ",".join(str(v) for v in MUG.center)
    within = objects(client, scene_id, near=near_mug, radius=1.0)
    assert labels(within) == ["mug"] and within["objects"][0]["distance"] < 0.15
    # Between the two, nearer the bowl (the table and the counter are 3 m apart).
    point = (3.6, 3.0, 0.9)
    assert math.dist(point, BOWL.center) < math.dist(point, MUG.center)
    everything = objects(client, scene_id, near="3.6,3.0,0.9")
    assert labels(everything) == ["bowl", "mug"]
    distances = [item["distance"] for item in everything["objects"]]
    assert distances == sorted(distances)
    first = objects(client, scene_id, near="3.6,3.0,0.9", limit=1)
    assert labels(first) == ["bowl"] and first["next_after"] == first["objects"][0]["track_id"]
    second = objects(
        client, scene_id, near="3.6,3.0,0.9", limit=1, after=first["next_after"], as_of=first["seq"]
    )
    assert labels(second) == ["mug"] and second["next_after"] is None


def test_as_of_time_between_two_batches_is_the_earlier_batchs_state(api: Api) -> None:
    client, worker, _ = api
    scene_id, bodies = discovered_at(client, worker, KITCHEN)
    status = [
        client.get(f"/v1/scenes/{scene_id}/batches/{body['batch_id']}").json() for body in bodies
    ]
    fifth, sixth = status[4]["last_seq"], status[5]["last_seq"]  # batches at 104 s and 105 s
    base = f"/v1/scenes/{scene_id}"
    iso = datetime.fromtimestamp(START + 4.5, UTC).isoformat()
    for when in (START + 4.5, iso, START + 4):
        graph = client.get(f"{base}/graph", params={"as_of_time": when, "include": "all"})
        assert graph.status_code == 200 and graph.json()["seq"] == fifth
        assert (
            graph.json()
            == client.get(f"{base}/graph", params={"as_of": fifth, "include": "all"}).json()
        )
    assert client.get(f"{base}/graph", params={"as_of_time": START + 5}).json()["seq"] == sixth
    assert objects(client, scene_id, as_of_time=START + 4.5)["seq"] == fifth
    mug_id = objects(client, scene_id, label="mug")["objects"][0]["track_id"]
    for path, params in (
        (f"/tracks/{mug_id}", {}),
        ("/occupancy", {}),
        ("/plan", {"x": 1.0, "y": 1.0}),
        (f"/tracks/{mug_id}/history", {}),
    ):
        answer = client.get(f"{base}{path}", params={**params, "as_of_time": START + 4.5})
        assert answer.status_code == 200 and answer.json()["seq"] == fifth, path
    # A time after the last batch is the head; before the first, no state on the robot's clock.
    head = client.get(base).json()["head_seq"]
    assert client.get(f"{base}/graph", params={"as_of_time": START + 1e4}).json()["seq"] == head
    before = client.get(f"{base}/graph", params={"as_of_time": START - 1})
    assert before.status_code == 404 and before.json()["field"] == "as_of_time"


def test_similar_among_five_mugs_picks_the_one_that_looks_so(api: Api) -> None:
    client, worker, _ = api
    scene_id, _bodies = discovered_at(client, worker, FIVE_MUGS)
    tracks = objects(client, scene_id)["objects"]
    assert len(tracks) == 5
    rng = np.random.default_rng(3)
    for mug in MUGS:
        # The mug as a camera might see it again: its look, with crop noise.
        look = object_embedding(mug.id) + rng.normal(0.0, 0.05, size=64)
        response = client.post(
            f"/v1/scenes/{scene_id}/objects/similar", json={"embedding": look.tolist(), "k": 3}
        )
        assert response.status_code == 200, response.text
        matches = response.json()["matches"]
        assert len(matches) == 3
        truth = min(tracks, key=lambda item: math.dist(item["center"], mug.center))
        assert matches[0]["track_id"] == truth["track_id"]
        assert matches[0]["score"] > 0.9 > matches[1]["score"] >= matches[2]["score"]
        assert matches[0]["label"] == "mug" and matches[0]["class_probabilities"]["mug"] > 0.5
    look = object_embedding("mug-a").tolist()
    none = client.post(
        f"/v1/scenes/{scene_id}/objects/similar", json={"embedding": look, "label": "bowl"}
    )
    assert none.status_code == 200 and none.json()["matches"] == []


def test_history_of_a_carried_mug_shows_both_parents_in_order(api: Api) -> None:
    client, worker, _ = api
    scene_id, _bodies = discovered_at(client, worker, ROOM)
    ids = fixture_ids(client, scene_id)
    mug_id = objects(client, scene_id, label="mug")["objects"][0]["track_id"]
    carried = ROOM.moved("mug", (COUNTER.center[0], COUNTER.center[1], COUNTER.top_z + 0.05))
    later = timed(wire_batches(carried, TABLE_VIEWS[1:3] + COUNTER_VIEWS * 2, "c"), START + 100)
    feed(client, worker, scene_id, later)
    history = client.get(f"/v1/scenes/{scene_id}/tracks/{mug_id}/history").json()
    spans = history["spans"]
    parents = [span["parent"] for span in spans if span["parent"] is not None]
    assert [p for i, p in enumerate(parents) if i == 0 or parents[i - 1] != p] == [
        ids["table"],
        ids["counter"],
    ]
    assert all(a["to_seq"] < b["from_seq"] for a, b in itertools.pairwise(spans))
    assert spans[0]["from_time"] is not None and spans[-1]["to_time"] >= START + 100
    assert math.dist(spans[-1]["center"], carried.objects[0].center) < 0.15
    # Each span ends as the track was at that seq (the whole scene folded to it).
    for span in spans:
        belief = client.get(
            f"/v1/scenes/{scene_id}/tracks/{mug_id}", params={"as_of": span["to_seq"]}
        ).json()
        assert belief["parent"] == span["parent"] and belief["state"] == span["state"]
        assert belief["center"] == span["center"]
    paged = client.get(f"/v1/scenes/{scene_id}/tracks/{mug_id}/history", params={"limit": 1}).json()
    assert paged["spans"] == spans[:1] and paged["next_after"] == spans[0]["from_seq"]


@pytest.mark.parametrize(
    ("path", "params", "field"),
    [
        ("/objects", {"near": "1,2"}, "near"),
        ("/objects", {"near": "nan,0,0"}, "near"),
        ("/objects", {"near": "1,2,1e9"}, "near"),
        ("/objects", {"radius": 1.0}, "radius"),
        ("/objects", {"near": "1,2,0", "radius": 0}, "radius"),
        ("/objects", {"near": "1,2,0", "radius": 1000}, "radius"),
        ("/objects", {"near": "1,2,0", "radius": "inf"}, "radius"),
        ("/objects", {"limit": 0}, "limit"),
        ("/objects", {"limit": 1001}, "limit"),
        ("/objects", {"state": "lost"}, "state"),
        ("/objects", {"changed_since": -1}, "changed_since"),
        ("/objects", {"changed_since": 1, "changed_since_time": 5}, "changed_since_time"),
        ("/objects", {"as_of": 1, "as_of_time": 5}, "as_of_time"),
        ("/objects", {"as_of_time": "yesterday"}, "as_of_time"),
        ("/objects", {"as_of_time": "2026-12-03T10:00:00"}, "as_of_time"),  # no timezone
        ("/objects", {"as_of_time": "1e12"}, "as_of_time"),
        ("/objects", {"as_of_time": "nan"}, "as_of_time"),
        ("/graph", {"as_of": 1, "as_of_time": 5}, "as_of_time"),
        ("/occupancy", {"as_of_time": "x" * 41}, "as_of_time"),
        ("/tracks/trk-000001/history", {"limit": 0}, "limit"),
    ],
)
def test_bad_questions_name_their_field_and_change_nothing(
    api: Api, path: str, params: dict[str, Any], field: str
) -> None:
    client, _worker, _ = api
    scene_id = client.post("/v1/scenes", json={"name": "empty"}).json()["id"]
    response = client.get(f"/v1/scenes/{scene_id}{path}", params=params)
    assert response.status_code == 422, response.text
    assert response.json()["field"] == field
    assert client.get(f"/v1/scenes/{scene_id}").json()["head_seq"] == 0


def test_bad_similarity_questions_name_their_field(api: Api) -> None:
    client, worker, _ = api
    scene_id, _bodies = discovered_at(client, worker, FIVE_MUGS)
    head = client.get(f"/v1/scenes/{scene_id}").json()["head_seq"]
    look = object_embedding("mug-a").tolist()
    for body, field in (
        ({"embedding": [0.0] * 64}, "embedding"),  # a zero vector has no direction
        ({"embedding": look[:32]}, "embedding"),  # not the scene's dimension
        ({"embedding": []}, "embedding"),
        ({"embedding": [1.0] * 4097}, "embedding"),
        ({"embedding": [1e7] * 64}, "embedding[0]"),
        ({"embedding": look, "k": 0}, "k"),
        ({"embedding": look, "k": 101}, "k"),
        ({"embedding": look, "label": ""}, "label"),
        ({"embedding": look, "extra": 1}, "extra"),
    ):
        response = client.post(f"/v1/scenes/{scene_id}/objects/similar", json=body)
        assert response.status_code == 422, (body, response.text)
        assert response.json()["field"] == field
    missing = client.get(f"/v1/scenes/{scene_id}/tracks/trk-999999/history")
    assert missing.status_code == 404 and missing.json()["field"] == "track_id"
    cursor = client.get(f"/v1/scenes/{scene_id}/objects", params={"after": "trk-999999"})
    assert cursor.status_code == 404 and cursor.json()["field"] == "after"
    assert client.get(f"/v1/scenes/{scene_id}").json()["head_seq"] == head
