"""Events of the active half (section 3.4): a fixture's verification and the inspections the
planner targets and records. They are part of the log's one union, `core.events.Event`, and
are imported from there."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, ClassVar, Literal

from pydantic import Field

from core.event_envelope import TrackEvent
from core.values import Omitted, ViewPose


@dataclass(frozen=True, kw_only=True)
class VerificationRequested(TrackEvent):
    """A near-threshold or class-conflicting fixture waits for one bounded verification."""

    topic: ClassVar[str] = "verification_requested"
    type: ClassVar[str] = "verification_requested"
    candidates: Mapping[str, float]  # each class's mean similarity over the cluster
    batch_votes: Mapping[str, float]  # how the supporting batches voted
    agreement: float
    mean_margin: float
    batches_observed: int
    best_frame: str | None


@dataclass(frozen=True, kw_only=True)
class TrackVerified(TrackEvent):
    """A verdict on a pending track: evidence weight 3, existence +1.8 or -2.2."""

    topic: ClassVar[str] = "verify"
    type: ClassVar[str] = "verify"
    verdict: Literal["confirm", "reject"]
    label: str
    source: str
    verdict_frame: Annotated[str | None, Field(alias="frame_id")]  # equals the envelope's
    existence_logodds: float
    p_exist: float


@dataclass(frozen=True, kw_only=True)
class InspectionRecorded(TrackEvent):
    """One fixture-centered capture in the ledger: frames, outcome and attached children."""

    topic: ClassVar[str] = "inspection"
    type: ClassVar[str] = "inspection"
    capture_id: str
    fixture_id: str
    frames: tuple[str, ...]
    primary_frame: str | None
    fixture_verified: bool | None
    outcome: Literal["completed", "support_not_visible", "parent_rejected"]
    children: tuple[str, ...]
    attempts: int
    status: Literal["completed", "abandoned"] | None
    # Where the robot stood for the capture (the locked view, or the one the client named);
    # a failed capture excludes views near it for this fixture (older logs: none).
    view: Annotated[ViewPose | None, Omitted] = None


@dataclass(frozen=True, kw_only=True)
class InspectionTargeted(TrackEvent):
    """The planner locked a fixture as the inspection target (equations (4)-(6), section 3.4).

    The lock holds until the fixture's next capture (completed or failed), a rejection or its
    completion; the event says why the robot goes there: u_i with its six terms, Prox(i), the
    score of equation (5), and the view with J and its terms (equation (6)).
    """

    topic: ClassVar[str] = "inspection_targeted"
    type: ClassVar[str] = "inspection_targeted"
    robot: ViewPose  # the robot's pose the plan was decided for
    view: ViewPose  # where to stand, facing the fixture
    pitch: float  # camera tilt at the view, radians (negative looks down)
    uncertainty: float  # u_i
    uncertainty_terms: Mapping[str, float]  # phi_i: existence, class, parent, position, ...
    proximity: float  # Prox(i)
    score: float  # 0.8 u_i + 0.2 Prox(i)
    cost: float  # J(v, i)
    cost_terms: Mapping[str, float]  # standoff, travel, clearance, coverage, margin
    standoff_m: float  # d_foot(v, i)
    travel_m: float  # D_t(v)
    clearance_m: float  # Clr(v)
    coverage: float  # Cov(v, i)
    deferred: tuple[str, ...]  # fixtures ranked above it that had no feasible view
    replaces: Annotated[str | None, Omitted] = None  # the fixture of the lock it replaces

    def touched_tracks(self) -> tuple[str, ...]:
        """None: a lock changes no track (it is planning state)."""
        return ()
