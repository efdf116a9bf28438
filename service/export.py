"""The published graph in the formats graph tools read: GraphML and networkx's node-link JSON.

GraphML values are scalars (string, integer, float, boolean), so a node's attributes are
flattened by one rule:

- a value that is None is left out (GraphML has no null: an absent key means "none");
- a three-number vector (`center`, `extent`) becomes one float per axis: `center_x`,
  `center_y`, `center_z`;
- any other list or mapping (`class_probabilities`) becomes its JSON text;
- `id` is left out: it is the node's own id.

The GraphML document is written here, not by networkx, for two guarantees graph tools rely on:
booleans are xs:boolean (`true`/`false`, networkx writes `True`/`False`), and the document is
well-formed XML whatever text the log holds (a label stored before the text rule of
api_schema.text, with U+FFFF say, is exported with U+FFFD in its place).

Node-link JSON keeps every attribute as it is (JSON has null, lists and objects).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from typing import Any, Literal

import networkx as nx
import orjson

from api_schema.text import replace_refused

ExportFormat = Literal["graphml", "json-graph"]
EXPORT_FORMATS: tuple[ExportFormat, ...] = ("graphml", "json-graph")
MEDIA_TYPES: dict[ExportFormat, str] = {
    "graphml": "application/graphml+xml",
    "json-graph": "application/json",
}
_AXES = ("x", "y", "z")
GRAPHML_NS = "http://graphml.graphdrawing.org/xmlns"
_XSI = "http://www.w3.org/2001/XMLSchema-instance"
_SCHEMA_LOCATION = f"{GRAPHML_NS} {GRAPHML_NS}/1.0/graphml.xsd"
Flat = dict[str, str | int | float | bool]
_Keys = dict[tuple[str, str], tuple[str, str]]  # (scope, attribute name) -> (key id, type)


def graphml_attributes(attributes: Mapping[str, Any]) -> Flat:
    """Attributes as GraphML scalars, by the rule of the module docstring."""
    flat: Flat = {}
    for key, value in attributes.items():
        if value is None or key == "id":
            continue
        if isinstance(value, bool | int | float | str):
            flat[key] = value
        elif _is_vector3(value):
            for axis, component in zip(_AXES, value, strict=True):
                flat[f"{key}_{axis}"] = float(component)
        else:
            flat[key] = orjson.dumps(value, option=orjson.OPT_SORT_KEYS).decode()
    return flat


def _is_vector3(value: object) -> bool:
    return (
        isinstance(value, list | tuple)
        and len(value) == 3
        and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
    )


def graphml_document(graph: nx.DiGraph) -> bytes:
    """`graph` as a GraphML document: its attributes flattened (`graphml_attributes`), one
    `key` per attribute name and scope, typed `boolean`, `long`, `double` or `string`, booleans
    written `true`/`false` (xs:boolean), nodes and edges in a stable order. Every string goes
    through `replace_refused`, so text an older version stored with a character XML 1.0 forbids
    (U+FFFE, U+FFFF) still gives a well-formed document."""
    graph_data = graphml_attributes(graph.graph)
    nodes = [(node, graphml_attributes(graph.nodes[node])) for node in sorted(graph.nodes)]
    edges = [(edge, graphml_attributes(graph.edges[edge])) for edge in sorted(graph.edges)]
    root = ET.Element(
        "graphml",
        {"xmlns": GRAPHML_NS, "xmlns:xsi": _XSI, "xsi:schemaLocation": _SCHEMA_LOCATION},
    )
    keys: _Keys = {}
    for scope, records in (
        ("graph", [graph_data]),
        ("node", [data for _node, data in nodes]),
        ("edge", [data for _edge, data in edges]),
    ):
        for name, xml_type in _key_types(records).items():
            keys[scope, name] = f"d{len(keys)}", xml_type
            attributes = {"attr.name": replace_refused(name), "attr.type": xml_type}
            ET.SubElement(root, "key", {"id": keys[scope, name][0], "for": scope, **attributes})
    element = ET.SubElement(root, "graph", {"edgedefault": "directed"})
    _add_data(element, "graph", graph_data, keys)
    for node, data in nodes:
        node_element = ET.SubElement(element, "node", {"id": replace_refused(str(node))})
        _add_data(node_element, "node", data, keys)
    for (source, target), data in edges:
        ends = {"source": replace_refused(str(source)), "target": replace_refused(str(target))}
        _add_data(ET.SubElement(element, "edge", ends), "edge", data, keys)
    ET.indent(root)
    document: bytes = ET.tostring(root, encoding="utf-8", xml_declaration=True)
    return document + b"\n"


def _key_types(records: list[Flat]) -> dict[str, str]:
    """The GraphML type of each attribute name, in order of first appearance: booleans, integers,
    numbers (integers and floats mixed) or, for any other mixture, strings."""
    seen: dict[str, set[type]] = {}
    for record in records:
        for name, value in record.items():
            seen.setdefault(name, set()).add(type(value))
    types = {}
    for name, kinds in seen.items():
        if kinds == {bool}:
            types[name] = "boolean"
        elif kinds == {int}:
            types[name] = "long"
        elif kinds <= {int, float}:
            types[name] = "double"
        else:
            types[name] = "string"
    return types


def _add_data(element: ET.Element, scope: str, data: Flat, keys: _Keys) -> None:
    for name, value in data.items():
        key_id, xml_type = keys[scope, name]
        ET.SubElement(element, "data", {"key": key_id}).text = _lexical(value, xml_type)


def _lexical(value: str | int | float | bool, xml_type: str) -> str:
    """A value in the lexical form of its key's type (xs:boolean, xs:long, xs:double, text)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) or (xml_type == "double" and isinstance(value, int)):
        number = float(value)
        if math.isnan(number):
            return "NaN"
        if math.isinf(number):
            return "INF" if number > 0 else "-INF"
        return repr(number)
    if isinstance(value, int):
        return str(value)
    return replace_refused(value)


def export_graph(graph: nx.DiGraph, format: ExportFormat) -> bytes:
    """The graph as a GraphML document or as node-link JSON, nodes and edges in a stable order."""
    if format == "graphml":
        return graphml_document(graph)
    ordered = nx.DiGraph(**graph.graph)
    ordered.add_nodes_from((node, graph.nodes[node]) for node in sorted(graph.nodes))
    ordered.add_edges_from(
        (source, target, graph.edges[source, target]) for source, target in sorted(graph.edges)
    )
    return orjson.dumps(nx.node_link_data(ordered, edges="edges"))
