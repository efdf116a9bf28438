"""What the simulated robot talks to: the core in process, or the service over HTTP.

`InProcessMemory` calls decide/fold for batches, the planner's `decide_plan` and
`decide_inspection`, exactly the functions the service's worker and routes call;
`ServiceMemory` POSTs batches, /plan and /inspections through `pbdag_client` instead. Both answer the same `Memory`
protocol, so a rollout cannot tell them apart (a test checks they take the same decisions).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from api_schema import BatchIn, InspectionIn, RobotPose
from codec.observations import decode_batch, decode_frames
from codec.occupancy import occupancy_out
from core.decide import decide
from core.events import InspectionRecorded, SceneCreated
from core.evolve import evolve, fold
from core.graph import is_published
from core.inspection import decide_inspection
from core.params import Params
from core.planner import Plan, decide_plan, unresolved_fixtures
from core.state import SceneState
from core.values import ViewPose
from pbdag_client import Client, InsufficientStorage, RateLimited, RequestRefused
from pbdag_errors import Refused

T = TypeVar("T")


@dataclass(frozen=True)
class Node:
    """A published node of the memory's graph."""

    track_id: str
    label: str
    kind: str
    center: tuple[float, float, float]
    parent: str | None


@dataclass(frozen=True)
class TrackSummary:
    """Any track of the memory, published or not (for the traces of shortfalls)."""

    track_id: str
    label: str
    kind: str
    state: str
    center: tuple[float, float, float]
    parent: str | None
    visible_misses: int


@dataclass(frozen=True)
class PlanStep:
    """The part of a plan the robot acts on."""

    decision: str
    reason: str
    fixture_id: str | None = None
    view: tuple[float, float, float, float] | None = None  # x, y, yaw, pitch
    goal: tuple[float, float] | None = None  # explore: the frontier's goal
    centroid: tuple[float, float] | None = None
    deferred: tuple[str, ...] = ()


@dataclass(frozen=True)
class Recorded:
    """The memory recorded the capture, with this outcome (completed, support_not_visible or
    parent_rejected)."""

    outcome: str

    @property
    def text(self) -> str:
        """The outcome as reports print it."""
        return self.outcome


@dataclass(frozen=True)
class Refusal:
    """The memory refused the capture and recorded nothing (the service's 4xx): why."""

    reason: str

    @property
    def text(self) -> str:
        """The refusal as reports print it."""
        return f"refused: {self.reason}"


InspectionOutcome = Recorded | Refusal


class Memory(Protocol):
    """What the robot talks to: the core in process, or the service over HTTP."""

    def post_batch(self, body: dict[str, Any]) -> None: ...
    def plan(self, pose: ViewPose) -> PlanStep: ...
    def inspect(
        self, capture_id: str, fixture_id: str, frames: list[dict[str, Any]], view: ViewPose
    ) -> InspectionOutcome: ...
    def graph(self) -> list[Node]: ...
    def tracks(self) -> list[TrackSummary]: ...
    def occupancy(self) -> dict[str, Any]: ...
    def queue(self) -> list[str]: ...


def _step_of(decided: Plan) -> PlanStep:
    deferred = tuple(d.fixture_id for d in decided.deferred)
    if decided.target is not None:
        v = decided.target.view
        return PlanStep(
            decided.decision,
            decided.reason,
            fixture_id=decided.target.candidate.fixture_id,
            view=(v.pose.x, v.pose.y, v.pose.yaw, v.pitch),
            deferred=deferred,
        )
    frontier = decided.frontier
    return PlanStep(
        decided.decision,
        decided.reason,
        goal=None if frontier is None else frontier.goal,
        centroid=None if frontier is None else frontier.centroid,
        deferred=deferred,
    )


class InProcessMemory:
    """The core's decide/fold and planner, as the service's worker and routes run them."""

    def __init__(self, name: str, params: Mapping[str, Any] | None = None) -> None:
        self.params = Params.from_dict(dict(params or {}))
        self.state = evolve(SceneState(), SceneCreated(name=name, params=self.params.to_dict()))

    def post_batch(self, body: dict[str, Any]) -> None:
        batch = decode_batch(BatchIn.model_validate(body))
        self.state = fold(self.state, decide(self.state, batch))

    def plan(self, pose: ViewPose) -> PlanStep:
        decided, events = decide_plan(self.state, pose)
        self.state = fold(self.state, events)
        return _step_of(decided)

    def inspect(
        self, capture_id: str, fixture_id: str, frames: list[dict[str, Any]], view: ViewPose
    ) -> InspectionOutcome:
        body = InspectionIn.model_validate({"fixture_id": fixture_id, "frames": frames})
        try:
            events = decide_inspection(
                self.state, capture_id, fixture_id, decode_frames(body.frames), None, view=view
            )
        except Refused as error:  # the service answers 4xx, and appends nothing
            return Refusal(error.detail)
        self.state = fold(self.state, events)
        (recorded,) = (e for e in events if isinstance(e, InspectionRecorded))
        return Recorded(recorded.outcome)

    def graph(self) -> list[Node]:
        return [
            Node(t.track_id, t.label, t.kind, t.center, t.parent)
            for t in (self.state.tracks[i] for i in sorted(self.state.tracks))
            if is_published(t)
        ]

    def tracks(self) -> list[TrackSummary]:
        return [
            TrackSummary(
                t.track_id, t.label, t.kind, t.lifecycle, t.center, t.parent, t.visible_misses
            )
            for t in (self.state.tracks[i] for i in sorted(self.state.tracks))
        ]

    def occupancy(self) -> dict[str, Any]:
        return occupancy_out("in-process", self.state).model_dump()

    def queue(self) -> list[str]:
        return [t.track_id for t in unresolved_fixtures(self.state)]


class ServiceMemory:
    """The service over HTTP through its client: POST batches (waiting for each), POST /plan,
    POST /inspections. A 429 is waited out (its Retry-After) for up to `timeout_s`."""

    def __init__(
        self,
        client: Client,
        name: str,
        params: Mapping[str, Any] | None = None,
        timeout_s: float = 120.0,
    ) -> None:
        self.client = client
        self.timeout_s = timeout_s
        self.scene_id = self._patiently(
            lambda: client.create_scene(name, params=dict(params or {}))
        ).id

    def _patiently(self, call: Callable[[], T]) -> T:
        deadline = time.monotonic() + self.timeout_s
        while True:
            try:
                return call()
            except RateLimited as error:
                if time.monotonic() >= deadline:
                    raise
                time.sleep(error.retry_after if error.retry_after is not None else 1.0)

    def post_batch(self, body: dict[str, Any]) -> None:
        batch = BatchIn.model_validate(body)
        self._patiently(lambda: self.client.post_batch(self.scene_id, batch))
        self.client.wait_for_batch(
            self.scene_id, batch.batch_id, timeout=self.timeout_s, poll_interval=0.01
        )

    def plan(self, pose: ViewPose) -> PlanStep:
        robot = RobotPose(x=float(pose.x), y=float(pose.y), yaw=float(pose.yaw))
        out = self._patiently(lambda: self.client.plan(self.scene_id, robot))
        deferred = tuple(d.fixture_id for d in out.deferred)
        target, frontier = out.target, out.frontier
        if target is not None:
            v = target.view
            return PlanStep(
                out.decision,
                out.reason,
                fixture_id=target.fixture_id,
                view=(v.x, v.y, v.yaw, v.pitch),
                deferred=deferred,
            )
        return PlanStep(
            out.decision,
            out.reason,
            goal=None if frontier is None or frontier.goal is None else _pair(frontier.goal),
            centroid=None if frontier is None else _pair(frontier.centroid),
            deferred=deferred,
        )

    def inspect(
        self, capture_id: str, fixture_id: str, frames: list[dict[str, Any]], view: ViewPose
    ) -> InspectionOutcome:
        body = InspectionIn.model_validate(
            {
                "fixture_id": fixture_id,
                "frames": frames,
                "capture_id": capture_id,
                "view": {"x": float(view.x), "y": float(view.y), "yaw": float(view.yaw)},
            }
        )
        try:
            return Recorded(self.client.post_inspection(self.scene_id, body).outcome)
        except (RateLimited, InsufficientStorage):
            raise  # a limit of the service, not a refusal of this capture
        except RequestRefused as error:
            return Refusal(error.detail)  # the service appended nothing

    def graph(self) -> list[Node]:
        nodes = self._patiently(lambda: self.client.graph(self.scene_id)).nodes
        return [Node(n.id, n.label, n.kind, _triple(n.center), n.parent) for n in nodes]

    def tracks(self) -> list[TrackSummary]:
        return [
            TrackSummary(
                t.track_id, t.label, t.kind, t.state, _triple(t.center), t.parent, t.visible_misses
            )
            for t in self._patiently(lambda: self.client.tracks(self.scene_id))
        ]

    def occupancy(self) -> dict[str, Any]:
        return self._patiently(lambda: self.client.occupancy(self.scene_id)).model_dump()

    def queue(self) -> list[str]:
        fixtures = self._patiently(lambda: self.client.inspection_queue(self.scene_id))
        return [f.fixture_id for f in fixtures]


def _pair(values: list[float]) -> tuple[float, float]:
    return (values[0], values[1])


def _triple(values: list[float]) -> tuple[float, float, float]:
    return (values[0], values[1], values[2])
