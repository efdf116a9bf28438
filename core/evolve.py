"""evolve: the only way state changes. A fold of events, never a recomputation of perception."""

from __future__ import annotations

import operator
from collections.abc import Iterable, Mapping
from typing import Any

from core.events import (
    BaselineFrozen,
    BaselineLoaded,
    Event,
    FixtureEvidence,
    InspectionRecorded,
    SceneCreated,
    TrackAdded,
    TrackConfirmed,
    TrackDemoted,
    TrackMoved,
    TrackRemoved,
    TrackReparented,
    TrackUpdated,
    TrackVerified,
    VerificationRequested,
)
from core.params import Params
from core.state import BaselineRecord, SceneState, Track, Vec3, VoxelKey


def evolve(state: SceneState, event: Event) -> SceneState:
    """State after one event."""
    return fold(state, (event,))


def fold(state: SceneState, events: Iterable[Event]) -> SceneState:
    """reduce(evolve, events, state), with one copy of the track table instead of one per event."""
    tracks = dict(state.tracks)
    params, name = state.params, state.name
    head_seq, next_track_number = state.head_seq, state.next_track_number
    voxels: dict[VoxelKey, tuple[int, tuple[float, ...]]] | None = None  # copied on first use
    baselines, source_baseline = list(state.baselines), state.source_baseline
    for event in events:
        head_seq += 1
        if isinstance(event, SceneCreated):
            params = Params.from_dict(event.details.get("params"))
            name = str(event.details.get("name", ""))
            source_baseline = event.details.get("baseline")
            continue
        if isinstance(event, FixtureEvidence):
            if voxels is None:
                voxels = dict(state.voxels)
            _add_voxel_evidence(voxels, event)
            continue
        if isinstance(event, BaselineFrozen):
            fixture_ids = tuple(event.details["fixture_ids"])
            baselines.append(
                BaselineRecord(
                    int(event.details["version"]),
                    head_seq,
                    str(event.details["sha256"]),
                    fixture_ids,
                )
            )
            for fixture_id in fixture_ids:
                tracks[fixture_id] = tracks[fixture_id].evolved(pinned=True)
            continue
        if isinstance(event, BaselineLoaded):
            for record in event.details["fixtures"]:
                tracks[record["track_id"]] = Track.from_dict(record)
            next_track_number = max(next_track_number, int(event.details["next_track_number"]))
            continue
        track_id = event.track_id
        if track_id is None:
            raise ValueError(f"{event.type} event without a track id")
        if isinstance(event, TrackAdded):
            next_track_number += 1
            tracks[track_id] = _observe(_new_track(track_id, event), event, params)
            continue
        track = tracks[track_id]
        if isinstance(event, TrackUpdated):
            tracks[track_id] = _apply_update(track, event, params)
        elif isinstance(event, TrackConfirmed):
            published = track.published_center or _vec3(event.details["center"])
            tracks[track_id] = track.evolved(lifecycle="confirmed", published_center=published)
        elif isinstance(event, TrackMoved):
            tracks[track_id] = track.evolved(published_center=_vec3(event.details["to"]))
        elif isinstance(event, TrackReparented):
            tracks[track_id] = track.evolved(parent=event.details.get("new_parent"))
        elif isinstance(event, TrackDemoted | TrackRemoved):
            tracks[track_id] = track.evolved(lifecycle=str(event.state))
        elif isinstance(event, VerificationRequested):
            tracks[track_id] = track.evolved(verification="pending")
        elif isinstance(event, TrackVerified):
            tracks[track_id] = _apply_verdict(track, event, params)
        elif isinstance(event, InspectionRecorded):
            tracks[track_id] = track.evolved(
                inspection_status=event.details.get("status"),
                inspection_attempts=int(event.details["attempts"]),
            )
        else:
            raise ValueError(f"no evolve rule for event type {event.type!r}")
    return SceneState(
        params=params,
        name=name,
        head_seq=head_seq,
        tracks=tracks,
        next_track_number=next_track_number,
        voxels=state.voxels if voxels is None else voxels,
        baselines=tuple(baselines),
        source_baseline=source_baseline,
    )


def _add_voxel_evidence(
    voxels: dict[VoxelKey, tuple[int, tuple[float, ...]]], event: Event
) -> None:
    """Each fixture mask adds one count and its class similarities to every voxel it covers."""
    for detection in event.details["detections"]:
        scores = tuple(detection["class_scores"])
        flat = detection["voxels"]
        for i in range(0, len(flat), 3):
            key = (flat[i], flat[i + 1], flat[i + 2])
            count, totals = voxels.get(key) or (0, (0.0,) * len(scores))
            voxels[key] = (count + 1, tuple(map(operator.add, totals, scores)))


def _apply_verdict(track: Track, event: Event, params: Params) -> Track:
    """A cached verification: evidence weight 3 for the verified label, existence from the event."""
    details = event.details
    class_evidence = dict(track.class_evidence)
    label = details["label"]
    class_evidence[label] = (
        class_evidence.get(label, 0.0) + params.fusion.verification_evidence_weight
    )
    return track.evolved(
        class_evidence=class_evidence,
        existence_logodds=float(details["existence_logodds"]),
        verification="confirmed" if details["verdict"] == "confirm" else "rejected",
        verdict_frame=details.get("frame_id"),
        lifecycle=str(event.state),
    )


def _new_track(track_id: str, event: Event) -> Track:
    first = event.details["observations"][0]
    return Track(
        track_id=track_id,
        kind=str(event.details["kind"]),
        lifecycle="tentative",
        class_evidence={},
        existence_logodds=0.0,
        center=_vec3(first["center"]),
        extent=_vec3(first["extent"]),
        recent_centers=(),
    )


def _apply_update(track: Track, event: Event, params: Params) -> Track:
    if event.details["evidence"] == "observed":
        return _observe(track, event, params)
    # A visibility-admissible miss: only existence and the miss count change.
    return track.evolved(
        existence_logodds=float(event.details["existence_logodds"]),
        visible_misses=int(event.details["visible_misses"]),
        lifecycle=str(event.state),
    )


def _observe(track: Track, event: Event, params: Params) -> Track:
    """State fusion of a positive batch: evidence, latest center, recent centers, appearance."""
    details: Mapping[str, Any] = event.details
    observations = details["observations"]
    weight = params.fusion.observation_evidence_weight
    class_evidence = dict(track.class_evidence)
    parent_evidence = dict(track.parent_evidence)
    for observation in observations:
        class_evidence[observation["label"]] = (
            class_evidence.get(observation["label"], 0.0) + weight
        )
        if observation.get("parent") is not None:
            parent_evidence[observation["parent"]] = (
                parent_evidence.get(observation["parent"], 0.0) + weight
            )
    centers = track.recent_centers + tuple(_vec3(o["center"]) for o in observations)
    embedding_sum = track.embedding_sum
    if details.get("embedding_sum") is not None:
        batch_sum = details["embedding_sum"]
        embedding_sum = (
            tuple(float(v) for v in batch_sum)
            if embedding_sum is None
            else tuple(map(operator.add, embedding_sum, batch_sum))
        )
    last = observations[-1]
    extra: dict[str, Any] = {}
    if "best_frame" in details:
        extra.update(
            best_frame=details["best_frame"], best_frame_support=int(details["best_frame_support"])
        )
    if "parent_evidence" in details:
        parent_evidence = dict(details["parent_evidence"])
    return track.evolved(
        **extra,
        margin_sum=track.margin_sum + float(details.get("margin", 0.0)),
        lifecycle=str(event.state),
        class_evidence=class_evidence,
        parent_evidence=parent_evidence,
        existence_logodds=float(details["existence_logodds"]),
        center=_vec3(details.get("center", last["center"])),
        extent=_vec3(last["extent"]),
        recent_centers=centers[-params.fusion.max_recent_centers :],
        embedding_sum=embedding_sum,
        embedding_count=track.embedding_count + int(details.get("embedding_count", 0)),
        last_observed=float(details["timestamp"]),
        last_observed_frame=str(last["frame_id"]),
        batches_observed=int(details["batches_observed"]),
        visible_misses=0,
    )


def _vec3(values: Any) -> Vec3:
    x, y, z = values
    return (float(x), float(y), float(z))
