"""Tracks: the projection for queries, one belief at any seq, and explanations."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query

from api_schema import Explanation, TrackBelief
from core.errors import NotFound
from core.values import LifecycleState
from service.deps import AsOf, ContainerDep, SceneDep, StatesDep, TrackId, text_query
from service.explain import explain
from service.store.projection import query_tracks
from service.wire import belief_out

router = APIRouter(prefix="/v1/scenes/{scene_id}/tracks", tags=["tracks"])


@router.get("", response_model=list[TrackBelief])
def list_tracks(
    scene: SceneDep,
    container: ContainerDep,
    label: Annotated[str | None, text_query("Only tracks of this class.", 200)] = None,
    state: Annotated[
        LifecycleState | None, Query(description="Only tracks in this lifecycle state.")
    ] = None,
    parent: Annotated[str | None, text_query("Only tracks supported by this parent.", 64)] = None,
) -> list[TrackBelief]:
    """Current tracks from the SQL projection, filtered by label, state or parent."""
    rows = query_tracks(container.engine, scene.id, label=label, state=state, parent=parent)
    return [belief_out(scene.id, seq, track) for seq, track in rows]


@router.get("/{track_id}", response_model=TrackBelief)
def get_track(scene: SceneDep, track_id: TrackId, states: StatesDep, as_of: AsOf) -> TrackBelief:
    """The full belief of one track at `as_of` (default now)."""
    state = states.state(scene.id, as_of)
    track = state.tracks.get(track_id)
    if track is None:
        raise NotFound("track", track_id, "track_id")
    return belief_out(scene.id, state.head_seq, track)


@router.get("/{track_id}/explain", response_model=Explanation)
def explain_track(
    scene: SceneDep,
    track_id: TrackId,
    container: ContainerDep,
    events: Annotated[
        bool, Query(description="Also every event of the track (large for a track seen often).")
    ] = False,
) -> Explanation:
    """Why the track is in its state, from the log: one sentence and the visible misses since
    its last sighting (for a removal, those behind it); `events=true` adds its events."""
    stored = container.log.read(scene.id, track_id=track_id)
    if not stored:
        raise NotFound("track", track_id, "track_id")
    return explain(track_id, stored, with_events=events)
