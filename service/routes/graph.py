"""The published scene graph, now or at any earlier seq."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Query

from api_schema import Graph
from core.graph import graph_to_dict, pending_verifications, publish
from service.deps import AsOf, SceneDep, StatesDep, text_query

router = APIRouter(prefix="/v1/scenes/{scene_id}", tags=["graph"])


@router.get("/graph", response_model=Graph)
def get_graph(
    scene: SceneDep,
    states: StatesDep,
    as_of: AsOf = None,
    include: Annotated[
        Literal["published", "all"],
        Query(description="`all` adds hypotheses, demoted and removed tracks."),
    ] = "published",
    parent: Annotated[
        str | None, text_query("Only nodes whose support parent is this.", 64)
    ] = None,
    label: Annotated[str | None, text_query("Only nodes of this class.", 200)] = None,
) -> Graph:
    """The graph at `as_of` (default now): confirmed nodes, or every track with include=all."""
    state = states.state(scene.id, as_of)
    graph = publish(state, include_all=include == "all", parent=parent, label=label)
    return Graph.model_validate(
        {
            "scene_id": scene.id,
            "seq": state.head_seq,
            "pending_verifications": pending_verifications(state),
            **graph_to_dict(graph),
        }
    )
