"""What the simulated robot talks to: the core in process, or the service over HTTP.

`InProcessMemory` calls decide/fold for batches, the planner's `decide_plan`,
`decide_inspection` and `decide_verdict`, exactly the functions the service's worker and routes
call; `ServiceMemory` POSTs batches, /plan, /inspections and verdicts
(`/tracks/{id}/verification`) through `pbdag_client` instead, and reads the verification queue
(`/verifications`). Both answer the same `Memory` protocol, so a rollout cannot tell them apart
(a test checks they take the same decisions).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from api_schema import BatchIn, InspectionIn, RobotPose, TrackBelief, VerdictIn
from codec.observations import decode_batch, decode_frames
from codec.occupancy import occupancy_out
from core.decide import decide
from core.events import InspectionRecorded, SceneCreated
from core.evolve import evolve, fold
from core.graph import is_published, pending_verifications
from core.inspection import decide_inspection
from core.params import Params
from core.planner import Candidate, Plan, decide_plan, unresolved_fixtures
from core.state import SceneState, Track
from core.values import ViewPose
from core.verification import decide_verdict
from pbdag_client import (
    Client,
    InsufficientStorage,
    RateLimited,
    RequestRefused,
    ResourceNotFound,
)
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
class Ranked:
    """A fixture of the plan with the terms of equation (5): u_i, its six phi_i, Prox, score."""

    fixture_id: str
    uncertainty: float
    terms: Mapping[str, float]
    proximity: float
    score: float


@dataclass(frozen=True)
class PlanStep:
    """The part of a plan the robot acts on, and the ranking it came from (for the traces)."""

    decision: str
    reason: str
    fixture_id: str | None = None
    view: tuple[float, float, float, float] | None = None  # x, y, yaw, pitch
    goal: tuple[float, float] | None = None  # explore: the frontier's goal
    centroid: tuple[float, float] | None = None
    deferred: tuple[str, ...] = ()
    target: Ranked | None = None  # inspect: the target's terms
    ranked: tuple[Ranked, ...] = ()  # Q_t by equation (5), best first


@dataclass(frozen=True)
class PendingVerification:
    """A fixture hypothesis in the verification queue: what a verifier looks at."""

    track_id: str
    label: str
    center: tuple[float, float, float]
    best_frame: str | None  # the observation to crop; the verdict names it


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
# A verdict the memory recorded (`Recorded` holds the track's lifecycle state after it), or
# one it refused.
VerdictOutcome = Recorded | Refusal


class Memory(Protocol):
    """What the robot talks to: the core in process, or the service over HTTP."""

    def post_batch(self, body: dict[str, Any]) -> None: ...
    def plan(self, pose: ViewPose) -> PlanStep: ...
    def inspect(
        self,
        capture_id: str,
        fixture_id: str,
        frames: list[dict[str, Any]],
        view: ViewPose,
        fixture_verified: bool | None = None,
    ) -> InspectionOutcome: ...
    def pending_verifications(self) -> list[PendingVerification]: ...
    def verify(self, track_id: str, body: VerdictIn) -> VerdictOutcome: ...
    def track(self, track_id: str) -> TrackSummary | None: ...
    def graph(self) -> list[Node]: ...
    def tracks(self) -> list[TrackSummary]: ...
    def occupancy(self) -> dict[str, Any]: ...
    def queue(self) -> list[str]: ...


def _ranked_of(entry: Candidate) -> Ranked:
    u = entry.uncertainty
    return Ranked(entry.fixture_id, u.value, dict(u.terms), entry.proximity, entry.score)


def _step_of(decided: Plan) -> PlanStep:
    deferred = tuple(d.fixture_id for d in decided.deferred)
    ranked = tuple(_ranked_of(c) for c in decided.ranked)
    if decided.target is not None:
        v = decided.target.view
        return PlanStep(
            decided.decision,
            decided.reason,
            fixture_id=decided.target.candidate.fixture_id,
            view=(v.pose.x, v.pose.y, v.pose.yaw, v.pitch),
            deferred=deferred,
            target=_ranked_of(decided.target.candidate),
            ranked=ranked,
        )
    frontier = decided.frontier
    return PlanStep(
        decided.decision,
        decided.reason,
        goal=None if frontier is None else frontier.goal,
        centroid=None if frontier is None else frontier.centroid,
        deferred=deferred,
        ranked=ranked,
    )


def _summary(t: Track) -> TrackSummary:
    return TrackSummary(
        t.track_id, t.label, t.kind, t.lifecycle, t.center, t.parent, t.visible_misses
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
        self,
        capture_id: str,
        fixture_id: str,
        frames: list[dict[str, Any]],
        view: ViewPose,
        fixture_verified: bool | None = None,
    ) -> InspectionOutcome:
        body = InspectionIn.model_validate(
            {"fixture_id": fixture_id, "frames": frames, "fixture_verified": fixture_verified}
        )
        try:
            events = decide_inspection(
                self.state,
                capture_id,
                fixture_id,
                decode_frames(body.frames),
                body.fixture_verified,
                view=view,
            )
        except Refused as error:  # the service answers 4xx, and appends nothing
            return Refusal(error.detail)
        self.state = fold(self.state, events)
        (recorded,) = (e for e in events if isinstance(e, InspectionRecorded))
        return Recorded(recorded.outcome)

    def pending_verifications(self) -> list[PendingVerification]:
        """What `GET /verifications` lists: pending tracks not removed, by id."""
        tracks = [self.state.tracks[i] for i in pending_verifications(self.state)]
        return [PendingVerification(t.track_id, t.label, t.center, t.best_frame) for t in tracks]

    def verify(self, track_id: str, body: VerdictIn) -> VerdictOutcome:
        try:
            events = decide_verdict(
                self.state, track_id, body.verdict, body.label, body.source, body.frame_id
            )
        except Refused as error:  # the service answers 4xx, and appends nothing
            return Refusal(error.detail)
        self.state = fold(self.state, events)
        return Recorded(self.state.tracks[track_id].lifecycle)

    def track(self, track_id: str) -> TrackSummary | None:
        found = self.state.tracks.get(track_id)
        return None if found is None else _summary(found)

    def graph(self) -> list[Node]:
        return [
            Node(t.track_id, t.label, t.kind, t.center, t.parent)
            for t in (self.state.tracks[i] for i in sorted(self.state.tracks))
            if is_published(t)
        ]

    def tracks(self) -> list[TrackSummary]:
        return [_summary(self.state.tracks[i]) for i in sorted(self.state.tracks)]

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
        ranked = tuple(
            Ranked(q.fixture_id, q.uncertainty.value, q.uncertainty.terms, q.proximity, q.score)
            for q in out.queue
        )
        target, frontier = out.target, out.frontier
        if target is not None:
            v, u = target.view, target.uncertainty
            return PlanStep(
                out.decision,
                out.reason,
                fixture_id=target.fixture_id,
                view=(v.x, v.y, v.yaw, v.pitch),
                deferred=deferred,
                target=Ranked(target.fixture_id, u.value, u.terms, target.proximity, target.score),
                ranked=ranked,
            )
        return PlanStep(
            out.decision,
            out.reason,
            goal=None if frontier is None or frontier.goal is None else _pair(frontier.goal),
            centroid=None if frontier is None else _pair(frontier.centroid),
            deferred=deferred,
            ranked=ranked,
        )

    def inspect(
        self,
        capture_id: str,
        fixture_id: str,
        frames: list[dict[str, Any]],
        view: ViewPose,
        fixture_verified: bool | None = None,
    ) -> InspectionOutcome:
        body = InspectionIn.model_validate(
            {
                "fixture_id": fixture_id,
                "frames": frames,
                "capture_id": capture_id,
                "fixture_verified": fixture_verified,
                "view": {"x": float(view.x), "y": float(view.y), "yaw": float(view.yaw)},
            }
        )
        try:
            return Recorded(self.client.post_inspection(self.scene_id, body).outcome)
        except (RateLimited, InsufficientStorage):
            raise  # a limit of the service, not a refusal of this capture
        except RequestRefused as error:
            return Refusal(error.detail)  # the service appended nothing

    def pending_verifications(self) -> list[PendingVerification]:
        """`GET /verifications` (pending), each track's center from `GET /tracks/{id}`."""
        items = self._patiently(lambda: self.client.verifications(self.scene_id))
        pending = []
        for item in items:
            center = _triple(self._belief(item.track_id).center)
            pending.append(PendingVerification(item.track_id, item.label, center, item.best_frame))
        return pending

    def _belief(self, track_id: str) -> TrackBelief:
        return self._patiently(lambda: self.client.track(self.scene_id, track_id))

    def verify(self, track_id: str, body: VerdictIn) -> VerdictOutcome:
        try:
            result = self._patiently(
                lambda: self.client.post_verdict(self.scene_id, track_id, body)
            )
        except (RateLimited, InsufficientStorage):
            raise  # a limit of the service, not a refusal of this verdict
        except RequestRefused as error:
            return Refusal(error.detail)  # the service appended nothing
        return Recorded(result.state or "absent")

    def track(self, track_id: str) -> TrackSummary | None:
        try:
            t = self._belief(track_id)
        except ResourceNotFound:
            return None
        return TrackSummary(
            t.track_id, t.label, t.kind, t.state, _triple(t.center), t.parent, t.visible_misses
        )

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
