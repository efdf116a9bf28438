"""What a batch, a verdict or a capture decides about each track, before it is written as events.

The stages of `decide` hand each other these immutable values: the existence stage returns one
update per track (equation (3) with the fused values it carries), the lifecycle stage one
`TrackDecision` per track (that update and the transitions it triggers), and the emitter
(`core/emit.py`) turns decisions into events. No stage reads another stage's events.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

from core.fixtures import FixtureProposal
from core.geometry import Proposal
from core.state import Track
from core.values import LifecycleState, Vec3


@dataclass(frozen=True)
class Existence:
    """Equation (3) for one track: the log-odds after this batch (or verdict) and its counters."""

    logodds: float
    p_exist: float
    batches_observed: int  # distinct positive batches since (re)acquisition
    visible_misses: int  # visibility-admissible misses since the last positive batch
    reacquired: bool  # a removed track keeps its identity and restarts as a hypothesis
    lifecycle: LifecycleState  # the state the update leaves the track in, before transitions


@dataclass(frozen=True, eq=False)
class ObjectSighting:
    """The proposals of a batch (or a capture) that one object track explains."""

    track_id: str
    new: bool  # a new hypothesis (`add`), else an update of an existing track
    proposals: tuple[Proposal, ...]
    parents: tuple[str | None, ...]  # each proposal's support parent from geometry
    embedding_sum: tuple[float, ...] | None  # the batch's appearance in the track's dimension
    embedding_count: int
    # The match supports the track itself (its place or its appearance), not only something of
    # its class nearby: only then does the batch add existence evidence.
    corroborated: bool
    existence: Existence

    @property
    def frame_id(self) -> str:
        """A new track is named by its first sighting's frame, an update by its latest."""
        return self.proposals[0 if self.new else -1].frame_id


@dataclass(frozen=True, eq=False)
class FixtureSighting:
    """One batch's voxel cluster that a fixture track explains (or a new fixture hypothesis)."""

    track_id: str
    new: bool
    proposal: FixtureProposal
    batch_frame: str  # the batch's last frame
    timestamp: float
    center: Vec3  # the EMA of the cluster centers (alpha 0.35), or the cluster's own
    best_frame: str | None  # the frame to crop for a verifier
    best_frame_support: int
    existence: Existence

    @property
    def frame_id(self) -> str:
        """The frame that covered most of the cluster, else the batch's last."""
        return self.proposal.best_frame or self.batch_frame


@dataclass(frozen=True)
class Reidentification:
    """A missing object is a hypothesis seen since elsewhere: it takes the hypothesis's place."""

    track_id: str
    hypothesis: Track
    cosine: float  # their appearance cosine
    frame_id: str
    box: tuple[float, ...]  # the hypothesis's visibility box
    existence: Existence


@dataclass(frozen=True)
class Miss:
    """An unmatched track the visibility gate says was observable (U V = 1 in equation (3))."""

    track_id: str
    frame_id: str  # the frame that showed it best
    samples_passed: int
    existence: Existence


@dataclass(frozen=True)
class Verdict:
    """A cached verification of a pending track (eta_c or eta_r in equation (3))."""

    track_id: str
    verdict: Literal["confirm", "reject"]
    label: str
    source: str
    frame_id: str | None
    existence: Existence


Update = ObjectSighting | FixtureSighting | Reidentification | Miss | Verdict


@dataclass(frozen=True)
class Publication:
    """Graph publication: the track becomes a node (`confirm`)."""

    p_exist: float
    center: Vec3
    batches_observed: int
    consensus: bool | None = None  # fixtures: did the consensus gate pass
    # What stood in for cross-batch confirmation: a verdict or a verified capture (None: batches).
    reason: Literal["verification", "inspection"] | None = None


@dataclass(frozen=True)
class VerificationRequest:
    """A near-threshold or class-conflicting fixture waits for one bounded verification."""

    candidates: Mapping[str, float]  # each class's mean similarity over the cluster
    batch_votes: Mapping[str, float]  # how the supporting batches voted
    agreement: float
    mean_margin: float
    batches_observed: int
    best_frame: str | None


@dataclass(frozen=True)
class Move:
    """A published track at least 0.35 m from its last published position."""

    moved_from: Vec3
    to: Vec3
    distance: float


@dataclass(frozen=True)
class Reparent:
    """A valid support change."""

    old_parent: str | None
    new_parent: str


@dataclass(frozen=True)
class Demotion:
    """A published track below p_exist 0.30 is unpublished."""

    p_exist: float


@dataclass(frozen=True)
class Removal:
    """p_exist <= 0.12 after three visibility-admissible misses, or a rejection."""

    p_exist: float
    visible_misses: int | None = None
    reason: Literal["verification_rejected"] | None = None


@dataclass(frozen=True)
class Retirement:
    """The track leaves the memory in play for good."""

    reason: Literal["removed", "unseen", "merged"]
    frame_id: str
    last_observed: float | None
    merged_into: str | None = None


@dataclass(frozen=True)
class TrackDecision:
    """One track's update and the lifecycle transitions it triggers, in the order the log keeps:
    update, publication or verification request, move, reparent, demotion, removal, retirement."""

    track_id: str
    frame_id: str | None
    lifecycle: LifecycleState  # after the update, before the transitions
    update: Update | None = None
    parent_evidence: Mapping[str, float] | None = None  # objects sighted: support evidence after
    publish: Publication | None = None
    request: VerificationRequest | None = None
    move: Move | None = None
    reparent: Reparent | None = None
    demote: Demotion | None = None
    remove: Removal | None = None
    retire: Retirement | None = None
