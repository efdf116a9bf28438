"""The published graph in the formats graph tools read: GraphML and networkx's node-link JSON.

GraphML values are scalars (string, integer, float, boolean), so a node's attributes are
flattened by one rule:

- a value that is None is left out (GraphML has no null: an absent key means "none");
- a three-number vector (`center`, `extent`) becomes one float per axis: `center_x`,
  `center_y`, `center_z`;
- any other list or mapping (`class_probabilities`) becomes its JSON text;
- `id` is left out: it is the node's own id.

Node-link JSON keeps every attribute as it is (JSON has null, lists and objects).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal

import networkx as nx
import orjson

ExportFormat = Literal["graphml", "json-graph"]
EXPORT_FORMATS: tuple[ExportFormat, ...] = ("graphml", "json-graph")
MEDIA_TYPES: dict[ExportFormat, str] = {
    "graphml": "application/graphml+xml",
    "json-graph": "application/json",
}
_AXES = ("x", "y", "z")


def graphml_attributes(attributes: Mapping[str, Any]) -> dict[str, str | int | float | bool]:
    """Attributes as GraphML scalars, by the rule of the module docstring."""
    flat: dict[str, str | int | float | bool] = {}
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


def graphml_graph(graph: nx.DiGraph) -> nx.DiGraph:
    """A copy of `graph` whose graph, node and edge attributes are GraphML scalars."""
    flat = nx.DiGraph(**graphml_attributes(graph.graph))
    for node in sorted(graph.nodes):
        flat.add_node(node, **graphml_attributes(graph.nodes[node]))
    for source, target in sorted(graph.edges):
        flat.add_edge(source, target, **graphml_attributes(graph.edges[source, target]))
    return flat


def export_graph(graph: nx.DiGraph, format: ExportFormat) -> bytes:
    """The graph as a GraphML document or as node-link JSON, nodes and edges in a stable order."""
    if format == "graphml":
        return "\n".join(nx.generate_graphml(graphml_graph(graph))).encode() + b"\n"
    ordered = nx.DiGraph(**graph.graph)
    ordered.add_nodes_from((node, graph.nodes[node]) for node in sorted(graph.nodes))
    ordered.add_edges_from(
        (source, target, graph.edges[source, target]) for source, target in sorted(graph.edges)
    )
    return orjson.dumps(nx.node_link_data(ordered, edges="edges"))
