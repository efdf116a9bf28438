"""Questions in the robot's terms: where is the mug, what is on the counter, what changed since,
what is near a point, what looks like this, and where was that object over time."""

from __future__ import annotations

import math
from datetime import datetime
from typing import Annotated

from fastapi import APIRouter, Query

from api_schema import ObjectPage, SimilarIn, SimilarOut, TrackHistory
from core.errors import NotFound
from core.state import SceneState, Track
from core.values import LifecycleState, Vec3
from service.deps import (
    MAX_INT,
    AsOf,
    ContainerDep,
    SceneDep,
    StatesDep,
    TimeQuery,
    TrackId,
    invalid_input,
    seconds,
    text_query,
)
from service.queries import (
    ObjectQuery,
    appearance_dimension,
    history_spans,
    matching_objects,
    most_similar,
    object_out,
    similar_out,
)

router = APIRouter(prefix="/v1/scenes/{scene_id}", tags=["objects"])

# Metres: the question's point within the plan's bounds, its radius within a house.
MAX_COORDINATE = 200.0
MAX_RADIUS = 100.0
# One coordinate in -200..200 m, as decimals: the pattern states the bound in the schema.
_COORDINATE = r"[+-]?(?:200(?:\.0+)?|1[0-9]{2}(?:\.[0-9]+)?|[0-9]{1,2}(?:\.[0-9]+)?)"
POINT = rf"^{_COORDINATE},{_COORDINATE},{_COORDINATE}$"


def parse_point(text: str) -> Vec3:
    """`x,y,z` in metres, finite and within +-200 m; a 422 naming `near` otherwise."""
    parts = text.split(",")
    if len(parts) != 3:
        raise invalid_input("near", "three numbers x,y,z (metres) separated by commas")
    try:
        x, y, z = (float(part) for part in parts)
    except ValueError:
        raise invalid_input("near", "three numbers x,y,z (metres) separated by commas") from None
    if not all(math.isfinite(v) and abs(v) <= MAX_COORDINATE for v in (x, y, z)):
        raise invalid_input("near", f"each coordinate finite and within +-{MAX_COORDINATE:g} m")
    return (x, y, z)


def _changed_since(
    container: ContainerDep, scene_id: str, seq: int | None, time: float | datetime | None
) -> int | None:
    """The seq to compare changes with: `changed_since`, or the last seq a batch appended at or
    before `changed_since_time` (-1 before the first: every object changed since)."""
    if time is None:
        return seq
    if seq is not None:
        raise invalid_input("changed_since_time", "give changed_since or changed_since_time")
    at = container.log.seq_at_time(scene_id, seconds(time))
    return -1 if at is None else at


@router.get("/objects", response_model=ObjectPage)
def list_objects(
    scene: SceneDep,
    states: StatesDep,
    container: ContainerDep,
    as_of: AsOf,
    label: Annotated[str | None, text_query("Only objects of this class.", 200)] = None,
    near: Annotated[
        str | None,
        Query(
            max_length=100,
            pattern=POINT,
            description="A point `x,y,z` in metres (each within +-200): answers by distance.",
        ),
    ] = None,
    radius: Annotated[
        float | None,
        Query(gt=0, le=MAX_RADIUS, allow_inf_nan=False, description="Metres from `near`."),
    ] = None,
    on: Annotated[str | None, text_query("Only objects resting on this fixture.", 64)] = None,
    changed_since: Annotated[
        int | None, Query(ge=0, le=MAX_INT, description="Only objects changed after this seq.")
    ] = None,
    changed_since_time: TimeQuery = None,
    state: Annotated[
        LifecycleState | None,
        Query(description="Only objects in this state (default: every state but retired)."),
    ] = None,
    limit: Annotated[int, Query(ge=1, le=1000, description="Page size.")] = 100,
    after: Annotated[
        str | None, text_query("The previous page's `next_after` (a track id).", 64)
    ] = None,
) -> ObjectPage:
    """The scene's objects (never fixtures) at `as_of` (default now) that match every filter,
    by distance from `near` when given, else by track id; one page."""
    if radius is not None and near is None:
        raise invalid_input("radius", "a radius needs a point: give near=x,y,z")
    since = _changed_since(container, scene.id, changed_since, changed_since_time)
    point = None if near is None else parse_point(near)
    snapshot = states.state(scene.id, as_of)
    query = ObjectQuery(label=label, on=on, state=state, near=point, radius=radius)
    found = matching_objects(snapshot, query)
    if after is not None:
        found = _after(snapshot, found, after, point)
    ids = [track.track_id for track, _distance in (found if since is not None else found[:limit])]
    changes = container.log.last_changes(scene.id, ids, snapshot.head_seq)
    if since is not None:
        found = [item for item in found if changes.get(item[0].track_id, 0) > since]
    page = found[:limit]
    objects = [
        object_out(snapshot, track, changes.get(track.track_id, 0), distance)
        for track, distance in page
    ]
    more = len(found) > limit
    return ObjectPage(
        scene_id=scene.id,
        seq=snapshot.head_seq,
        objects=objects,
        next_after=page[-1][0].track_id if more else None,
    )


def _after(
    snapshot: SceneState,
    found: list[tuple[Track, float | None]],
    after: str,
    point: Vec3 | None,
) -> list[tuple[Track, float | None]]:
    """The answers that sort after the track `after` (by distance and id, or by id)."""
    cursor = snapshot.tracks.get(after)
    if cursor is None:
        raise NotFound("track", after, "after")
    if point is None:
        return [item for item in found if item[0].track_id > after]
    key = (math.dist(cursor.center, point), after)
    return [item for item in found if (item[1] or 0.0, item[0].track_id) > key]


@router.post("/objects/similar", response_model=SimilarOut)
def similar_objects(
    scene: SceneDep, body: SimilarIn, states: StatesDep, container: ContainerDep, as_of: AsOf
) -> SimilarOut:
    """The `k` objects whose appearance (count-averaged, l2-normalized) has the largest cosine
    with `embedding`, best first, at `as_of` (default now)."""
    snapshot = states.state(scene.id, as_of)
    dimension = appearance_dimension(snapshot)
    if dimension is not None and dimension != len(body.embedding):
        raise invalid_input(
            "embedding", f"has {len(body.embedding)} values; the scene's are {dimension}", "body"
        )
    ranked = most_similar(snapshot, body.embedding, body.k, body.label)
    changes = container.log.last_changes(
        scene.id, [track.track_id for track, _score in ranked], snapshot.head_seq
    )
    matches = [
        similar_out(snapshot, track, score, changes.get(track.track_id, 0))
        for track, score in ranked
    ]
    return SimilarOut(scene_id=scene.id, seq=snapshot.head_seq, matches=matches)


@router.get("/tracks/{track_id}/history", response_model=TrackHistory)
def track_history(
    scene: SceneDep,
    track_id: TrackId,
    states: StatesDep,
    container: ContainerDep,
    as_of: AsOf,
    after: Annotated[
        int, Query(ge=-1, le=MAX_INT, description="Spans that start after this seq.")
    ] = -1,
    limit: Annotated[int, Query(ge=1, le=1000, description="Spans per page.")] = 100,
) -> TrackHistory:
    """Where the track was and on what, over time, from its events up to `as_of` (default
    now): spans of one place, one parent and one state, in seq order."""
    snapshot = states.state(scene.id, as_of)
    stored = container.log.read(scene.id, track_id=track_id, up_to=snapshot.head_seq)
    if not stored:
        raise NotFound("track", track_id, "track_id")
    spans = [span for span in history_spans(snapshot.params, stored) if span.from_seq > after]
    page = spans[:limit]
    return TrackHistory(
        scene_id=scene.id,
        track_id=track_id,
        seq=snapshot.head_seq,
        spans=page,
        next_after=page[-1].from_seq if len(spans) > limit else None,
    )
