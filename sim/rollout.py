"""Closed-loop autonomous rollouts (section 3.4; the paper's Table 3 protocol).

The robot starts with an empty memory and an unknown map at the scenario trajectory's first
point. It asks the memory for the plan and acts on it:

- `explore`: it drives to the frontier's goal (or, with none, turns where it stands) and looks
  around: `look_around_views` keyframes, evenly spaced in yaw;
- `inspect`: it drives to the view, makes a fixed-base RGB-D sweep (the view's heading first,
  then the alternates of `sweep_yaw_deg`) at full detector resolution and posts the inspection
  (the primary view first, alternates for retry; the view it stood at);
- `done`: it stops.

It drives along a shortest path over the simulator's true free space (the room, walls and
fixtures, inflated by the robot's radius: the paper's navigation proxy), while the planner sees
only the map A_t built from what the robot posted. On the way it posts one semantic keyframe
(one-frame batch) every `keyframe_spacing_m` of travel, seen by the far-range detector
(`detector.far_range_input_scale`), within the coarse-discovery budget of 600 keyframes.

The memory is either the core in process (`InProcessMemory`: decide/fold for batches, the
planner's `decide_plan` and `decide_inspection`, exactly the functions the service's routes
call) or the service over HTTP (`ServiceMemory`: POST batches, POST /plan, POST /inspections).
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import httpx
import numpy as np
import numpy.typing as npt
from scipy import sparse
from scipy.sparse import csgraph

from api_schema import BatchIn, InspectionIn, Occupancy
from core.decide import decide
from core.errors import PbdagError
from core.events import SceneCreated
from core.evolve import evolve, fold
from core.graph import is_published
from core.inspection import decide_inspection
from core.params import Params
from core.planner import Plan, decide_plan, unresolved_fixtures
from core.state import SceneState, ViewPose
from service.codec import decode_batch, decode_frames
from service.wire import occupancy_out
from sim.camera import look_at
from sim.detector_model import RealisticDetector
from sim.render import add_kinect_noise, render
from sim.scenario import load_scenario
from sim.scenario_spec import Scenario
from sim.stream import run_rng
from sim.timeline import Timeline
from sim.truth import TruthFixture
from sim.wire import make_batch, make_frame
from sim.world import Box, World

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class RolloutSettings:
    """How the simulated robot acts; defaults are the protocol's (documented in the README)."""

    keyframe_budget: int = 600  # coarse discovery: semantic keyframes posted on the way
    inspection_budget: int | None = None  # inspection captures (None: until the plan is done)
    keyframe_spacing_m: float = 0.5  # one keyframe per this much travel
    look_around_views: int = 6  # keyframes of a turn in place (60 degrees apart, FOV 62)
    keyframe_pitch_deg: float = -20.0  # keyframes look a little down, at furniture tops
    sweep_yaw_deg: tuple[float, ...] = (0.0, -20.0, 20.0)  # the primary view, then alternates
    grid_m: float = 0.10  # the true free-space grid the robot drives on
    max_decisions: int = 400  # a bound on plans asked (a rollout that loops stops here)
    max_visits_per_goal: int = 3  # an explore goal reached this often is recorded as stuck


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


class FreeSpace:
    """The simulator's true free space on a grid: where the robot's center may be."""

    def __init__(self, world: World, robot_radius_m: float, cell_m: float) -> None:
        self.cell = cell_m
        sx, sy, _ = world.room_size
        self.cols, self.rows = int(sx / cell_m), int(sy / cell_m)
        xs = (np.arange(self.cols) + 0.5) * cell_m
        ys = (np.arange(self.rows) + 0.5) * cell_m
        gx, gy = np.meshgrid(xs, ys)  # (rows, cols)
        free = (
            (gx > robot_radius_m)
            & (gx < sx - robot_radius_m)
            & (gy > robot_radius_m)
            & (gy < sy - robot_radius_m)
        )
        for box in (*world.fixtures, *world.occluders):
            free &= _box_distance(box, gx, gy) > robot_radius_m
        self.free = free
        index = -np.ones(free.shape, dtype=np.int64)
        index[free] = np.arange(int(free.sum()))
        self.index = index
        rows_idx, cols_idx = np.nonzero(free)
        self.cell_rc = np.column_stack((rows_idx, cols_idx))
        sources, targets, weights = [], [], []
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            r2, c2 = rows_idx + dr, cols_idx + dc
            ok = (r2 >= 0) & (r2 < self.rows) & (c2 >= 0) & (c2 < self.cols)
            ok[ok] &= free[r2[ok], c2[ok]]
            if dr and dc:  # a diagonal step needs both sides free (no corner cutting)
                ok[ok] &= free[rows_idx[ok], c2[ok]] & free[r2[ok], cols_idx[ok]]
            sources.append(index[rows_idx[ok], cols_idx[ok]])
            targets.append(index[r2[ok], c2[ok]])
            weights.append(np.full(int(ok.sum()), math.hypot(dr, dc) * cell_m))
        n = int(free.sum())
        self.graph = sparse.coo_matrix(
            (np.concatenate(weights), (np.concatenate(sources), np.concatenate(targets))),
            shape=(n, n),
        ).tocsr()

    def xy(self, node: int) -> tuple[float, float]:
        r, c = self.cell_rc[node]
        return ((c + 0.5) * self.cell, (r + 0.5) * self.cell)

    def nearest(self, x: float, y: float, among: npt.NDArray[np.bool_] | None = None) -> int:
        """The free node nearest (x, y), optionally among a subset of nodes."""
        centers = (self.cell_rc[:, ::-1] + 0.5) * self.cell
        d = np.hypot(centers[:, 0] - x, centers[:, 1] - y)
        if among is not None:
            d = np.where(among, d, np.inf)
        return int(np.argmin(d))

    def path(self, start: int, x: float, y: float) -> list[int]:
        """The shortest path from node `start` to the reachable node nearest (x, y)."""
        distances, predecessors = csgraph.dijkstra(
            self.graph, directed=False, indices=start, return_predecessors=True
        )
        goal = self.nearest(x, y, np.isfinite(distances))
        nodes = [goal]
        while nodes[-1] != start:
            nodes.append(int(predecessors[nodes[-1]]))
        return nodes[::-1]


def _box_distance(box: Box, gx: FloatArray, gy: FloatArray) -> FloatArray:
    """Planar distance from grid points to a (turned) box's footprint, 0 inside."""
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    dx, dy = gx - box.center[0], gy - box.center[1]
    lx, ly = c * dx + s * dy, -s * dx + c * dy
    ex = np.maximum(np.abs(lx) - box.size[0] / 2, 0.0)
    ey = np.maximum(np.abs(ly) - box.size[1] / 2, 0.0)
    result: FloatArray = np.hypot(ex, ey)
    return result


@dataclass
class Capture:
    """One inspection the robot made."""

    fixture_id: str
    view: tuple[float, float, float, float]
    outcome: str
    keyframes_before: int
    graph_after: list[Node]


@dataclass
class RolloutResult:
    """What one rollout did and what the memory holds at its end."""

    scenario: str
    seed: int
    order: str
    via_service: bool
    path: list[tuple[float, float]] = field(default_factory=list)
    keyframes: list[tuple[float, float, float]] = field(default_factory=list)  # x, y, travelled
    captures: list[Capture] = field(default_factory=list)
    decisions: list[dict[str, Any]] = field(default_factory=list)
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


class Robot:
    """The simulated robot of one rollout: its pose, camera, detector and the memory it feeds."""

    def __init__(
        self,
        scenario: Scenario,
        seed: int,
        memory: Memory,
        settings: RolloutSettings,
        robot_radius_m: float,
        result: RolloutResult,
    ) -> None:
        self.scenario, self.seed, self.memory, self.settings = scenario, seed, memory, settings
        timeline = Timeline(scenario)
        self.world = timeline.world(0)
        self.rng = run_rng(scenario, seed)
        self.detector = RealisticDetector(scenario, self.rng)
        self.camera = scenario.camera.model()
        self.eye_height = scenario.camera.eye_height
        self.free = FreeSpace(self.world, robot_radius_m, settings.grid_m)
        assert scenario.trajectory is not None
        first = scenario.trajectory.points[0]
        self.x, self.y = first.at[0], first.at[1]
        self.yaw = math.atan2(first.look_at[1] - self.y, first.look_at[0] - self.x)
        self.node = self.free.nearest(self.x, self.y)
        self.result = result
        self.frames = 0
        self.travelled = 0.0
        self.since_keyframe = 0.0
        result.path.append((self.x, self.y))

    @property
    def pose(self) -> ViewPose:
        return ViewPose(x=self.x, y=self.y, yaw=_wrap(self.yaw))

    @property
    def keyframes_left(self) -> int:
        return self.settings.keyframe_budget - len(self.result.keyframes)

    def frame(self, yaw: float, pitch: float, input_scale: float) -> dict[str, Any]:
        """Render, detect and encode one frame at the robot's position."""
        eye = np.array([self.x, self.y, self.eye_height])
        forward = np.array(
            [math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw), math.sin(pitch)]
        )
        pose = look_at(eye, eye + forward)
        view = render(self.world, self.camera, pose)
        detections = self.detector.detect(view, self.world, self.frames, self.rng, input_scale)
        depth = view.depth
        if self.scenario.detector.depth_noise == "kinect":
            depth = add_kinect_noise(depth, self.rng)
        frame_id = f"{self.scenario.name}-s{self.seed}-k{self.frames:05d}"
        timestamp = self.frames * self.scenario.frame_period
        self.frames += 1
        return make_frame(frame_id, timestamp, self.camera, pose, depth, detections)

    def keyframe(self, yaw: float) -> None:
        """One semantic keyframe (far-range detector), posted as a one-frame batch."""
        if self.keyframes_left <= 0:
            return
        self.yaw = yaw
        pitch = math.radians(self.settings.keyframe_pitch_deg)
        frame = self.frame(yaw, pitch, self.scenario.detector.far_range_input_scale)
        self.memory.post_batch(make_batch(frame["frame_id"], [frame]))
        self.result.keyframes.append((self.x, self.y, self.travelled))
        self.since_keyframe = 0.0

    def look_around(self, facing: float | None = None) -> None:
        """Turn in place, one keyframe per step, starting towards `facing`."""
        start = self.yaw if facing is None else facing
        n = self.settings.look_around_views
        for k in range(n):
            self.keyframe(start + 2 * math.pi * k / n)

    def drive_to(self, x: float, y: float) -> None:
        """Follow the shortest true-free path, posting keyframes along it."""
        nodes = self.free.path(self.node, x, y)
        for node in nodes[1:]:
            nx, ny = self.free.xy(node)
            step = math.hypot(nx - self.x, ny - self.y)
            heading = math.atan2(ny - self.y, nx - self.x) if step > 1e-9 else self.yaw
            self.x, self.y, self.yaw, self.node = nx, ny, heading, node
            self.travelled += step
            self.since_keyframe += step
            self.result.path.append((nx, ny))
            if self.since_keyframe >= self.settings.keyframe_spacing_m:
                self.keyframe(heading)
        self.node = nodes[-1]

    def sweep(self, yaw: float, pitch: float) -> list[dict[str, Any]]:
        """The fixed-base RGB-D sweep of an inspection: primary first, then the alternates."""
        frames = []
        for offset in self.settings.sweep_yaw_deg:
            frames.append(self.frame(yaw + math.radians(offset), pitch, 1.0))
        self.yaw = yaw
        return frames


def _wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


def rollout(
    scenario: Scenario,
    seed: int,
    memory: Memory,
    settings: RolloutSettings | None = None,
    *,
    order: str = "pbdag",
    via_service: bool = False,
    robot_radius_m: float | None = None,
) -> RolloutResult:
    """One closed-loop rollout from an empty memory and an unknown map."""
    settings = settings or RolloutSettings()
    started = time.perf_counter()
    timeline = Timeline(scenario)
    result = RolloutResult(scenario.name, seed, order, via_service)
    result.truth_fixtures = timeline.fixture_truths()
    world = timeline.world(0)
    result.truth_objects = tuple(
        (box.id, box.label, box.center, timeline.placements(0)[box.id].support)
        for box in world.objects
    )
    radius = Params().planner.robot_radius_m if robot_radius_m is None else robot_radius_m
    robot = Robot(scenario, seed, memory, settings, radius, result)
    visits: dict[tuple[int, int], int] = {}
    robot.look_around()
    while True:
        if len(result.decisions) >= settings.max_decisions:
            result.stop_reason = "decision bound reached"
            break
        begun = time.perf_counter()
        step = memory.plan(robot.pose)
        result.plan_ms.append(1000 * (time.perf_counter() - begun))
        result.decisions.append(
            {
                "decision": step.decision,
                "reason": step.reason,
                "fixture_id": step.fixture_id,
                "goal": step.goal,
                "deferred": list(step.deferred),
                "keyframes": len(result.keyframes),
                "robot": (round(robot.x, 2), round(robot.y, 2)),
            }
        )
        if step.decision == "done":
            result.stop_reason = "plan done: " + step.reason
            break
        if step.decision == "inspect":
            assert step.view is not None and step.fixture_id is not None
            budget = settings.inspection_budget
            if budget is not None and len(result.captures) >= budget:
                result.stop_reason = f"inspection budget ({budget}) spent"
                break
            vx, vy, vyaw, vpitch = step.view
            robot.drive_to(vx, vy)
            frames = robot.sweep(vyaw, vpitch)
            capture_id = f"cap-{len(result.captures):03d}"
            view = ViewPose(x=vx, y=vy, yaw=_wrap(vyaw))
            outcome = memory.inspect(capture_id, step.fixture_id, frames, view)
            result.captures.append(
                Capture(step.fixture_id, step.view, outcome, len(result.keyframes), memory.graph())
            )
            continue
        # explore
        if robot.keyframes_left <= 0:
            result.stop_reason = f"keyframe budget ({settings.keyframe_budget}) spent"
            break
        if step.goal is None:
            if visits.get((-1, -1), 0) >= settings.max_visits_per_goal:
                result.stop_reason = "stuck: told to look around where it already looked"
                break
            visits[(-1, -1)] = visits.get((-1, -1), 0) + 1
            robot.look_around()
            continue
        key = (round(step.goal[0] / 0.5), round(step.goal[1] / 0.5))
        visits[key] = visits.get(key, 0) + 1
        if visits[key] > settings.max_visits_per_goal:
            result.stuck_goals.append(step.goal)
            result.stop_reason = f"stuck: frontier goal {step.goal} reached {visits[key] - 1} times"
            break
        robot.drive_to(*step.goal)
        centroid = step.centroid or step.goal
        facing = math.atan2(centroid[1] - robot.y, centroid[0] - robot.x)
        robot.look_around(facing)
    result.final_graph = memory.graph()
    result.final_tracks = memory.tracks()
    result.final_queue = memory.queue()
    result.occupancy = memory.occupancy()
    result.seconds = time.perf_counter() - started
    return result


def main(argv: list[str] | None = None) -> None:
    """Run one rollout in process (or through a service) and print what it did."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("scenario", type=Path)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--via-service", metavar="URL")
    arguments = parser.parse_args(argv)
    scenario = load_scenario(arguments.scenario)
    memory: Memory
    if arguments.via_service:
        memory = ServiceMemory(httpx.Client(base_url=arguments.via_service), scenario.name)
    else:
        memory = InProcessMemory(scenario.name)
    result = rollout(scenario, arguments.seed, memory, via_service=bool(arguments.via_service))
    fixtures = [n for n in result.final_graph if n.kind == "fixture"]
    objects = [n for n in result.final_graph if n.kind == "object"]
    print(
        f"{scenario.name} seed {arguments.seed}: {len(result.keyframes)} keyframes, "
        f"{len(result.captures)} inspections, path {result.path_length_m:.1f} m, "
        f"{len(fixtures)} fixtures, {len(objects)} objects, {result.seconds:.1f} s; "
        f"stop: {result.stop_reason}"
    )


if __name__ == "__main__":
    main()
