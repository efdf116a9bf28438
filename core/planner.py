"""Where the robot should go next: inspect a fixture, explore a frontier, or nothing (section 3.4).

- Q_t: canonical confirmed fixtures of the inspection taxonomy whose close-range inspection is
  unresolved (the capture ledger: not completed, not abandoned), not rejected, not in progress
  (the locked target) and not cooling down after a failed capture.
- Target selection, equation (5): the fixtures of Q_t ranked by 0.8 u_i + 0.2 Prox(i); the first
  with a feasible view is the target (a fixture with none is deferred, the next one checked).
- The view: the feasible view minimising J, equation (6) (core/views.py).
- The target stays locked (`inspection_targeted`) until the fixture's next capture, a rejection
  or its completion; while locked, the plan keeps it (its view re-checked, and replaced by the
  cheapest feasible one when it is no longer feasible).
- No target with a feasible view: frontier exploration (the nearest reachable frontier); with
  none either, fixtures cooling down are retried; then `done`.

`plan` is pure: the plan decided at seq n is `plan(state at n, robot pose)`, reproducible
from the log with `as_of`.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from core.errors import StateConflict
from core.events import Event, InspectionTargeted
from core.navigation import Frontier, Navigation
from core.occupancy import MapGeometry
from core.params import Params
from core.state import SceneState, Track
from core.uncertainty import Uncertainty, fixture_uncertainty
from core.values import ViewPose
from core.views import View, best_view

Decision = Literal["inspect", "explore", "done"]
QueueStatus = Literal["queued", "in_progress", "retry_cooldown"]


@dataclass(frozen=True)
class Candidate:
    """A fixture of the queue with the terms of equation (5)."""

    fixture_id: str
    label: str
    uncertainty: Uncertainty
    proximity: float  # Prox(i)
    score: float  # 0.8 u_i + 0.2 Prox(i)


@dataclass(frozen=True)
class Target:
    """The fixture to inspect and the view to inspect it from."""

    candidate: Candidate
    view: View


@dataclass(frozen=True)
class Deferral:
    """A fixture of the queue passed over, and why."""

    fixture_id: str
    reason: Literal["no_feasible_view", "retry_cooldown"]


@dataclass(frozen=True)
class Plan:
    """The decision for one robot pose on one state."""

    decision: Decision
    seq: int  # the state's head: the plan is reproducible from the log at this seq
    robot: ViewPose
    reason: str
    target: Target | None = None
    lock: Literal["held", "new"] | None = None  # the target is the held lock, or a new one
    replaces: str | None = None  # the fixture of the lock a new one replaces
    frontier: Frontier | None = None
    deferred: tuple[Deferral, ...] = ()
    ranked: tuple[Candidate, ...] = ()  # Q_t by equation (5), best first


def unresolved_fixtures(state: SceneState) -> list[Track]:
    """Confirmed fixtures of the inspection taxonomy whose inspection is unresolved."""
    taxonomy = set(state.params.fixtures.inspection_taxonomy)
    return [
        t
        for t in (state.tracks[i] for i in sorted(state.tracks))
        if t.kind == "fixture"
        and t.lifecycle == "confirmed"
        and t.verification != "rejected"
        and t.label in taxonomy
        and t.inspection_status is None
    ]


def queue_status(state: SceneState, fixture_id: str) -> QueueStatus:
    """In progress (the locked target), cooling down after a failed capture, or queued."""
    ledger = state.plan
    if ledger.lock is not None and ledger.lock.fixture_id == fixture_id:
        return "in_progress"
    failed_at = ledger.failed_at_lock.get(fixture_id)
    cooldown = state.params.planner.retry_cooldown_locks
    if failed_at is not None and ledger.locks - failed_at < cooldown:
        return "retry_cooldown"
    return "queued"


def inspection_queue(state: SceneState) -> list[Track]:
    """Q_t: the unresolved fixtures neither in progress nor cooling down."""
    return [t for t in unresolved_fixtures(state) if queue_status(state, t.track_id) == "queued"]


def proximity(fixture: Track, robot: ViewPose, params: Params) -> float:
    """Prox(i) = clip(1 - d / 8 m, 0, 1), d the planar distance robot - fixture centre."""
    distance = math.hypot(fixture.center[0] - robot.x, fixture.center[1] - robot.y)
    return min(1.0, max(0.0, 1.0 - distance / params.planner.proximity_range_m))


def candidate(state: SceneState, fixture: Track, robot: ViewPose) -> Candidate:
    """The terms of equation (5) for one fixture."""
    params = state.params
    u = fixture_uncertainty(fixture, state.clock, params)
    prox = proximity(fixture, robot, params)
    score = params.planner.uncertainty_weight * u.value + params.planner.proximity_weight * prox
    return Candidate(fixture.track_id, fixture.label, u, prox, score)


def ranked(state: SceneState, fixtures: list[Track], robot: ViewPose) -> list[Candidate]:
    """Fixtures by equation (5), best first (ties by id)."""
    scored = [candidate(state, f, robot) for f in fixtures]
    seed = state.params.planner.tie_break_seed
    if seed is None:
        return sorted(scored, key=lambda c: (-c.score, c.fixture_id))
    return sorted(scored, key=lambda c: (-c.score, _hashed(seed, c.fixture_id), c.fixture_id))


def _hashed(seed: int, fixture_id: str) -> str:
    """A reproducible pseudo-random rank of a fixture under a seed (ties of equation (5))."""
    return hashlib.sha256(f"{seed}:{fixture_id}".encode()).hexdigest()


def plan(state: SceneState, robot: ViewPose) -> Plan:
    """The plan for a robot at `robot` on this state (pure, deterministic)."""
    params = state.params
    geometry = MapGeometry.of(params.occupancy)
    if max(abs(robot.x), abs(robot.y)) >= geometry.side // 2 * geometry.resolution_m:
        raise StateConflict(  # a pose the API admits, outside this scene's own map
            f"robot_pose ({robot.x:.2f}, {robot.y:.2f}) is outside the scene's map "
            f"(|x|, |y| < {params.occupancy.half_extent_m} m: occupancy.half_extent_m)",
            "robot_pose",
        )
    unresolved = unresolved_fixtures(state)
    queue = [f for f in unresolved if queue_status(state, f.track_id) == "queued"]
    order = tuple(ranked(state, queue, robot))

    def make(decision: Decision, reason: str, **details: Any) -> Plan:
        return Plan(decision, state.head_seq, robot, reason, ranked=order, **details)

    if state.occupancy.known_cells() == 0:
        return make("explore", "the map is empty: turn in place to observe")
    if not _beside_the_map(state, geometry, robot):
        # Nothing known is near: no path, no view (and no planning work over empty space).
        return make("explore", "the robot is not in known free space: turn in place to observe")
    navigation = Navigation(state.occupancy, geometry, robot, params.planner)
    failed = state.plan.failed_views
    by_id = {f.track_id: f for f in unresolved}
    locked, deferred, replaces = _locked_plan(state, navigation, by_id, robot, make)
    if locked is not None:
        return locked

    def first_feasible(entries: Iterable[Candidate], reason: str) -> Plan | None:
        """Lock the first of `entries` with a feasible view; defer the others on the way."""
        for entry in entries:
            fixture_id = entry.fixture_id
            view = best_view(
                navigation, by_id[fixture_id], failed.get(fixture_id, ()), params.planner
            )
            if view is not None:
                return make(
                    "inspect",
                    reason,
                    target=Target(entry, view),
                    lock="new",
                    replaces=replaces,
                    deferred=tuple(deferred),
                )
            deferred.append(Deferral(fixture_id, "no_feasible_view"))
        return None

    inspect = first_feasible(order, "the best-ranked fixture with a feasible view (equation (5))")
    if inspect is not None:
        return inspect
    frontier = nearest_frontier(navigation, params)
    if frontier is not None:
        return make(
            "explore",
            "no fixture with a feasible view: the nearest reachable frontier",
            frontier=frontier,
            deferred=tuple(deferred),
        )
    cooling = [f for f in unresolved if queue_status(state, f.track_id) == "retry_cooldown"]
    inspect = first_feasible(
        ranked(state, cooling, robot),
        "nothing else is left: a fixture cooling down after a failed capture",
    )
    if inspect is not None:
        return inspect
    if not (np.isfinite(navigation.travel) & navigation.known_ok).any():
        return make(
            "explore",
            "the robot is not in known free space: turn in place to observe",
            deferred=tuple(deferred),
        )
    return make(
        "done",
        "no fixture with a feasible view and no reachable frontier",
        deferred=tuple(deferred),
    )


def _locked_plan(
    state: SceneState,
    navigation: Navigation,
    by_id: Mapping[str, Track],
    robot: ViewPose,
    make: Callable[..., Plan],
) -> tuple[Plan | None, list[Deferral], str | None]:
    """The locked target while it has a feasible view (the locked one, else a new one):
    (that plan, or None with the lock deferred; the fixture of the lock a new one replaces)."""
    lock, failed, params = state.plan.lock, state.plan.failed_views, state.params
    if lock is None:
        return None, [], None
    if lock.fixture_id not in by_id:
        return None, [], lock.fixture_id  # completed, rejected or removed: the lock is void
    fixture = by_id[lock.fixture_id]
    held = candidate(state, fixture, robot)
    only = (lock.view.x, lock.view.y)
    view = best_view(
        navigation, fixture, failed.get(fixture.track_id, ()), params.planner, only=only
    )
    if view is not None:
        reason = "the locked target, its view still feasible"
        return make("inspect", reason, target=Target(held, view), lock="held"), [], None
    view = best_view(navigation, fixture, failed.get(fixture.track_id, ()), params.planner)
    if view is not None:
        reason = "the locked target, from a new view (the locked one is no longer feasible)"
        target = Target(held, view)
        return (
            make("inspect", reason, target=target, lock="new", replaces=fixture.track_id),
            [],
            None,
        )
    return None, [Deferral(fixture.track_id, "no_feasible_view")], fixture.track_id


def _beside_the_map(state: SceneState, geometry: MapGeometry, robot: ViewPose) -> bool:
    """Whether the robot's cell is inside the map's window, or within its radius of it."""
    row, col, _inside = geometry.cell_of(np.array([robot.x]), np.array([robot.y]))
    margin = math.ceil(state.params.planner.robot_radius_m / geometry.resolution_m) + 1
    (r0, c0), (rows, cols) = state.occupancy.origin, state.occupancy.shape
    return bool(
        r0 - margin <= row[0] < r0 + rows + margin and c0 - margin <= col[0] < c0 + cols + margin
    )


def nearest_frontier(navigation: Navigation, params: Params) -> Frontier | None:
    """The reachable frontier nearest by travel (ties: larger, then by centroid)."""
    reachable = [
        f
        for f in navigation.frontiers(params.planner.min_frontier_cells)
        if f.travel_m is not None and f.travel_m >= params.planner.min_frontier_travel_m
    ]
    if not reachable:
        return None
    return min(reachable, key=lambda f: (f.travel_m, -f.size, f.centroid))


def decide_plan(state: SceneState, robot: ViewPose) -> tuple[Plan, list[Event]]:
    """The plan, and the `inspection_targeted` event when it locks a new target."""
    decided = plan(state, robot)
    if decided.lock != "new" or decided.target is None:
        return decided, []
    target = decided.target
    fixture = state.tracks[target.candidate.fixture_id]
    view = target.view
    event = InspectionTargeted(
        track_id=fixture.track_id,
        state=fixture.lifecycle,
        robot=robot,
        view=view.pose,
        pitch=view.pitch,
        uncertainty=target.candidate.uncertainty.value,
        uncertainty_terms=target.candidate.uncertainty.terms,
        proximity=target.candidate.proximity,
        score=target.candidate.score,
        cost=view.cost,
        cost_terms=view.cost_terms,
        standoff_m=view.standoff_m,
        travel_m=view.travel_m,
        clearance_m=view.clearance_m,
        coverage=view.coverage,
        deferred=tuple(d.fixture_id for d in decided.deferred),
        replaces=decided.replaces,
    )
    return decided, [event]
