"""Typed audit events: one frozen dataclass per event (section 3.3, "Lifecycle transitions").

Events are the schema of the log. Each class declares its payload fields in the order the log
stores them, and carries what `evolve` needs, so folding the log never recomputes perception.
Events hold values only (core/values.py), never the in-memory records they fold into.

Each class has a `topic`, the one name its rows are stored under, and a `type` from the paper's
audit vocabulary, which several classes may share (`ObjectAdded` and `FixtureAdded` are both an
`add`). `Event`, at the end, is the closed union of the classes: a new event class is added
there and nowhere else (core/event_records.py reads the topics from it; `fold` does not type
check until it has a case for it). The stored form is in core/event_records.py. The active
half's events (section 3.4) are declared in core/active_events.py and imported here.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar, Literal

from pydantic import Field

# Re-exported: every event class is importable from here, where the union names them.
from core.active_events import InspectionRecorded as InspectionRecorded
from core.active_events import InspectionTargeted as InspectionTargeted
from core.active_events import TrackVerified as TrackVerified
from core.active_events import VerificationRequested as VerificationRequested
from core.event_envelope import BaseEvent, TrackEvent
from core.values import (
    BaselineFixture,
    BaselineSource,
    Observation,
    Omitted,
    Vec3,
    VoxelDetection,
)

# -- scene events ------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class SceneCreated(BaseEvent):
    """First event of every scene: its name and the parameters its events are decided with."""

    topic: ClassVar[str] = "scene_created"
    type: ClassVar[str] = "scene_created"
    name: str
    params: Mapping[str, Any]  # Params.to_dict(); folded with Params.from_dict
    baseline: Annotated[BaselineSource | None, Omitted] = None


@dataclass(frozen=True, kw_only=True)
class SceneRenamed(BaseEvent):
    """The scene's name from here on (`PATCH /v1/scenes/{id}`); its parameters stay as recorded."""

    topic: ClassVar[str] = "scene_renamed"
    type: ClassVar[str] = "scene_renamed"
    name: str


@dataclass(frozen=True, kw_only=True)
class FixtureEvidence(BaseEvent):
    """Class evidence of the batch's fixture masks, added to the scene's voxel map."""

    topic: ClassVar[str] = "fixture_evidence"
    type: ClassVar[str] = "fixture_evidence"
    detections: tuple[VoxelDetection, ...]


@dataclass(frozen=True, kw_only=True)
class OccupancyEvidence(BaseEvent):
    """What the batch's depth says of the occupancy map A_t (section 3.2): the cells its rays
    crossed (free) and the cells its points in the robot's height band fell in (occupied).

    Cells are flat indices `row * side + col` of the scene's grid (core/occupancy.py), sorted
    and stored as runs: gap from the previous run's end, run length, gap, length, ...
    """

    topic: ClassVar[str] = "occupancy_evidence"
    type: ClassVar[str] = "occupancy_evidence"
    resolution_m: float
    side: int  # cells per side of the grid
    free: tuple[int, ...]
    occupied: tuple[int, ...]
    timestamp: float  # the batch's newest frame: the scene clock


@dataclass(frozen=True, kw_only=True)
class BaselineFrozen(BaseEvent):
    """The confirmed fixtures frozen as an immutable, versioned package; they become pinned."""

    topic: ClassVar[str] = "baseline_frozen"
    type: ClassVar[str] = "baseline_frozen"
    version: int
    sha256: str
    fixture_ids: tuple[str, ...]

    def touched_tracks(self) -> tuple[str, ...]:
        """The fixtures it pins."""
        return self.fixture_ids


@dataclass(frozen=True, kw_only=True)
class BaselineLoaded(BaseEvent):
    """A new session starts from a frozen baseline: its fixtures keep their identities."""

    # Version 2: the fixtures as baseline records. Version 1 ("baseline_loaded") stored each
    # as the whole in-memory track record (core/upcasters.py reads it).
    topic: ClassVar[str] = "baseline_loaded_v2"
    type: ClassVar[str] = "baseline_loaded"
    source: BaselineSource
    fixtures: tuple[BaselineFixture, ...]
    next_track_number: int

    def touched_tracks(self) -> tuple[str, ...]:
        """The fixtures it loads."""
        return tuple(fixture.track_id for fixture in self.fixtures)


@dataclass(frozen=True, kw_only=True)
class BatchSkipped(BaseEvent):
    """A batch that can never be applied was parked as dead; the scene moved on without it.

    The memory lacks what that batch saw, and the log says so: an operator may requeue the
    batch, which then applies after the batches that came in the meantime.
    """

    topic: ClassVar[str] = "batch_skipped"
    type: ClassVar[str] = "batch_skipped"
    batch_id: str
    attempts: int
    reason: str


# -- a track appears ---------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class TrackAdded(TrackEvent):
    """A new internal hypothesis (`add`), with the batch's observations of it."""

    type: ClassVar[str] = "add"


@dataclass(frozen=True, kw_only=True)
class ObjectAdded(TrackAdded):
    """A new object hypothesis: the prior plus one positive observation (equation (3))."""

    topic: ClassVar[str] = "object_added"
    evidence: Literal["observed"] = "observed"
    observations: tuple[Observation, ...]
    embedding_sum: tuple[float, ...] | None  # appearance of this batch, summed
    embedding_count: int
    timestamp: float
    kind: Literal["object"] = "object"
    existence_logodds: float
    p_exist: float
    batches_observed: int
    parent_evidence: Mapping[str, float]


@dataclass(frozen=True, kw_only=True)
class FixtureAdded(TrackAdded):
    """A new coarse fixture hypothesis from a voxel cluster no fixture track explains."""

    topic: ClassVar[str] = "fixture_added"
    evidence: Literal["observed"] = "observed"
    observations: tuple[Observation, ...]
    center: Vec3
    margin: float  # mean top-vs-second class margin over the cluster
    best_frame: str | None  # the frame to crop for a verifier
    best_frame_support: int
    embedding_sum: None = None
    embedding_count: int = 0
    kind: Literal["fixture"] = "fixture"
    existence_logodds: float
    p_exist: float
    batches_observed: int
    timestamp: float


# -- one existence update per track per batch (`update`) ---------------------------------------


@dataclass(frozen=True, kw_only=True)
class TrackUpdated(TrackEvent):
    """One existence update of a batch (equation (3)): an observation or a visible miss."""

    type: ClassVar[str] = "update"


@dataclass(frozen=True, kw_only=True)
class TrackObserved(TrackUpdated):
    """A positive batch for an existing track."""


@dataclass(frozen=True, kw_only=True)
class ObjectObserved(TrackObserved):
    """State fusion of a positive batch for an object: latest center, evidence, appearance."""

    topic: ClassVar[str] = "object_observed"
    evidence: Literal["observed"] = "observed"
    observations: tuple[Observation, ...]
    embedding_sum: tuple[float, ...] | None
    embedding_count: int
    timestamp: float
    existence_logodds: float
    p_exist: float
    batches_observed: int
    reacquired: bool  # a removed track recovered its identity and restarts as a hypothesis
    parent_evidence: Mapping[str, float]  # after this batch (reset when the object relocated)
    # False: matched inside the gate but neither at the track's place nor confirmed by
    # appearance. The center follows it; existence and the miss count do not change (older
    # logs: every match corroborates).
    corroborated: Annotated[bool | None, Omitted] = None


@dataclass(frozen=True, kw_only=True)
class FixtureObserved(TrackObserved):
    """Support for a fixture from one more batch; its center is the EMA (alpha 0.35)."""

    topic: ClassVar[str] = "fixture_observed"
    evidence: Literal["observed"] = "observed"
    observations: tuple[Observation, ...]
    center: Vec3
    margin: float
    best_frame: str | None
    best_frame_support: int
    embedding_sum: None = None
    embedding_count: int = 0
    existence_logodds: float
    p_exist: float
    batches_observed: int
    reacquired: bool
    timestamp: float


@dataclass(frozen=True, kw_only=True)
class ObjectReidentified(TrackObserved):
    """A track seen elsewhere since this object was last seen is this object.

    The unique-class fallback, deferred (section 3.3): a carried object seen at its new place
    before its old place was seen empty starts a hypothesis, its absence not yet established,
    which may be published there before the old place is seen again (the hand-over,
    `reidentify_published`). Once the absence is established, and appearance singles the pair
    out, the object takes the hypothesis's place,
    box, class and appearance evidence and support evidence, and one positive update per batch
    the hypothesis was seen in (equation (3)); the hypothesis retires, merged into it.
    """

    topic: ClassVar[str] = "object_reidentified"
    evidence: Literal["reidentified"] = "reidentified"
    hypothesis: str  # the track id of the hypothesis
    appearance_cosine: float
    seen_in: str | None  # the hypothesis's last observation (frame id)
    timestamp: float  # ... and its time
    center: Vec3
    extent: Vec3
    box: tuple[float, ...]  # (low x, y, z, high x, y, z), the hypothesis's
    recent_centers: tuple[Vec3, ...]
    class_evidence: Mapping[str, float]  # the hypothesis's, added to the object's
    embedding_sum: tuple[float, ...] | None  # ... likewise
    embedding_count: int
    existence_logodds: float
    p_exist: float
    batches_observed: int
    reacquired: bool  # the object had been removed: it restarts as a hypothesis
    parent_evidence: Mapping[str, float]  # the hypothesis's (the old support's is stale)


@dataclass(frozen=True, kw_only=True)
class VisibleMiss(TrackUpdated):
    """An unmatched track the visibility gate says was observable: a miss (U V = 1)."""

    topic: ClassVar[str] = "visible_miss"
    evidence: Literal["visible_miss"] = "visible_miss"
    samples_passed: int
    samples_total: int
    existence_logodds: float
    p_exist: float
    visible_misses: int


# -- lifecycle ---------------------------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class TrackConfirmed(TrackEvent):
    """Graph publication: cross-batch confirmation with p_exist >= 0.72."""

    topic: ClassVar[str] = "confirm"
    type: ClassVar[str] = "confirm"
    p_exist: float
    center: Vec3
    batches_observed: int
    consensus: Annotated[bool | None, Omitted] = None  # fixtures: did the consensus gate pass
    reason: Annotated[Literal["verification", "inspection"] | None, Omitted] = None


@dataclass(frozen=True, kw_only=True)
class TrackMoved(TrackEvent):
    """A published track is at least 0.35 m from its last published position."""

    topic: ClassVar[str] = "move"
    type: ClassVar[str] = "move"
    moved_from: Annotated[Vec3, Field(alias="from")]
    to: Vec3
    distance: float


@dataclass(frozen=True, kw_only=True)
class TrackReparented(TrackEvent):
    """The support parent changed: the old and the new parent."""

    topic: ClassVar[str] = "reparent"
    type: ClassVar[str] = "reparent"
    old_parent: str | None
    new_parent: str


@dataclass(frozen=True, kw_only=True)
class TrackDemoted(TrackEvent):
    """A published track fell below p_exist 0.30 and is unpublished."""

    topic: ClassVar[str] = "demote"
    type: ClassVar[str] = "demote"
    p_exist: float


@dataclass(frozen=True, kw_only=True)
class TrackRemoved(TrackEvent):
    """p_exist <= 0.12 after at least three visibility-admissible misses, or a rejection."""

    topic: ClassVar[str] = "remove"
    type: ClassVar[str] = "remove"
    p_exist: float
    visible_misses: Annotated[int | None, Omitted] = None
    reason: Annotated[Literal["verification_rejected"] | None, Omitted] = None


@dataclass(frozen=True, kw_only=True)
class TrackRetired(TrackEvent):
    """A track leaves the memory in play for good: a hypothesis never published and no longer
    believed (removed by visible misses, or unseen for `retire_unseen_hypothesis_s`), or a
    second track of one fixture, merged into the track that stands for it."""

    topic: ClassVar[str] = "retire"
    type: ClassVar[str] = "retire"
    reason: Literal["removed", "unseen", "merged"]
    last_observed: float | None
    merged_into: Annotated[str | None, Omitted] = None  # reason "merged": the track it joined


# A positive observation of a track in a batch (isinstance accepts this union).
Sighting = ObjectAdded | FixtureAdded | ObjectObserved | FixtureObserved

# An event of the log: exactly one of these classes. The one place a new event class is
# registered: its topic is read from here, and `fold`, whose match over this union ends in
# `assert_never`, fails type checking until it has a case for the new class.
Event = (
    SceneCreated
    | SceneRenamed
    | FixtureEvidence
    | OccupancyEvidence
    | BaselineFrozen
    | BaselineLoaded
    | BatchSkipped
    | ObjectAdded
    | FixtureAdded
    | ObjectObserved
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
    | InspectionRecorded
    | InspectionTargeted
)
