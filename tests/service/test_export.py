"""Exports of the published graph: GraphML and node-link JSON, over HTTP and `pbdag export`."""

from __future__ import annotations

import io
import json
from pathlib import Path

import networkx as nx
import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.bootstrap import Container, build_container
from service.cli import main
from service.export import export_graph, graphml_attributes
from service.settings import Settings
from service.worker import Worker
from tests.clients import local_client
from tests.wire_scenes import batch

GRAPHML = "application/graphml+xml"
# The mug is seen 3 times, then its place is seen empty until it is removed.
SIGHTINGS, BATCHES = 3, 12


def post_story(client: TestClient, container: Container) -> tuple[str, int]:
    """A scene whose mug is confirmed, then removed; (scene id, the seq of its confirmation)."""
    scene_id = str(client.post("/v1/scenes", json={"name": "export"}).json()["id"])
    for i in range(BATCHES):
        posted = client.post(f"/v1/scenes/{scene_id}/batches", json=batch(f"b{i}", i, mug=i < 3))
        assert posted.status_code == 202, posted.text
    assert Worker(container).drain() == BATCHES
    removals = client.get(f"/v1/scenes/{scene_id}/events", params={"type": "remove"}).json()
    assert [e["track_id"] for e in removals["events"]] == ["trk-000001"]
    confirms = client.get(f"/v1/scenes/{scene_id}/events", params={"type": "confirm"}).json()
    confirmed_at = int(confirms["events"][0]["seq"])
    assert confirmed_at < int(removals["events"][0]["seq"])
    return scene_id, confirmed_at


def read_graphml(body: bytes) -> nx.DiGraph:
    graph = nx.read_graphml(io.BytesIO(body))
    assert isinstance(graph, nx.DiGraph)
    return graph


def test_graphml_and_json_graph_parse_back_and_as_of_sees_the_removed_mug(
    container: Container, client: TestClient
) -> None:
    scene_id, confirmed_at = post_story(client, container)
    url = f"/v1/scenes/{scene_id}/graph"
    now = client.get(url, params={"format": "graphml"})
    assert now.status_code == 200 and now.headers["content-type"] == GRAPHML
    assert list(read_graphml(now.content).nodes) == []  # removed: not published
    before = client.get(url, params={"format": "graphml", "as_of": confirmed_at})
    graph = read_graphml(before.content)
    assert list(graph.nodes) == ["trk-000001"]
    mug = graph.nodes["trk-000001"]
    assert (mug["label"], mug["state"], mug["kind"]) == ("mug", "confirmed", "object")
    assert mug["center_z"] == pytest.approx(2.0, abs=0.1)
    assert json.loads(mug["class_probabilities"])["mug"] > 0.5
    assert "parent" not in mug  # None is left out
    assert graph.graph["seq"] == confirmed_at and graph.graph["scene_id"] == scene_id

    as_json = client.get(url, params={"format": "json-graph", "as_of": confirmed_at})
    assert as_json.headers["content-type"] == "application/json"
    linked = nx.node_link_graph(as_json.json(), edges="edges")
    assert linked.is_directed() and list(linked.nodes) == ["trk-000001"]
    assert linked.nodes["trk-000001"]["center"] == pytest.approx(
        [mug["center_x"], mug["center_y"], mug["center_z"]]
    )
    assert linked.nodes["trk-000001"]["parent"] is None
    # The default answer is unchanged, and agrees with the exports.
    plain = client.get(url, params={"as_of": confirmed_at}).json()
    assert [node["id"] for node in plain["nodes"]] == ["trk-000001"]
    every = client.get(url, params={"format": "json-graph", "include": "all"}).json()
    assert [(n["id"], n["state"]) for n in every["nodes"]] == [("trk-000001", "removed")]


def test_a_bad_format_or_a_seq_past_the_head_names_the_field(
    container: Container, client: TestClient
) -> None:
    scene_id = client.post("/v1/scenes", json={"name": "x"}).json()["id"]
    bad = client.get(f"/v1/scenes/{scene_id}/graph", params={"format": "gexf"})
    assert bad.status_code == 422 and bad.json()["field"] == "format"
    assert bad.headers["content-type"] == "application/problem+json"
    late = client.get(f"/v1/scenes/{scene_id}/graph", params={"format": "graphml", "as_of": 99})
    assert late.status_code == 404 and late.json()["field"] == "as_of"


def supported_graph() -> nx.DiGraph:
    """A mug on a table, with the attributes core.graph.node_attributes gives a node."""
    graph = nx.DiGraph(seq=7)
    for track_id, kind, label, parent in (
        ("trk-000001", "fixture", "table", None),
        ("trk-000002", "object", "mug", "trk-000001"),
    ):
        graph.add_node(
            track_id,
            id=track_id,
            kind=kind,
            label=label,
            state="confirmed",
            p_exist=0.98,
            center=[1.0, 2.0, 0.75],
            extent=[0.1, 0.1, 0.1],
            parent=parent,
            class_probabilities={label: 0.9, "other": 0.1},
            last_observed=3.5,
            last_observed_frame="f3",
            pinned=False,
            verification=None,
            inspection=None,
        )
    graph.add_edge("trk-000002", "trk-000001", relation="on")
    return graph


def test_support_edges_and_flattened_attributes_survive_both_formats() -> None:
    graph = supported_graph()
    graphml = read_graphml(export_graph(graph, "graphml"))
    assert list(graphml.edges(data=True)) == [("trk-000002", "trk-000001", {"relation": "on"})]
    assert graphml.nodes["trk-000002"]["parent"] == "trk-000001"
    assert graphml.nodes["trk-000002"]["pinned"] is False
    assert graphml.nodes["trk-000002"]["p_exist"] == 0.98
    linked = nx.node_link_graph(json.loads(export_graph(graph, "json-graph")), edges="edges")
    assert list(linked.edges(data=True)) == list(graph.edges(data=True))
    for node, attributes in graph.nodes(data=True):  # node_link_graph keeps `id` as the node
        assert {"id": node, **linked.nodes[node]} == attributes


def test_graphml_attributes_follow_the_documented_rule() -> None:
    flat = graphml_attributes(
        {"id": "t", "center": [1, 2.5, 3], "parent": None, "scores": {"b": 1.0, "a": 0.5}}
    )
    assert flat == {
        "center_x": 1.0,
        "center_y": 2.5,
        "center_z": 3.0,
        "scores": '{"a":0.5,"b":1.0}',
    }


def test_pbdag_export_writes_the_graph_of_the_configured_database(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("PBDAG_DATA_DIR", str(tmp_path))
    monkeypatch.delenv("PBDAG_DATABASE_URL", raising=False)
    container = build_container(Settings(allow_anonymous_local=True))
    with local_client(create_app(container)) as client:
        scene_id, confirmed_at = post_story(client, container)
    out = tmp_path / "scene.graphml"
    assert main(["export", scene_id, "--as-of", str(confirmed_at), "--out", str(out)]) == 0
    assert list(read_graphml(out.read_bytes()).nodes) == ["trk-000001"]
    assert "1 nodes, 0 edges" in capsys.readouterr().err
    assert main(["export", scene_id, "--format", "json-graph"]) == 0
    assert json.loads(capsys.readouterr().out)["nodes"] == []
    assert main(["export", "scn-missing"]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["export", scene_id, "--as-of", "9999"]) == 2
    assert "outside" in capsys.readouterr().err
