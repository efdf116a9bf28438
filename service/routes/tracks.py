"""Tracks: the projection for queries, one belief at any seq, and explanations."""

from __future__ import annotations

from typing import Annotated

import orjson
from fastapi import APIRouter, Query

from api_schema import Explanation, TrackBelief
from core.state import Track
from service.deps import ContainerDep, StatesDep
from service.errors import NotFound
from service.explain import explain
from service.routes.graph import AsOf
from service.store.projection import query_tracks

router = APIRouter(prefix="/v1/scenes/{scene_id}/tracks", tags=["tracks"])


def belief_out(scene_id: str, seq: int, track: Track) -> TrackBelief:
    """Wire form of one track's belief."""
    embedding = track.embedding()
    return TrackBelief(
        scene_id=scene_id,
        seq=seq,
        track_id=track.track_id,
        kind=track.kind,
        label=track.label,
        state=track.lifecycle,
        p_exist=track.p_exist,
        existence_logodds=track.existence_logodds,
        class_probabilities=track.class_probabilities(),
        class_evidence=dict(track.class_evidence),
        center=list(track.center),
        covariance=track.covariance(),
        extent=list(track.extent),
        recent_centers=[list(c) for c in track.recent_centers],
        parent=track.parent,
        parent_probabilities=track.parent_probabilities(),
        embedding=None if embedding is None else [float(v) for v in embedding],
        embedding_count=track.embedding_count,
        last_observed=track.last_observed,
        last_observed_frame=track.last_observed_frame,
        batches_observed=track.batches_observed,
        visible_misses=track.visible_misses,
        published_center=None if track.published_center is None else list(track.published_center),
    )


@router.get("", response_model=list[TrackBelief])
def list_tracks(
    scene_id: str,
    container: ContainerDep,
    label: Annotated[str | None, Query(description="Only tracks of this class.")] = None,
    state: Annotated[str | None, Query(description="Only tracks in this lifecycle state.")] = None,
    parent: Annotated[
        str | None, Query(description="Only tracks supported by this parent.")
    ] = None,
) -> list[TrackBelief]:
    """Current tracks from the SQL projection, filtered by label, state or parent."""
    container.log.scene(scene_id)
    rows = query_tracks(container.engine, scene_id, label=label, state=state, parent=parent)
    return [
        belief_out(scene_id, row["updated_seq"], Track.from_dict(orjson.loads(row["belief"])))
        for row in rows
    ]


@router.get("/{track_id}", response_model=TrackBelief)
def get_track(scene_id: str, track_id: str, states: StatesDep, as_of: AsOf = None) -> TrackBelief:
    """The full belief of one track at `as_of` (default now)."""
    state = states.state(scene_id, as_of)
    track = state.tracks.get(track_id)
    if track is None:
        raise NotFound("track", track_id)
    return belief_out(scene_id, state.head_seq, track)


@router.get("/{track_id}/explain", response_model=Explanation)
def explain_track(scene_id: str, track_id: str, container: ContainerDep) -> Explanation:
    """Why the track is in its state (for a removal: the visible misses behind it), from the log."""
    container.log.scene(scene_id)
    events = list(container.log.read(scene_id, track_id=track_id))
    if not events:
        raise NotFound("track", track_id)
    return explain(track_id, events)
