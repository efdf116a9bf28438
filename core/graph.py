"""Publish(B, M): the scene graph of equation (1), as networkx and as plain dicts."""

from __future__ import annotations

from typing import Any

import networkx as nx

from core.state import SceneState, Track

PUBLISHED_STATES = frozenset({"confirmed"})


def is_published(track: Track) -> bool:
    """Only confirmed tracks are graph nodes; hypotheses, demoted and removed ones are not."""
    return track.lifecycle in PUBLISHED_STATES


def node_attributes(track: Track) -> dict[str, Any]:
    """The node of one track as the API shows it."""
    return {
        "id": track.track_id,
        "kind": track.kind,
        "label": track.label,
        "state": track.lifecycle,
        "p_exist": track.p_exist,
        "center": list(track.center),
        "extent": list(track.extent),
        "parent": track.parent,
        "class_probabilities": track.class_probabilities(),
        "last_observed": track.last_observed,
        "last_observed_frame": track.last_observed_frame,
        "pinned": track.pinned,
        "verification": track.verification,
        "inspection": track.inspection_status,
    }


def publish(
    state: SceneState,
    *,
    include_all: bool = False,
    parent: str | None = None,
    label: str | None = None,
) -> nx.DiGraph:
    """Graph of the state: nodes are tracks, edges object -on-> support parent."""
    graph = nx.DiGraph(seq=state.head_seq)
    for track_id in sorted(state.tracks):
        track = state.tracks[track_id]
        if not include_all and not is_published(track):
            continue
        if parent is not None and track.parent != parent:
            continue
        if label is not None and track.label != label:
            continue
        graph.add_node(track_id, **node_attributes(track))
    for track_id in list(graph.nodes):
        support = state.tracks[track_id].parent
        if support is not None and support in graph:  # both ends published (and not filtered out)
            graph.add_edge(track_id, support, relation="on")
    return graph


def pending_verifications(state: SceneState) -> list[str]:
    """Tracks waiting for a verdict: the graph says so rather than publishing them."""
    return sorted(
        t.track_id
        for t in state.tracks.values()
        if t.verification == "pending" and t.lifecycle != "removed"
    )


def graph_to_dict(graph: nx.DiGraph) -> dict[str, Any]:
    """Nodes and edges as JSON-able lists in a stable order."""
    return {
        "nodes": [dict(graph.nodes[n]) for n in sorted(graph.nodes)],
        "edges": [
            {"source": s, "target": t, "relation": graph.edges[s, t]["relation"]}
            for s, t in sorted(graph.edges)
        ],
    }
