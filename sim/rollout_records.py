"""The records of a closed-loop rollout (`sim.rollout`): its settings, each inspection capture
and what the whole rollout did."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from sim.memories import (
    InspectionOutcome,
    Node,
    Ranked,
    Recorded,
    TrackSummary,
)
from sim.truth import TruthFixture
from sim.verifier import VerdictRecord


@dataclass(frozen=True)
class RolloutSettings:
    """How the simulated robot acts; defaults are the protocol's (documented in sim/scenarios/README.md)."""

    keyframe_budget: int = 600  # coarse discovery: semantic keyframes posted on the way
    # Inspections the memory recorded (None: until the plan is done). A capture the memory
    # refused (a 4xx: nothing appended, e.g. its target merged away while the robot drove to
    # it) is no inspection: it is kept in `refused` and the robot asks for the plan again.
    inspection_budget: int | None = None
    keyframe_spacing_m: float = 0.5  # one keyframe per this much travel
    look_around_views: int = 6  # keyframes of a turn in place (60 degrees apart, FOV 62)
    keyframe_pitch_deg: float = -20.0  # keyframes look a little down, at furniture tops
    sweep_yaw_deg: tuple[float, ...] = (0.0, -20.0, 20.0)  # the primary view, then alternates
    grid_m: float = 0.10  # the true free-space grid the robot drives on
    max_decisions: int = 400  # a bound on plans asked (a rollout that loops stops here)
    max_visits_per_goal: int = 3  # an explore goal reached this often is recorded as stuck
    # Keyframes carry the object detector's output too (off: the paper's pipeline, where fine
    # objects come from fixture-centered captures only).
    keyframe_objects: bool = False
    # The simulated VLM answers coarse-stage and parent verification (off: neither is asked,
    # a fixture waiting for a verdict stays unpublished and captures carry no verification).
    verifier: bool = True
    # The chance each answer is wrong. 0 by default: the paper gives no rate for its VLM, so
    # the protocol's default measures the memory's mechanics with a truthful verifier; a sweep
    # of this knob measures how much a wrong one costs.
    verifier_error_rate: float = 0.0


@dataclass
class Capture:
    """One inspection the robot made."""

    fixture_id: str
    view: tuple[float, float, float, float]
    outcome: InspectionOutcome
    keyframes_before: int
    graph_after: list[Node]
    fixture_verified: bool | None = None  # the verifier's parent verification
    target: Ranked | None = None  # equation (5)'s terms when the plan chose the fixture

    @property
    def completed(self) -> bool:
        """The memory recorded the capture as a completed inspection."""
        return self.outcome == Recorded("completed")


@dataclass
class RolloutResult:
    """What one rollout did and what the memory holds at its end."""

    scenario: str
    seed: int
    order: str
    via_service: bool
    path: list[tuple[float, float]] = field(default_factory=list)
    keyframes: list[tuple[float, float, float]] = field(default_factory=list)  # x, y, travelled
    captures: list[Capture] = field(default_factory=list)  # inspections the memory recorded
    refused: list[Capture] = field(default_factory=list)  # captures it refused (nothing recorded)
    decisions: list[dict[str, Any]] = field(default_factory=list)
    verdicts: list[VerdictRecord] = field(default_factory=list)
    plan_ms: list[float] = field(default_factory=list)
    stop_reason: str = ""
    stuck_goals: list[tuple[float, float]] = field(default_factory=list)
    final_graph: list[Node] = field(default_factory=list)
    final_tracks: list[TrackSummary] = field(default_factory=list)
    final_queue: list[str] = field(default_factory=list)
    occupancy: dict[str, Any] = field(default_factory=dict)
    truth_fixtures: tuple[TruthFixture, ...] = ()
    truth_objects: tuple[tuple[str, str, tuple[float, float, float], str], ...] = ()
    seconds: float = 0.0

    @property
    def path_length_m(self) -> float:
        return sum(math.dist(a, b) for a, b in zip(self.path, self.path[1:], strict=False))
