"""evolve: the only way state changes. A fold of events, never a recomputation of perception."""

from __future__ import annotations

import operator
from collections.abc import Iterable
from typing import assert_never

from core.baseline import loaded_track
from core.belief import class_distribution
from core.events import (
    BaselineFrozen,
    BaselineLoaded,
    BatchSkipped,
    Event,
    FixtureAdded,
    FixtureEvidence,
    FixtureObserved,
    InspectionRecorded,
    InspectionTargeted,
    ObjectAdded,
    ObjectObserved,
    ObjectReidentified,
    OccupancyEvidence,
    SceneCreated,
    SceneRenamed,
    TrackConfirmed,
    TrackDemoted,
    TrackMoved,
    TrackRemoved,
    TrackReparented,
    TrackRetired,
    TrackVerified,
    VerificationRequested,
    VisibleMiss,
)
from core.occupancy import GridWork
from core.params import Params
from core.plan_ledger import InspectionLock, PlanLedger
from core.state import BaselineRecord, SceneState, Track, TrackChanges
from core.values import Vec3


def evolve(state: SceneState, event: Event) -> SceneState:
    """State after one event."""
    return fold(state, (event,))


def fold(state: SceneState, events: Iterable[Event]) -> SceneState:
    """reduce(evolve, events, state), with one copy of the track table instead of one per event."""
    tracks = dict(state.tracks)
    params, name = state.params, state.name
    head_seq, next_track_number = state.head_seq, state.next_track_number
    voxels = state.voxels
    baselines, source_baseline = list(state.baselines), state.source_baseline
    occupancy: GridWork | None = None  # copied on first use
    clock, plan = state.clock, state.plan
    touched: set[str] = set()
    for event in events:
        head_seq += 1
        touched.update(event.touched_tracks())
        match event:
            case SceneCreated():
                params = Params.recorded(event.params)
                name = event.name
                source_baseline = None if event.baseline is None else event.baseline.__dict__
            case SceneRenamed():
                name = event.name
            case FixtureEvidence():
                voxels = voxels.with_event(event)
            case OccupancyEvidence():
                if occupancy is None:
                    occupancy = GridWork(state.occupancy)
                occupancy.apply(event.side, event.free, event.occupied, params.occupancy)
                clock = event.timestamp if clock is None else max(clock, event.timestamp)
            case InspectionTargeted():
                lock = InspectionLock(event.track_id, event.view, event.pitch, head_seq)
                plan = PlanLedger(lock, plan.locks + 1, plan.failed_views, plan.failed_at_lock)
            case BaselineFrozen():
                record = BaselineRecord(event.version, head_seq, event.sha256, event.fixture_ids)
                baselines.append(record)
                for fixture_id in event.fixture_ids:
                    tracks[fixture_id] = tracks[fixture_id].evolved(pinned=True)
            case BatchSkipped():
                pass  # the log records the gap; the state is what the other batches made it
            case BaselineLoaded():
                for fixture in event.fixtures:
                    tracks[fixture.track_id] = loaded_track(fixture)
                next_track_number = max(next_track_number, event.next_track_number)
            case ObjectAdded() | FixtureAdded():
                next_track_number += 1
                tracks[event.track_id] = _observe(_new_track(event), event, params)
            case _ if isinstance(event, TrackChange):
                tracks[event.track_id] = _changed(tracks[event.track_id], event, params)
            case InspectionRecorded():
                tracks[event.track_id] = tracks[event.track_id].evolved(
                    inspection_status=event.status, inspection_attempts=event.attempts
                )
                for child in event.children:  # now held by the capture ledger (section 3.3)
                    tracks[child] = tracks[child].evolved(capture_id=event.capture_id)
                touched.update(event.children)
                plan = _after_capture(plan, event)
            case _:
                assert_never(event)
    return SceneState(
        params=params,
        name=name,
        head_seq=head_seq,
        tracks=tracks,
        next_track_number=next_track_number,
        voxels=voxels,
        baselines=tuple(baselines),
        source_baseline=source_baseline,
        occupancy=state.occupancy if occupancy is None else occupancy.frozen(),
        clock=clock,
        plan=plan,
    ).with_arrays_from(state, touched)


# The events that change only their own track, from that track alone.
TrackChange = (
    ObjectObserved
    | FixtureObserved
    | ObjectReidentified
    | VisibleMiss
    | TrackConfirmed
    | TrackMoved
    | TrackReparented
    | TrackDemoted
    | TrackRemoved
    | TrackRetired
    | VerificationRequested
    | TrackVerified
)


def _changed(track: Track, event: TrackChange, params: Params) -> Track:
    """The track after an event that changes it alone."""
    match event:
        case ObjectObserved() | FixtureObserved():
            return _observe(track, event, params)
        case ObjectReidentified():
            return _reidentify(track, event, params)
        case VisibleMiss():
            # A visibility-admissible miss: only existence and the miss count change.
            return track.evolved(
                existence_logodds=event.existence_logodds,
                visible_misses=event.visible_misses,
                lifecycle=event.state,
            )
        case TrackConfirmed():
            published = track.published_center or event.center
            return track.evolved(lifecycle="confirmed", published_center=published)
        case TrackMoved():
            # Moved: what it covered before is no longer where it is.
            return track.evolved(
                published_center=event.to, box=_box([(track.center, track.extent)])
            )
        case TrackReparented():
            return track.evolved(parent=event.new_parent)
        case TrackRemoved():
            return track.evolved(lifecycle=event.state, capture_id=None)
        case TrackDemoted() | TrackRetired():
            return track.evolved(lifecycle=event.state)
        case VerificationRequested():
            return track.evolved(verification="pending")
        case TrackVerified():
            return _apply_verdict(track, event, params)
        case _:
            assert_never(event)


def _after_capture(plan: PlanLedger, event: InspectionRecorded) -> PlanLedger:
    """A capture releases a lock on its fixture; a failed one records its view and the time of
    the failure (in locks) for the retry cooldown."""
    lock = plan.lock
    if lock is not None and lock.fixture_id == event.fixture_id:
        lock = None
    if event.outcome == "completed":
        return PlanLedger(lock, plan.locks, plan.failed_views, plan.failed_at_lock)
    failed_views = dict(plan.failed_views)
    if event.view is not None:
        failed_views[event.fixture_id] = (*failed_views.get(event.fixture_id, ()), event.view)
    failed_at = {**plan.failed_at_lock, event.fixture_id: plan.locks}
    return PlanLedger(lock, plan.locks, failed_views, failed_at)


def _apply_verdict(track: Track, event: TrackVerified, params: Params) -> Track:
    """A cached verification: evidence weight 3 for the verified label, existence from the event."""
    class_evidence = dict(track.class_evidence)
    class_evidence[event.label] = (
        class_evidence.get(event.label, 0.0) + params.fusion.verification_evidence_weight
    )
    return track.evolved(
        class_evidence=class_evidence,
        existence_logodds=event.existence_logodds,
        verification="confirmed" if event.verdict == "confirm" else "rejected",
        verdict_frame=event.verdict_frame,
        lifecycle=event.state,
    )


def _new_track(event: ObjectAdded | FixtureAdded) -> Track:
    first = event.observations[0]
    return Track(
        track_id=event.track_id,
        kind=event.kind,
        lifecycle="tentative",
        class_evidence={},
        existence_logodds=0.0,
        center=first.center,
        extent=first.extent,
        recent_centers=(),
        first_observed=event.timestamp if isinstance(event, ObjectAdded) else None,
    )


def _observe(
    track: Track,
    event: ObjectAdded | FixtureAdded | ObjectObserved | FixtureObserved,
    params: Params,
) -> Track:
    """State fusion of a positive batch: evidence, latest center, recent centers, appearance."""
    observations = event.observations
    weight = params.fusion.observation_evidence_weight
    from_scores = params.fusion.class_evidence_from_scores
    class_evidence = dict(track.class_evidence)
    for observation in observations:
        evidence = class_distribution(observation.label, observation.class_scores, from_scores)
        for label, share in evidence.items():
            class_evidence[label] = class_evidence.get(label, 0.0) + weight * share
    centers = track.recent_centers + tuple(o.center for o in observations)
    last = observations[-1]
    changes: TrackChanges = {
        "lifecycle": event.state,
        "class_evidence": class_evidence,
        "existence_logodds": event.existence_logodds,
        "extent": last.extent,
        "recent_centers": centers[-params.fusion.max_recent_centers :],
        "embedding_sum": _summed(track.embedding_sum, event.embedding_sum),
        "embedding_count": track.embedding_count + event.embedding_count,
        "last_observed": event.timestamp,
        "last_observed_frame": last.frame_id,
        "batches_observed": event.batches_observed,
        "visible_misses": 0,
    }
    if isinstance(event, FixtureAdded | FixtureObserved):
        # Fixtures: the EMA center, the best frame to crop, the class margin (summed since the
        # track was last acquired: a re-acquired fixture earns its consensus anew); no parents.
        restart = isinstance(event, FixtureAdded) or event.reacquired
        changes.update(
            {
                "center": event.center,
                "best_frame": event.best_frame,
                "best_frame_support": event.best_frame_support,
                "margin_sum": (0.0 if restart else track.margin_sum) + event.margin,
                "parent_evidence": dict(track.parent_evidence),
            }
        )
    else:
        changes.update(
            {
                "center": last.center,
                "parent_evidence": dict(event.parent_evidence),
                "box": _observed_box(track, event, params),
            }
        )
        if isinstance(event, ObjectObserved) and event.corroborated is False:
            # An uncorroborated match leaves the misses standing.
            changes["visible_misses"] = track.visible_misses
    return track.evolved(**changes)


def _reidentify(track: Track, event: ObjectReidentified, params: Params) -> Track:
    """The object takes the hypothesis's place and evidence (its own class and appearance
    evidence gain the hypothesis's); its misses at the old place are explained."""
    class_evidence = dict(track.class_evidence)
    for label, weight in event.class_evidence.items():
        class_evidence[label] = class_evidence.get(label, 0.0) + weight
    embedding_sum = _summed(track.embedding_sum, event.embedding_sum)
    return track.evolved(
        lifecycle=event.state,
        center=event.center,
        extent=event.extent,
        box=event.box,
        recent_centers=event.recent_centers[-params.fusion.max_recent_centers :],
        class_evidence=class_evidence,
        embedding_sum=embedding_sum,
        embedding_count=track.embedding_count + event.embedding_count,
        existence_logodds=event.existence_logodds,
        last_observed=event.timestamp,
        last_observed_frame=event.seen_in,
        batches_observed=event.batches_observed,
        visible_misses=0,
        parent_evidence=dict(event.parent_evidence),
        capture_id=None,
    )


def _summed(
    total: tuple[float, ...] | None, added: tuple[float, ...] | None
) -> tuple[float, ...] | None:
    """An appearance sum with another one added (either may be absent)."""
    if added is None:
        return total
    return added if total is None else tuple(map(operator.add, total, added))


def _box(boxes: list[tuple[Vec3, Vec3]]) -> tuple[float, ...]:
    """The union of (center, extent) boxes as (low x, y, z, high x, y, z).

    Per axis, min(c - e / 2) and max(c + e / 2) over the boxes in their order, unrolled (one or
    two boxes per call on the fold's path): `min` of several values keeps the first of equal
    ones, so chaining it pairwise gives the same floats as over the whole sequence.
    """
    c, e = boxes[0]
    x0, y0, z0 = c[0] - e[0] / 2, c[1] - e[1] / 2, c[2] - e[2] / 2
    x1, y1, z1 = c[0] + e[0] / 2, c[1] + e[1] / 2, c[2] + e[2] / 2
    for c, e in boxes[1:]:
        x0, y0, z0 = min(x0, c[0] - e[0] / 2), min(y0, c[1] - e[1] / 2), min(z0, c[2] - e[2] / 2)
        x1, y1, z1 = max(x1, c[0] + e[0] / 2), max(y1, c[1] + e[1] / 2), max(z1, c[2] + e[2] / 2)
    return (x0, y0, z0, x1, y1, z1)


def _observed_box(
    track: Track, event: ObjectAdded | ObjectObserved, params: Params
) -> tuple[float, ...]:
    """The visibility box after a positive batch: grown by it while the object stays put."""
    seen = _box([(o.center, o.extent) for o in event.observations])
    fresh = (
        isinstance(event, ObjectAdded)
        or event.reacquired
        or event.corroborated is False
        or track.box is None
    )
    if fresh or track.box is None:
        return seen
    union = _box([_as_center_extent(track.box), _as_center_extent(seen)])
    if max(union[i + 3] - union[i] for i in range(3)) > params.fusion.max_box_m:
        return seen  # drifted or carried: the latest view is the object
    return union


def _as_center_extent(box: tuple[float, ...]) -> tuple[Vec3, Vec3]:
    center = ((box[0] + box[3]) / 2, (box[1] + box[4]) / 2, (box[2] + box[5]) / 2)
    extent = (box[3] - box[0], box[4] - box[1], box[5] - box[2])
    return center, extent


def track_steps(params: Params, events: Iterable[Event]) -> Iterable[tuple[Event, Track | None]]:
    """One track's own events (its `add` first), each with the track after it: the fold of
    the scene restricted to what changes that track alone (`TrackChange`), so a track's history
    is read from its events without replaying the scene. The track is None until its `add`;
    events that do not change a single track (a capture names its fixture) leave it as it is."""
    track: Track | None = None
    for event in events:
        if isinstance(event, ObjectAdded | FixtureAdded):
            track = _observe(_new_track(event), event, params)
        elif isinstance(event, TrackChange) and track is not None:
            track = _changed(track, event, params)
        yield event, track
