"""The published scene graph, now or at any earlier seq."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Query

from api_schema import Graph
from core.graph import graph_to_dict, pending_verifications, publish
from service.deps import StatesDep

router = APIRouter(prefix="/v1/scenes/{scene_id}", tags=["graph"])

AsOf = Annotated[int | None, Query(ge=0, description="Seq to travel back to (default: the head).")]


@router.get("/graph", response_model=Graph)
def get_graph(
    scene_id: str,
    states: StatesDep,
    as_of: AsOf = None,
    include: Annotated[
        Literal["published", "all"],
        Query(description="`all` adds hypotheses, demoted and removed tracks."),
    ] = "published",
    parent: Annotated[
        str | None, Query(description="Only nodes whose support parent is this track.")
    ] = None,
    label: Annotated[str | None, Query(description="Only nodes of this class.")] = None,
) -> Graph:
    """The graph at `as_of` (default now): confirmed nodes, or every track with include=all."""
    state = states.state(scene_id, as_of)
    graph = publish(state, include_all=include == "all", parent=parent, label=label)
    return Graph.model_validate(
        {
            "scene_id": scene_id,
            "seq": state.head_seq,
            "pending_verifications": pending_verifications(state),
            **graph_to_dict(graph),
        }
    )
