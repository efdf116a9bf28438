"""The GraphML export as XML tools read it: well-formed whatever the log holds, booleans as
xs:boolean, read back by ElementTree and by networkx.read_graphml with their types."""

from __future__ import annotations

import io
import xml.etree.ElementTree as ET
from dataclasses import replace

import networkx as nx
from fastapi.testclient import TestClient

from service.bootstrap import Container
from service.export import export_graph
from service.store.engine import write_transaction
from service.worker import Worker
from tests.service.minimal_events import added
from tests.wire_scenes import batch

NS = {"g": "http://graphml.graphdrawing.org/xmlns"}


def keys_of(document: bytes) -> dict[str, tuple[str, str, str]]:
    """The document's keys: id -> (for, attr.name, attr.type)."""
    root = ET.fromstring(document)
    return {
        key.attrib["id"]: (key.attrib["for"], key.attrib["attr.name"], key.attrib["attr.type"])
        for key in root.findall("g:key", NS)
    }


def node_data(document: bytes, node_id: str) -> dict[str, str]:
    """The raw text of a node's data elements, by attribute name."""
    names = {key_id: name for key_id, (_for, name, _type) in keys_of(document).items()}
    node = ET.fromstring(document).find(f"g:graph/g:node[@id='{node_id}']", NS)
    assert node is not None, node_id
    return {names[data.attrib["key"]]: data.text or "" for data in node.findall("g:data", NS)}


def test_an_exported_scene_reads_back_with_its_booleans(
    container: Container, client: TestClient
) -> None:
    scene_id = client.post("/v1/scenes", json={"name": "kitchen"}).json()["id"]
    for i in range(3):  # the mug is seen three times: confirmed
        posted = client.post(f"/v1/scenes/{scene_id}/batches", json=batch(f"b{i}", i))
        assert posted.status_code == 202, posted.text
    assert Worker(container).drain() == 3
    response = client.get(f"/v1/scenes/{scene_id}/graph", params={"format": "graphml"})
    assert response.status_code == 200 and response.headers["content-type"].startswith(
        "application/graphml+xml"
    )
    document = response.content
    # ElementTree: well-formed, the boolean key typed boolean, its value xs:boolean.
    assert ("node", "pinned", "boolean") in keys_of(document).values()
    raw = node_data(document, "trk-000001")
    assert raw["pinned"] == "false" and raw["label"] == "mug" and raw["state"] == "confirmed"
    # networkx: the same graph, with Python types.
    graph = nx.read_graphml(io.BytesIO(document))
    mug = graph.nodes["trk-000001"]
    assert mug["pinned"] is False
    assert isinstance(mug["p_exist"], float) and mug["p_exist"] > 0.5
    assert graph.graph["scene_id"] == scene_id and isinstance(graph.graph["seq"], int)


def test_true_and_false_are_xs_boolean_and_numbers_keep_their_types() -> None:
    graph = nx.DiGraph(seq=4)
    graph.add_node("trk-000001", pinned=True, p_exist=1, label="table")
    graph.add_node("trk-000002", pinned=False, p_exist=0.5, label="mug")
    graph.add_edge("trk-000002", "trk-000001", relation="on", confirmed=True)
    document = export_graph(graph, "graphml")
    assert node_data(document, "trk-000001")["pinned"] == "true"
    assert node_data(document, "trk-000002")["pinned"] == "false"
    assert b">True<" not in document and b">False<" not in document
    types = {(scope, name): xml_type for scope, name, xml_type in keys_of(document).values()}
    assert types == {
        ("graph", "seq"): "long",
        ("node", "pinned"): "boolean",
        ("node", "p_exist"): "double",  # an integer and a float: numbers
        ("node", "label"): "string",
        ("edge", "relation"): "string",
        ("edge", "confirmed"): "boolean",
    }
    read = nx.read_graphml(io.BytesIO(document))
    assert read.nodes["trk-000001"] == {"pinned": True, "p_exist": 1.0, "label": "table"}
    assert read.nodes["trk-000002"]["pinned"] is False
    assert read.edges["trk-000002", "trk-000001"] == {"relation": "on", "confirmed": True}


def test_text_an_older_version_stored_still_exports_well_formed(
    container: Container, client: TestClient
) -> None:
    # An event as the code before the text rule accepted it: U+FFFF in a label, U+FFFE in a
    # frame id (XML 1.0 forbids both, even as character references).
    scene_id = client.post("/v1/scenes", json={"name": "old"}).json()["id"]
    event = added("trk-000001")
    old = replace(event.observations[0], label="mu\uffffg", frame_id="f\ufffe")
    with write_transaction(container.engine) as connection:
        container.log.append(connection, scene_id, 0, [replace(event, observations=(old,))])
    url = f"/v1/scenes/{scene_id}/graph"
    assert client.get(url, params={"include": "all"}).json()["nodes"][0]["label"] == "mu\uffffg"
    document = client.get(url, params={"format": "graphml", "include": "all"}).content
    assert "\uffff".encode() not in document and "\ufffe".encode() not in document
    assert node_data(document, "trk-000001")["label"] == "mu\ufffdg"  # ElementTree parses it
    graph = nx.read_graphml(io.BytesIO(document))
    assert graph.nodes["trk-000001"]["label"] == "mu\ufffdg"
    assert "mu\ufffdg" in graph.nodes["trk-000001"]["class_probabilities"]


def test_every_string_of_the_document_is_cleaned() -> None:
    graph = nx.DiGraph(seq=1, scene_id="s\x00")
    graph.add_node("n\uffff", **{"label": "a\ud800b", "odd\ufffe": 1.5})
    graph.add_node("m", label="plain")
    graph.add_edge("n\uffff", "m", relation="on\x7f")
    document = export_graph(graph, "graphml")
    read = nx.read_graphml(io.BytesIO(document))
    assert sorted(read.nodes) == ["m", "n\ufffd"]
    assert read.nodes["n\ufffd"] == {"label": "a\ufffdb", "odd\ufffd": 1.5}
    assert read.graph["scene_id"] == "s\ufffd"
    assert read.edges["n\ufffd", "m"]["relation"] == "on\ufffd"
