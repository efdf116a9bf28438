"""The published scene graph, now or at any earlier seq, as JSON or exported (GraphML,
node-link JSON)."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Query
from starlette.responses import Response

from api_schema import Graph, NodeLinkGraph
from core.graph import graph_to_dict, pending_verifications, publish
from service.deps import AsOf, SceneDep, StatesDep, text_query
from service.export import MEDIA_TYPES, ExportFormat, export_graph

router = APIRouter(prefix="/v1/scenes/{scene_id}", tags=["graph"])


@router.get(
    "/graph",
    response_model=Graph | NodeLinkGraph,
    responses={
        200: {
            "description": "The graph: this service's JSON (default), node-link JSON "
            "(`format=json-graph`) or GraphML (`format=graphml`).",
            "content": {MEDIA_TYPES["graphml"]: {"schema": {"type": "string"}}},
        }
    },
)
def get_graph(
    scene: SceneDep,
    states: StatesDep,
    as_of: AsOf,
    include: Annotated[
        Literal["published", "all"],
        Query(description="`all` adds hypotheses, demoted and removed tracks."),
    ] = "published",
    parent: Annotated[
        str | None, text_query("Only nodes whose support parent is this.", 64)
    ] = None,
    label: Annotated[str | None, text_query("Only nodes of this class.", 200)] = None,
    format: Annotated[
        ExportFormat | None,
        Query(
            description="`graphml` (application/graphml+xml) or `json-graph` (networkx "
            "node-link JSON); default: this service's JSON."
        ),
    ] = None,
) -> Graph | Response:
    """The graph at `as_of` (default now): confirmed nodes, or every track with include=all."""
    state = states.state(scene.id, as_of)
    graph = publish(state, include_all=include == "all", parent=parent, label=label)
    if format is not None:
        graph.graph["scene_id"] = scene.id
        return Response(export_graph(graph, format), media_type=MEDIA_TYPES[format])
    return Graph.model_validate(
        {
            "scene_id": scene.id,
            "seq": state.head_seq,
            "pending_verifications": pending_verifications(state),
            **graph_to_dict(graph),
        }
    )
