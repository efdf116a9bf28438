"""Metrics of a memory over time: event recall within a latency bound, and false absence.

Each comes in a strict reading, the headline of every table, and a lenient one printed beside it.
Event latency starts at the first frame a change could be seen (`sim.observability`), so it
measures the memory, not the camera's route; it is counted in batches (the update step).
Event recall, strict (`event_recall`): a move or transfer counts only when the identity the
object had before it is the one reflected at its new place; lenient (`lenient_event_recall`):
any recalling event of the object's assigned track, a new track's first parent included.
False absence, strict (`false_absence`, identity-conditioned): an acquired object's assigned
track is not published; lenient (`class_false_absence`, identity-agnostic): no published node
of its class within 0.5 m of it, which any node of the class satisfies.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from core.event_envelope import TrackEvent
from core.events import TrackConfirmed, TrackMoved, TrackRemoved, TrackReparented
from evaluation.metrics import (
    matchable,
    present_objects,
    published_objects,
    ratio,
    squared_distance,
)
from evaluation.predictions import FramePrediction, MethodEvent
from sim.truth import FrameTruth, ScheduledEvent, TruthObject, Vec3

# The method event that shows a scheduled change was noticed, per scheduled event type.
RECALLING_EVENT: dict[str, type[TrackEvent]] = {
    "appear": TrackConfirmed,
    "move": TrackMoved,
    "disappear": TrackRemoved,
    "transfer": TrackReparented,
}
PRESENCE_RADIUS_M = 0.5  # the paper's 0.5 m gate: a node this close stands for the object


@dataclass(frozen=True)
class EventOutcome:
    """What became of one scheduled change."""

    event: ScheduledEvent
    observable_frame: int | None  # first frame the change could be seen, None: never
    recalled_frame: int | None  # first frame the method reflected it, at any latency
    latency_batches: int | None  # batches from the observable batch to the recalling one
    within_bound: bool  # recalled within the latency bound

    @property
    def recalled(self) -> bool:
        """Reflected at all (the unbounded count)."""
        return self.recalled_frame is not None


@dataclass(frozen=True)
class EventRecall:
    """How many scheduled changes the method reflected within the bound, and how fast."""

    recalled: int  # within the latency bound
    total: int  # every scheduled change, observable or not
    recalled_any: int  # at any latency before the run ends
    unobservable: int  # changes no camera view ever showed
    per_event: list[EventOutcome]
    latency_bound_batches: int | None


@dataclass(frozen=True)
class FalseAbsence:
    """How often a present, already acquired object is missing from the published graph."""

    rate: float
    absent: int
    eligible: int
    by_object: dict[str, int] = field(default_factory=dict)  # absent checkpoints per object


def batch_of(frame: int, frames_per_batch: int) -> int:
    """Index of the batch holding a frame (batches are consecutive runs of frames from 0)."""
    return frame // frames_per_batch


def event_recall(
    scheduled: Sequence[ScheduledEvent],
    method_events: Sequence[MethodEvent],
    assignment: Mapping[str, str],
    fixture_map: Mapping[str, str],
    truth: Sequence[FrameTruth],
    predictions: Sequence[FramePrediction],
    observable_frames: Sequence[int | None] | None = None,
    frames_per_batch: int = 2,
    latency_bound_batches: int | None = None,
) -> EventRecall:
    """The strict reading: a move or transfer counts only when the object's identity before it
    is the one reflected at its new place.

    The identity before a change is the object's assigned track when that track stood for the
    object (published, with its label, within 0.5 m: the assignment's own gate) at the last
    frame before the change at which any published node did; an object the memory did not hold
    just before, or held through another track, has no identity to carry over, and its move or
    transfer is never reflected. The change is reflected at the first frame f at or after that
    track's recalling event (move: TrackMoved; transfer: TrackReparented to
    fixture_map[event.parent] from a parent it had, so a track's first parent is not a
    transfer) at which the track is published within 0.5 m of the object where it now is.
    appear and disappear read as in `lenient_event_recall`: an appearance has no identity
    before it, and a disappeared object's assigned track can only have stood for it before.
    Latency, the bound and the counts are as there.
    """
    _check_aligned(truth, predictions)
    index = _TruthIndex(truth)
    frames = [
        _lenient_frame(event, method_events, assignment, fixture_map, len(truth))
        if event.type in ("appear", "disappear")
        else _identity_frame(event, method_events, assignment, fixture_map, index, predictions)
        for event in _known(scheduled)
    ]
    return _tally(scheduled, frames, observable_frames, frames_per_batch, latency_bound_batches)


def lenient_event_recall(
    scheduled: Sequence[ScheduledEvent],
    method_events: Sequence[MethodEvent],
    assignment: Mapping[str, str],
    fixture_map: Mapping[str, str],
    n_frames: int,
    observable_frames: Sequence[int | None] | None = None,
    frames_per_batch: int = 2,
    latency_bound_batches: int | None = None,
) -> EventRecall:
    """The lenient reading: scheduled changes answered by the right event of the object's track.

    A change is reflected at the first frame f, event.frame <= f < n_frames, at which the
    object's assigned track emits: appear -> TrackConfirmed; move -> TrackMoved; disappear ->
    TrackRemoved; transfer -> TrackReparented with a new parent equal to
    fixture_map[event.parent]. An
    object without an assigned track, or a transfer to an unmatched fixture, is never reflected.
    Lenient because the assigned track is the one of the whole run: a track first created at
    the new place, and its first parent event (from no parent), count as the move or transfer.
    Its latency is batch(f) - batch(observable frame), floored at 0 (a memory may act on less
    evidence than the observability test asks for); without an observable frame it counts from
    the scheduled frame. It is recalled when reflected with latency <= the bound (no bound:
    whenever reflected). `total` counts every scheduled change, so an unobservable one is a
    miss for every method, and the trace says why.
    """
    frames = [
        _lenient_frame(event, method_events, assignment, fixture_map, n_frames)
        for event in _known(scheduled)
    ]
    return _tally(scheduled, frames, observable_frames, frames_per_batch, latency_bound_batches)


def _known(scheduled: Sequence[ScheduledEvent]) -> Sequence[ScheduledEvent]:
    for event in scheduled:
        if event.type not in RECALLING_EVENT:
            raise ValueError(f"unknown scheduled event type {event.type!r}")
    return scheduled


def _recalling(
    event: ScheduledEvent,
    method_events: Sequence[MethodEvent],
    track_id: str,
    wanted_parent: str | None,
    n_frames: int,
) -> list[MethodEvent]:
    """The track's events of the kind that answers the change, from its frame on."""
    return [
        method_event
        for method_event in method_events
        if issubclass(method_event.kind, RECALLING_EVENT[event.type])
        and method_event.track_id == track_id
        and event.frame <= method_event.frame < n_frames
        and (event.type != "transfer" or method_event.new_parent == wanted_parent)
    ]


def _lenient_frame(
    event: ScheduledEvent,
    method_events: Sequence[MethodEvent],
    assignment: Mapping[str, str],
    fixture_map: Mapping[str, str],
    n_frames: int,
) -> int | None:
    track_id = assignment.get(event.object_id)
    wanted_parent = fixture_map.get(event.parent) if event.parent is not None else None
    if track_id is None or (event.type == "transfer" and wanted_parent is None):
        return None
    answers = _recalling(event, method_events, track_id, wanted_parent, n_frames)
    return min((answer.frame for answer in answers), default=None)


class _TruthIndex:
    """The present objects of every frame by id."""

    def __init__(self, truth: Sequence[FrameTruth]) -> None:
        self.frames = [
            {truth_object.object_id: truth_object for truth_object in present_objects(frame)}
            for frame in truth
        ]

    def at(self, frame: int, object_id: str) -> TruthObject | None:
        return self.frames[frame].get(object_id)


def _standing_for(truth_object: TruthObject, prediction: FramePrediction) -> set[str]:
    """Tracks published at this frame that stand for the object (label, within 0.5 m)."""
    return {
        node.track_id
        for node in published_objects(prediction)
        if matchable(truth_object, node, class_aware=True)
        and squared_distance(node.center, truth_object.center) <= PRESENCE_RADIUS_M**2
    }


def identity_before(
    event: ScheduledEvent,
    assignment: Mapping[str, str],
    truth: Sequence[FrameTruth],
    predictions: Sequence[FramePrediction],
) -> str | None:
    """The object's assigned track if it stood for the object just before the change: at the
    last earlier frame where any published node did (None: no such frame, or another track)."""
    return _identity_before(event, assignment, _TruthIndex(truth), predictions)


def _identity_before(
    event: ScheduledEvent,
    assignment: Mapping[str, str],
    index: _TruthIndex,
    predictions: Sequence[FramePrediction],
) -> str | None:
    track_id = assignment.get(event.object_id)
    for frame in range(min(event.frame, len(predictions)) - 1, -1, -1):
        truth_object = index.at(frame, event.object_id)
        standing = (
            set() if truth_object is None else _standing_for(truth_object, predictions[frame])
        )
        if standing:
            return track_id if track_id in standing else None
    return None


def _identity_frame(
    event: ScheduledEvent,
    method_events: Sequence[MethodEvent],
    assignment: Mapping[str, str],
    fixture_map: Mapping[str, str],
    index: _TruthIndex,
    predictions: Sequence[FramePrediction],
) -> int | None:
    """First frame the identity before a move or transfer stands at the new place, from its
    recalling event on."""
    track_id = _identity_before(event, assignment, index, predictions)
    wanted_parent = fixture_map.get(event.parent) if event.parent is not None else None
    if track_id is None or (event.type == "transfer" and wanted_parent is None):
        return None
    answers = [
        answer
        for answer in _recalling(event, method_events, track_id, wanted_parent, len(predictions))
        if event.type != "transfer" or answer.old_parent is not None
    ]
    first = min((answer.frame for answer in answers), default=None)
    if first is None:
        return None
    for frame in range(first, len(predictions)):
        truth_object = index.at(frame, event.object_id)
        if truth_object is not None and track_id in _standing_for(truth_object, predictions[frame]):
            return frame
    return None


def _tally(
    scheduled: Sequence[ScheduledEvent],
    recalled_frames: Sequence[int | None],
    observable_frames: Sequence[int | None] | None,
    frames_per_batch: int,
    latency_bound_batches: int | None,
) -> EventRecall:
    """Latency and the counts, from the frame each change was reflected at (None: never)."""
    observable = list(observable_frames or [event.frame for event in scheduled])
    outcomes: list[EventOutcome] = []
    for event, seen_at, recalled_frame in zip(scheduled, observable, recalled_frames, strict=True):
        latency = None
        if recalled_frame is not None:
            start = event.frame if seen_at is None else seen_at
            latency = max(
                0, batch_of(recalled_frame, frames_per_batch) - batch_of(start, frames_per_batch)
            )
        within = latency is not None and (
            latency_bound_batches is None or latency <= latency_bound_batches
        )
        outcomes.append(EventOutcome(event, seen_at, recalled_frame, latency, within))
    return EventRecall(
        recalled=sum(outcome.within_bound for outcome in outcomes),
        total=len(outcomes),
        recalled_any=sum(outcome.recalled for outcome in outcomes),
        unobservable=sum(outcome.observable_frame is None for outcome in outcomes),
        per_event=outcomes,
        latency_bound_batches=latency_bound_batches,
    )


def _check_aligned(truth: Sequence[FrameTruth], predictions: Sequence[FramePrediction]) -> None:
    if len(truth) != len(predictions):
        raise ValueError(f"{len(truth)} truth frames but {len(predictions)} prediction frames")


def false_absence(
    truth: Sequence[FrameTruth],
    predictions: Sequence[FramePrediction],
    assignment: Mapping[str, str],
) -> FalseAbsence:
    """Identity-conditioned (the strict reading): share of post-acquisition checkpoints whose
    assigned track is unpublished.

    A checkpoint (object, frame) is eligible when the object is present at that frame, has an
    assigned track, and that track was published at some strictly earlier frame. absent counts
    eligible checkpoints where the track is not published; rate = absent / eligible (0.0 when
    nothing is eligible).
    """
    _check_aligned(truth, predictions)
    acquired_tracks: set[str] = set()
    absent = eligible = 0
    by_object: Counter[str] = Counter()
    for frame_truth, frame_prediction in zip(truth, predictions, strict=True):
        published = {node.track_id for node in published_objects(frame_prediction)}
        for truth_object in present_objects(frame_truth):
            track_id = assignment.get(truth_object.object_id)
            if track_id in acquired_tracks:
                eligible += 1
                if track_id not in published:
                    absent += 1
                    by_object[truth_object.object_id] += 1
        # Updated after the checks: acquisition counts only from the NEXT frame on.
        acquired_tracks |= published & set(assignment.values())
    return FalseAbsence(ratio(absent, eligible), absent, eligible, dict(by_object))


def class_false_absence(
    truth: Sequence[FrameTruth],
    predictions: Sequence[FramePrediction],
    max_distance: float = PRESENCE_RADIUS_M,
) -> FalseAbsence:
    """Identity-agnostic (the lenient reading): share of post-acquisition checkpoints with no
    node of the class nearby.

    An object is covered at a frame when some published object node has its label and a center
    at most `max_distance` from its center. A checkpoint (object, frame) is eligible when the
    object is present and was covered at some strictly earlier frame since it last changed
    place (the memory had acquired it where it stands); it is absent when the object is not
    covered. rate = absent / eligible (0.0 when nothing is eligible).

    Acquisition restarts when an object is moved: until the memory has found it at its new
    place, that it does not hold it there is the latency of the move (event recall), not the
    loss of something it had. This is the paper's measure: a memory that never removes anything
    (Append-only) has no false absence by construction (Table 2, dagger).
    """
    _check_aligned(truth, predictions)
    max_squared = max_distance**2
    acquired: set[str] = set()
    place: dict[str, Vec3] = {}
    absent = eligible = 0
    by_object: Counter[str] = Counter()
    for frame_truth, frame_prediction in zip(truth, predictions, strict=True):
        nodes = published_objects(frame_prediction)
        covered_now = set()
        for truth_object in present_objects(frame_truth):
            before = place.get(truth_object.object_id)
            if before is not None and squared_distance(before, truth_object.center) > 0.0:
                acquired.discard(truth_object.object_id)  # moved: acquired anew where it is
            place[truth_object.object_id] = truth_object.center
            covered = any(
                matchable(truth_object, node, class_aware=True)
                and squared_distance(node.center, truth_object.center) <= max_squared
                for node in nodes
            )
            if covered:
                covered_now.add(truth_object.object_id)
            if truth_object.object_id in acquired:
                eligible += 1
                if not covered:
                    absent += 1
                    by_object[truth_object.object_id] += 1
        acquired |= covered_now
    return FalseAbsence(ratio(absent, eligible), absent, eligible, dict(by_object))


def latency_summary(latencies: Sequence[int]) -> tuple[float, int] | None:
    """Median and maximum of recalled events' latencies in batches (None when there are none)."""
    if not latencies:
        return None
    ordered = sorted(latencies)
    middle = len(ordered) // 2
    median = (
        float(ordered[middle])
        if len(ordered) % 2
        else (ordered[middle - 1] + ordered[middle]) / 2.0
    )
    return median, ordered[-1]
