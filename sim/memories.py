"""What the simulated robot talks to: the core in process, or the service over HTTP.

`InProcessMemory` calls decide/fold for batches, the planner's `decide_plan` and
`decide_inspection`, exactly the functions the service's worker and routes call;
`ServiceMemory` POSTs batches, /plan and /inspections instead. Both answer the same `Memory`
protocol, so a rollout cannot tell them apart (a test checks they take the same decisions).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from api_schema import BatchIn, InspectionIn, Occupancy
from core.decide import decide
from core.errors import PbdagError
from core.events import SceneCreated
from core.evolve import evolve, fold
from core.graph import is_published
from core.inspection import decide_inspection
from core.params import Params
from core.plan_ledger import ViewPose
from core.planner import Plan, decide_plan, unresolved_fixtures
from core.state import SceneState
from service.codec import decode_batch, decode_frames
from service.wire import occupancy_out


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


class Memory(Protocol):
    """What the robot talks to: the core in process, or the service over HTTP."""

    def post_batch(self, body: dict[str, Any]) -> None: ...
    def plan(self, pose: ViewPose) -> PlanStep: ...
    def inspect(
        self, capture_id: str, fixture_id: str, frames: list[dict[str, Any]], view: ViewPose
    ) -> str: ...
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
    ) -> str:
        body = InspectionIn.model_validate({"fixture_id": fixture_id, "frames": frames})
        try:
            events = decide_inspection(
                self.state, capture_id, fixture_id, decode_frames(body.frames), None, view=view
            )
        except PbdagError as error:  # the service answers 4xx, and appends nothing
            return f"refused: {error}"
        self.state = fold(self.state, events)
        outcome: str = events[-1].details()["outcome"]
        return outcome

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
    """The service over HTTP: POST batches (waiting for each), POST /plan, POST /inspections."""

    def __init__(
        self,
        client: Any,  # httpx.Client, or Starlette's TestClient in tests
        name: str,
        params: Mapping[str, Any] | None = None,
        timeout_s: float = 120.0,
    ) -> None:
        self.client = client
        self.timeout_s = timeout_s
        response = client.post("/v1/scenes", json={"name": name, "params": dict(params or {})})
        response.raise_for_status()
        self.scene = f"/v1/scenes/{response.json()['id']}"

    def _call(self, method: str, path: str, **kwargs: Any) -> dict[str, Any]:
        deadline = time.monotonic() + self.timeout_s
        while True:
            response = self.client.request(method, self.scene + path, **kwargs)
            if response.status_code == 429 and time.monotonic() < deadline:
                time.sleep(float(response.headers.get("retry-after", "1")))
                continue
            response.raise_for_status()
            body: dict[str, Any] = response.json()
            return body

    def post_batch(self, body: dict[str, Any]) -> None:
        self._call("POST", "/batches", json=body)
        deadline = time.monotonic() + self.timeout_s
        while time.monotonic() < deadline:
            status = self._call("GET", f"/batches/{body['batch_id']}")
            if status["status"] == "done":
                return
            if status["status"] == "dead":
                raise RuntimeError(f"batch {body['batch_id']} dead: {status['error']}")
            time.sleep(0.01)
        raise TimeoutError(f"batch {body['batch_id']} not done within {self.timeout_s:.0f} s")

    def plan(self, pose: ViewPose) -> PlanStep:
        robot = {"x": pose.x, "y": pose.y, "yaw": pose.yaw}
        out = self._call("POST", "/plan", json={"robot_pose": robot})
        deferred = tuple(d["fixture_id"] for d in out["deferred"])
        target, frontier = out["target"], out["frontier"]
        if target is not None:
            v = target["view"]
            return PlanStep(
                out["decision"],
                out["reason"],
                fixture_id=target["fixture_id"],
                view=(v["x"], v["y"], v["yaw"], v["pitch"]),
                deferred=deferred,
            )
        return PlanStep(
            out["decision"],
            out["reason"],
            goal=None if frontier is None or frontier["goal"] is None else tuple(frontier["goal"]),
            centroid=None if frontier is None else tuple(frontier["centroid"]),
            deferred=deferred,
        )

    def inspect(
        self, capture_id: str, fixture_id: str, frames: list[dict[str, Any]], view: ViewPose
    ) -> str:
        body = {
            "fixture_id": fixture_id,
            "frames": frames,
            "capture_id": capture_id,
            "view": {"x": view.x, "y": view.y, "yaw": view.yaw},
        }
        response = self.client.post(self.scene + "/inspections", json=body)
        if 400 <= response.status_code < 500 and response.status_code != 429:
            return f"refused: {response.json().get('detail', response.status_code)}"
        response.raise_for_status()
        outcome: str = response.json()["outcome"]
        return outcome

    def graph(self) -> list[Node]:
        nodes = self._call("GET", "/graph")["nodes"]
        return [
            Node(n["id"], n["label"], n["kind"], tuple(n["center"]), n["parent"]) for n in nodes
        ]

    def tracks(self) -> list[TrackSummary]:
        response = self.client.get(self.scene + "/tracks")
        response.raise_for_status()
        return [
            TrackSummary(
                t["track_id"],
                t["label"],
                t["kind"],
                t["state"],
                (t["center"][0], t["center"][1], t["center"][2]),
                t["parent"],
                t["visible_misses"],
            )
            for t in response.json()
        ]

    def occupancy(self) -> dict[str, Any]:
        return Occupancy.model_validate(self._call("GET", "/occupancy")).model_dump()

    def queue(self) -> list[str]:
        return [f["fixture_id"] for f in self._call("GET", "/inspection-queue")["fixtures"]]
