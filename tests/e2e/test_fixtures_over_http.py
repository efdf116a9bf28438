"""Issue 3 through the HTTP API: fixtures, verification, support, baselines, inspections."""

from __future__ import annotations

import dataclasses
import math

import pytest

from service.store.projection import rebuild_scene
from tests.core.rendered import COUNTER_VIEWS, TABLE_VIEWS
from tests.eval_extra import require_eval_extra

require_eval_extra()  # the simulator renders this test's world

from tests.e2e.fixture_api import Api, api, discovered, feed, fixture_ids, nodes  # noqa: E402
from tests.e2e.fixture_world import (  # noqa: E402
    AWAY_VIEW,
    CLOSE_VIEW,
    COUNTER,
    FINE,
    ROOM,
    TABLE,
    wire_batches,
    wire_frame,
)

__all__ = ["api"]  # the fixture, used by name


def test_each_fixture_confirmed_once_with_label_center_and_the_mug_on_the_table(api: Api) -> None:
    client, worker, _ = api
    scene_id = discovered(client, worker)
    fixtures = [n for n in nodes(client, scene_id) if n["kind"] == "fixture"]
    assert sorted(n["label"] for n in fixtures) == ["counter", "table"]
    truth = {"table": TABLE.center, "counter": COUNTER.center}
    for node in fixtures:
        assert math.dist(node["center"], truth[node["label"]]) < 0.3
    confirms = client.get(
        f"/v1/scenes/{scene_id}/events", params={"type": "confirm", "limit": 1000}
    ).json()["events"]
    fixture_confirms = [e for e in confirms if e["track_id"] in {n["id"] for n in fixtures}]
    assert len(fixture_confirms) == 2
    ids = fixture_ids(client, scene_id)
    on_table = nodes(client, scene_id, parent=ids["table"])
    assert [n["label"] for n in on_table] == ["mug"]
    graph = client.get(f"/v1/scenes/{scene_id}/graph").json()
    assert {"source": on_table[0]["id"], "target": ids["table"], "relation": "on"} in graph["edges"]


def test_mug_carried_to_the_counter_reparents_once_and_keeps_its_identity(api: Api) -> None:
    client, worker, _ = api
    scene_id = discovered(client, worker)
    ids = fixture_ids(client, scene_id)
    mug_id = nodes(client, scene_id, label="mug")[0]["id"]
    carried = ROOM.moved("mug", (COUNTER.center[0], COUNTER.center[1], COUNTER.top_z + 0.05))
    # Its place is seen empty twice first: its absence is established (see the core's fallback).
    feed(client, worker, scene_id, wire_batches(carried, TABLE_VIEWS[1:3] + COUNTER_VIEWS * 2, "c"))
    reparents = client.get(
        f"/v1/scenes/{scene_id}/events", params={"type": "reparent", "track_id": mug_id}
    ).json()
    assert [e["details"] for e in reparents["events"]][-1] == {
        "old_parent": ids["table"],
        "new_parent": ids["counter"],
    }
    after_table = [e for e in reparents["events"] if e["details"]["old_parent"] == ids["table"]]
    assert len(after_table) == 1
    assert [n["id"] for n in nodes(client, scene_id, label="mug")] == [mug_id]
    assert nodes(client, scene_id, label="mug")[0]["parent"] == ids["counter"]


@pytest.mark.parametrize("verdict", ["confirm", "reject"])
def test_conflicting_fixture_waits_for_a_verdict(api: Api, verdict: str) -> None:
    client, worker, _ = api
    ambiguous = {"table": {"table": 0.50, "desk": 0.48}}
    scene_id = discovered(client, worker, ambiguity=ambiguous)
    pending = client.get(f"/v1/scenes/{scene_id}/verifications").json()["verifications"]
    assert len(pending) == 1
    item = pending[0]
    assert item["candidates"]["table"] > item["candidates"]["desk"] and item["best_frame"]
    graph = client.get(f"/v1/scenes/{scene_id}/graph").json()
    assert graph["pending_verifications"] == [item["track_id"]]
    assert "table" not in {n["label"] for n in graph["nodes"]}
    response = client.post(
        f"/v1/scenes/{scene_id}/tracks/{item['track_id']}/verification",
        json={"verdict": verdict, "source": "vlm-test", "frame_id": item["best_frame"]},
    )
    assert response.status_code == 201, response.text
    assert response.json()["events"][0]["type"] == "verify"
    after = client.get(f"/v1/scenes/{scene_id}/tracks/{item['track_id']}").json()
    assert after["state"] == ("confirmed" if verdict == "confirm" else "removed")
    assert client.get(f"/v1/scenes/{scene_id}/verifications").json()["verifications"] == []
    again = client.post(
        f"/v1/scenes/{scene_id}/tracks/{item['track_id']}/verification",
        json={"verdict": "confirm", "source": "vlm-test", "frame_id": item["best_frame"]},
    )
    assert again.status_code == 409 and again.json()["field"] == "frame_id"


def test_baseline_is_reproducible_pins_its_fixtures_and_seeds_a_new_session(api: Api) -> None:
    client, worker, container = api
    scene_id = discovered(client, worker)
    frozen = client.post(f"/v1/scenes/{scene_id}/baselines")
    assert frozen.status_code == 201, frozen.text
    package = frozen.json()
    assert package["version"] == 1 and len(package["package"]["fixtures"]) == 2
    assert rebuild_scene(container.log, scene_id).identical
    assert client.get(f"/v1/scenes/{scene_id}/baselines/1").json()["sha256"] == package["sha256"]
    # the table is taken away while the robot looks at its place: pinned, it is never removed
    without_table = dataclasses.replace(ROOM, fixtures=(COUNTER,), objects=())
    blind = wire_batches(without_table, TABLE_VIEWS * 5, "x")
    feed(client, worker, scene_id, blind)
    ids = fixture_ids(client, scene_id)
    table = client.get(f"/v1/scenes/{scene_id}/tracks/{ids['table']}").json()
    assert table["state"] == "confirmed" and table["visible_misses"] >= 10
    delta = client.get(f"/v1/scenes/{scene_id}/delta", params={"baseline": 1, "limit": 1000}).json()
    assert delta["events"] and all(e["seq"] > package["seq"] for e in delta["events"])
    # a later session in the same house keeps the fixture identities
    later = client.post(
        "/v1/scenes", json={"name": "next day", "baseline": {"scene_id": scene_id, "version": 1}}
    )
    assert later.status_code == 201, later.text
    later_id = later.json()["id"]
    assert fixture_ids(client, later_id) == ids
    assert all(n["pinned"] for n in nodes(client, later_id) if n["kind"] == "fixture")
    feed(client, worker, later_id, wire_batches(ROOM, TABLE_VIEWS, "n"))
    assert fixture_ids(client, later_id) == ids  # re-observed, not duplicated


def test_inspection_attaches_three_children_held_by_the_capture_ledger(api: Api) -> None:
    """Section 3.3: fine nodes from inspection do not re-enter the frame-level front end. A
    keyframe neither moves nor duplicates them; the next capture of their fixture does both."""
    client, worker, _ = api
    scene_id = discovered(client, worker)
    ids = fixture_ids(client, scene_id)
    queue = client.get(f"/v1/scenes/{scene_id}/inspection-queue").json()["fixtures"]
    # Both fixtures, most uncertain first (u_i of equation (4)).
    assert sorted(f["fixture_id"] for f in queue) == sorted(ids.values())
    uncertainties = [f["uncertainty"] for f in queue]
    assert uncertainties == sorted(uncertainties, reverse=True)
    world = ROOM.without("mug")
    for box in FINE:
        world = world.with_object(box)
    body = {
        "fixture_id": ids["table"],
        "frames": [wire_frame(world, CLOSE_VIEW, "insp-0")],
        "fixture_verified": True,
    }
    response = client.post(f"/v1/scenes/{scene_id}/inspections", json=body)
    assert response.status_code == 201, response.text
    capture = response.json()
    assert capture["outcome"] == "completed" and len(capture["children"]) == 3
    children = {
        n["label"]: n
        for n in nodes(client, scene_id, parent=ids["table"])
        if n["id"] in capture["children"]
    }
    assert sorted(children) == ["book", "bowl", "remote"]
    ledger = client.get(f"/v1/scenes/{scene_id}/inspections").json()["inspections"]
    assert [c["capture_id"] for c in ledger] == [capture["capture_id"]]
    assert ids["table"] not in [
        f["fixture_id"]
        for f in client.get(f"/v1/scenes/{scene_id}/inspection-queue").json()["fixtures"]
    ]
    moved = world.moved("bowl", (TABLE.center[0] + 0.45, TABLE.center[1] - 0.2, TABLE.top_z + 0.04))
    bowl_id = children["bowl"]["id"]

    def bowl_events(kind: str) -> list[dict[str, object]]:
        query = {"type": kind, "track_id": bowl_id}
        page = client.get(f"/v1/scenes/{scene_id}/events", params=query).json()
        return list(page["events"])

    observed_before = len(bowl_events("update"))
    feed(
        client,
        worker,
        scene_id,
        [{"batch_id": "later", "frames": [wire_frame(moved, CLOSE_VIEW, "later-0")]}],
    )
    assert bowl_events("move") == [] and len(bowl_events("update")) == observed_before
    assert [n["id"] for n in nodes(client, scene_id, label="bowl")] == [bowl_id]
    again = {
        "fixture_id": ids["table"],
        "frames": [wire_frame(moved, CLOSE_VIEW, "insp-1")],
        "fixture_verified": True,
    }
    response = client.post(f"/v1/scenes/{scene_id}/inspections", json=again)
    assert response.status_code == 201, response.text
    assert bowl_id in response.json()["children"]
    assert len(bowl_events("move")) == 1
    assert [n["id"] for n in nodes(client, scene_id, label="bowl")] == [bowl_id]


def test_failed_capture_keeps_the_fixture_queued_for_a_bounded_retry(api: Api) -> None:
    client, worker, _ = api
    scene_id = discovered(client, worker)
    table_id = fixture_ids(client, scene_id)["table"]
    statuses: list[str | None] = []
    for attempt in range(3):
        body = {"fixture_id": table_id, "frames": [wire_frame(ROOM, AWAY_VIEW, f"away-{attempt}")]}
        capture = client.post(f"/v1/scenes/{scene_id}/inspections", json=body).json()
        assert capture["outcome"] == "support_not_visible" and capture["children"] == []
        statuses.append(capture["status"])
        queued = [
            f["fixture_id"]
            for f in client.get(f"/v1/scenes/{scene_id}/inspection-queue").json()["fixtures"]
        ]
        assert (table_id in queued) == (attempt < 2)
    assert statuses == [None, None, "abandoned"]


def test_bad_commands_get_a_clear_4xx_and_change_nothing(api: Api) -> None:
    client, worker, _ = api
    scene_id = discovered(client, worker)
    head = client.get(f"/v1/scenes/{scene_id}").json()["head_seq"]
    mug_id = nodes(client, scene_id, label="mug")[0]["id"]
    frame = wire_frame(ROOM, CLOSE_VIEW, "bad-0")
    cases = [
        (
            "post",
            f"/v1/scenes/{scene_id}/inspections",
            {"fixture_id": "trk-999999", "frames": [frame]},
            404,
            "fixture_id",
        ),
        (
            "post",
            f"/v1/scenes/{scene_id}/inspections",
            {"fixture_id": mug_id, "frames": [frame]},
            422,
            "fixture_id",
        ),
        (
            "post",
            f"/v1/scenes/{scene_id}/tracks/trk-999999/verification",
            {"verdict": "confirm", "source": "x"},
            404,
            "track_id",
        ),
        (
            "post",
            f"/v1/scenes/{scene_id}/tracks/{mug_id}/verification",
            {"verdict": "maybe", "source": "x"},
            422,
            "verdict",
        ),
        ("get", f"/v1/scenes/{scene_id}/baselines/7", None, 404, None),
        (
            "post",
            "/v1/scenes",
            {"name": "x", "baseline": {"scene_id": scene_id, "version": 3}},
            404,
            None,
        ),
    ]
    bad_scores = wire_frame(ROOM, TABLE_VIEWS[0], "bad-1")
    bad_scores["detections"][0]["class_scores"] = {"table": "high"}
    cases.append(
        (
            "post",
            f"/v1/scenes/{scene_id}/batches",
            {"batch_id": "bad", "frames": [bad_scores]},
            422,
            "frames[0].detections[0].class_scores",
        )
    )
    for method, url, body, status, field in cases:
        response = (
            getattr(client, method)(url, json=body)
            if body is not None
            else getattr(client, method)(url)
        )
        assert response.status_code == status, (url, response.text)
        assert response.headers["content-type"] == "application/problem+json"
        if field is not None:
            assert response.json()["field"].startswith(field), response.json()
    assert client.get(f"/v1/scenes/{scene_id}").json()["head_seq"] == head
    assert len(client.get("/v1/scenes").json()["scenes"]) == 1


def test_inspection_of_an_unconfirmed_fixture_is_a_409(api: Api) -> None:
    client, worker, _ = api
    scene_id = client.post("/v1/scenes", json={"name": "young"}).json()["id"]
    feed(client, worker, scene_id, wire_batches(ROOM, TABLE_VIEWS[:1], "y"))
    table = next(n for n in nodes(client, scene_id, include="all") if n["kind"] == "fixture")
    assert table["state"] == "tentative"
    body = {"fixture_id": table["id"], "frames": [wire_frame(ROOM, CLOSE_VIEW, "y-insp")]}
    response = client.post(f"/v1/scenes/{scene_id}/inspections", json=body)
    assert response.status_code == 409 and response.json()["field"] == "fixture_id"
