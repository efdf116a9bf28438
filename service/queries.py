"""Questions in the robot's terms, answered from one scene state: which objects (by class,
place, support, state and change), which look like an appearance vector, and where one object
was over time (from its own events)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from api_schema import HistorySpan, ObjectOut, SimilarMatch
from core.events import Event, ObjectReidentified, TrackMoved
from core.evolve import track_steps
from core.params import Params
from core.state import SceneState, Track
from core.values import LifecycleState, Vec3
from service.store.event_log import StoredEvent

# Without a `state` filter an answer leaves out retired tracks: hypotheses never published and
# given up, or merged into the track that stands for them.
DEFAULT_STATES: frozenset[str] = frozenset({"tentative", "confirmed", "demoted", "removed"})


@dataclass(frozen=True)
class ObjectQuery:
    """What `GET /objects` filters by (None: no filter)."""

    label: str | None = None
    on: str | None = None  # the parent fixture's track id
    state: LifecycleState | None = None
    near: Vec3 | None = None
    radius: float | None = None  # metres from `near`


def matching_objects(state: SceneState, query: ObjectQuery) -> list[tuple[Track, float | None]]:
    """The scene's object tracks that pass every filter but the change, each with its distance
    from `near`; by distance (then track id) when `near` is given, else by track id."""
    states = DEFAULT_STATES if query.state is None else {query.state}
    found: list[tuple[Track, float | None]] = []
    for track in state.tracks.values():
        if track.kind != "object" or track.lifecycle not in states:
            continue
        if query.label is not None and track.label != query.label:
            continue
        if query.on is not None and track.parent != query.on:
            continue
        distance = None if query.near is None else math.dist(track.center, query.near)
        if distance is not None and query.radius is not None and distance > query.radius:
            continue
        found.append((track, distance))
    if query.near is None:
        found.sort(key=lambda item: item[0].track_id)
    else:
        found.sort(key=lambda item: (item[1], item[0].track_id))
    return found


def object_out(
    state: SceneState, track: Track, changed_seq: int, distance: float | None = None
) -> ObjectOut:
    """One object as the answers give it, its parent fixture named with its class."""
    parent = state.tracks.get(track.parent) if track.parent is not None else None
    return ObjectOut(
        track_id=track.track_id,
        label=track.label,
        class_probabilities=track.class_probabilities(),
        state=track.lifecycle,
        p_exist=track.p_exist,
        center=list(track.center),
        parent=track.parent,
        parent_label=None if parent is None else parent.label,
        last_observed=track.last_observed,
        last_observed_frame=track.last_observed_frame,
        changed_seq=changed_seq,
        distance=distance,
    )


def unit(vector: Sequence[float]) -> np.ndarray:
    """`vector` l2-normalized (scaled by its largest value first: tiny values do not vanish)."""
    array = np.asarray(vector, dtype=np.float64)
    array = array / float(np.abs(array).max())
    result: np.ndarray = array / float(np.linalg.norm(array))
    return result


def appearance_dimension(state: SceneState) -> int | None:
    """The length of the scene's appearance vectors (its object tracks'), None before any."""
    for track in state.tracks.values():
        if track.kind == "object" and track.embedding_sum is not None:
            return len(track.embedding_sum)
    return None


def most_similar(
    state: SceneState, vector: Sequence[float], k: int, label: str | None
) -> list[tuple[Track, float]]:
    """The `k` object tracks (not retired) whose appearance has the largest cosine with
    `vector`, best first (ties by track id); tracks without an appearance are not compared."""
    candidates = [
        track
        for track in state.tracks.values()
        if track.kind == "object"
        and track.lifecycle in DEFAULT_STATES
        and (label is None or track.label == label)
        and track.embedding_sum is not None
        and len(track.embedding_sum) == len(vector)
    ]
    appearances = [track.embedding() for track in candidates]
    pairs = [(t, a) for t, a in zip(candidates, appearances, strict=True) if a is not None]
    if not pairs:
        return []
    matrix = np.stack([appearance for _track, appearance in pairs])
    scores = matrix @ unit(vector)
    ranked = sorted(
        ((track, float(score)) for (track, _a), score in zip(pairs, scores, strict=True)),
        key=lambda item: (-item[1], item[0].track_id),
    )
    return ranked[:k]


def similar_out(state: SceneState, track: Track, score: float, changed_seq: int) -> SimilarMatch:
    """One match: the object and its score."""
    return SimilarMatch(**object_out(state, track, changed_seq).model_dump(), score=score)


def _moved_place(event: Event) -> bool:
    """The event puts the track at another place (a published move, a re-identification)."""
    return isinstance(event, TrackMoved | ObjectReidentified)


def history_spans(params: Params, stored: Iterable[StoredEvent]) -> list[HistorySpan]:
    """A track's events folded one by one into spans: a new span starts when its parent or its
    lifecycle state changes, or when it moved (`move`) or was found elsewhere (re-identified)."""
    spans: list[HistorySpan] = []
    rows = list(stored)
    steps = track_steps(params, (row.to_core() for row in rows))
    for row, (event, track) in zip(rows, steps, strict=True):
        if track is None:
            continue
        last = spans[-1] if spans else None
        if (
            last is None
            or _moved_place(event)
            or last.parent != track.parent
            or last.state != track.lifecycle
        ):
            spans.append(
                HistorySpan(
                    from_seq=row.seq,
                    to_seq=row.seq,
                    from_time=row.batch_time,
                    to_time=row.batch_time,
                    parent=track.parent,
                    center=list(track.center),
                    state=track.lifecycle,
                    last_observed=track.last_observed,
                    events=1,
                )
            )
            continue
        spans[-1] = last.model_copy(
            update={
                "to_seq": row.seq,
                "to_time": row.batch_time if row.batch_time is not None else last.to_time,
                "center": list(track.center),
                "last_observed": track.last_observed,
                "events": last.events + 1,
            }
        )
    return spans
