"""Closed-loop autonomous rollouts (section 3.4; the paper's Table 3 protocol).

The robot starts with an empty memory and an unknown map at the scenario trajectory's first
point. It asks the memory for the plan and acts on it:

- `explore`: it drives to the frontier's goal (or, with none, turns where it stands) and looks
  around: `look_around_views` keyframes, evenly spaced in yaw;
- `inspect`: it drives to the view, makes a fixed-base RGB-D sweep (the view's heading first,
  then the alternates of `sweep_yaw_deg`) at full detector resolution and posts the inspection
  (the primary view first, alternates for retry; the view it stood at). A capture the memory
  refuses (its target merged into another fixture track while the robot drove, say) records
  nothing: it is no inspection, and the robot asks for the plan again;
- `done`: it stops.

It drives along a shortest path over the simulator's true free space (the room, walls and
fixtures, inflated by the robot's radius: the paper's navigation proxy), while the planner sees
only the map A_t built from what the robot posted. On the way it posts one semantic keyframe
(one-frame batch) every `keyframe_spacing_m` of travel, seen by the far-range detector
(`detector.far_range_input_scale`), within the coarse-discovery budget of 600 keyframes. A
keyframe carries the fixture segmenter's masks only: in the paper's pipeline fine objects come
from fixture-centered captures alone (`keyframe_objects` puts the object detector's output on
keyframes too; the detector runs either way, so both settings see the same random stream).

Section 3.4's VLM steps are a simulated verifier (`sim.verifier`, `verifier_error_rate`):
before each plan it answers every fixture in the memory's verification queue (a confirmed one
gets eta_c, is published, enters Q_t and is inspected like any other), and at each capture it
verifies the target fixture's class (`fixture_verified`: a rejection is a failed capture,
retried from another view).

The memory is either the core in process (`InProcessMemory`: decide/fold for batches, the
planner's `decide_plan`, `decide_inspection` and `decide_verdict`, exactly the functions the
service's routes call) or the service over HTTP (`ServiceMemory`: POST batches, POST /plan,
POST /inspections, GET /verifications and POST /tracks/{id}/verification).
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from core.params import Params
from core.values import ViewPose
from pbdag_client import Client
from sim.camera import look_at
from sim.detector_model import RealisticDetector
from sim.free_space import FreeSpace
from sim.memories import (
    InProcessMemory,
    Memory,
    PlanStep,
    Ranked,
    Refusal,
    ServiceMemory,
)
from sim.render import add_kinect_noise, render
from sim.rollout_records import Capture, RolloutResult, RolloutSettings
from sim.scenario import load_scenario
from sim.scenario_spec import Scenario
from sim.stream import run_rng
from sim.timeline import Timeline
from sim.verifier import (
    SimulatedVerifier,
    answer_verifications,
    parent_verified,
)
from sim.wire import make_batch, make_frame

__all__ = ["Capture", "RolloutResult", "RolloutSettings", "rollout"]

FloatArray = npt.NDArray[np.float64]


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

    def frame(
        self, yaw: float, pitch: float, input_scale: float, objects: bool = True
    ) -> dict[str, Any]:
        """Render, detect and encode one frame at the robot's position; without `objects`, the
        fixture masks alone (the detector still runs, so the random stream is the same)."""
        eye = np.array([self.x, self.y, self.eye_height])
        forward = np.array(
            [math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw), math.sin(pitch)]
        )
        pose = look_at(eye, eye + forward)
        view = render(self.world, self.camera, pose)
        detections = self.detector.detect(view, self.world, self.frames, self.rng, input_scale)
        if not objects:
            detections = [d for d in detections if d.kind == "fixture"]
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
        scale, objects = (
            self.scenario.detector.far_range_input_scale,
            self.settings.keyframe_objects,
        )
        frame = self.frame(yaw, pitch, scale, objects)
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


def _inspect(
    robot: Robot,
    memory: Memory,
    step: PlanStep,
    settings: RolloutSettings,
    visits: dict[tuple[int, int], int],
    result: RolloutResult,
    verifier: SimulatedVerifier | None = None,
) -> str | None:
    """Drive to the plan's view, sweep it and verify the fixture, as one capture; why to stop,
    if the budget is spent."""
    assert step.view is not None and step.fixture_id is not None
    budget = settings.inspection_budget
    if budget is not None and len(result.captures) >= budget:
        return f"inspection budget ({budget}) spent"
    vx, vy, vyaw, vpitch = step.view
    robot.drive_to(vx, vy)
    frames = robot.sweep(vyaw, vpitch)
    capture_id = f"cap-{len(result.captures) + len(result.refused):03d}"
    view = ViewPose(x=vx, y=vy, yaw=_wrap(vyaw))
    verified = parent_verified(verifier, memory, capture_id, step.fixture_id)
    outcome = memory.inspect(capture_id, step.fixture_id, frames, view, verified)
    capture = Capture(
        step.fixture_id,
        step.view,
        outcome,
        len(result.keyframes),
        memory.graph(),
        fixture_verified=verified,
        target=step.target,
    )
    (result.refused if isinstance(outcome, Refusal) else result.captures).append(capture)
    return None


def _explore(
    robot: Robot,
    memory: Memory,
    step: PlanStep,
    settings: RolloutSettings,
    visits: dict[tuple[int, int], int],
    result: RolloutResult,
    verifier: SimulatedVerifier | None = None,
) -> str | None:
    """Drive to the frontier goal and look around; why to stop (budget spent, stuck), if so."""
    if robot.keyframes_left <= 0:
        return f"keyframe budget ({settings.keyframe_budget}) spent"
    if step.goal is None:
        if visits.get((-1, -1), 0) >= settings.max_visits_per_goal:
            return "stuck: told to look around where it already looked"
        visits[(-1, -1)] = visits.get((-1, -1), 0) + 1
        robot.look_around()
        return None
    key = (round(step.goal[0] / 0.5), round(step.goal[1] / 0.5))
    visits[key] = visits.get(key, 0) + 1
    if visits[key] > settings.max_visits_per_goal:
        result.stuck_goals.append(step.goal)
        return f"stuck: frontier goal {step.goal} reached {visits[key] - 1} times"
    robot.drive_to(*step.goal)
    centroid = step.centroid or step.goal
    facing = math.atan2(centroid[1] - robot.y, centroid[0] - robot.x)
    robot.look_around(facing)
    return None


def _terms(entry: Ranked) -> dict[str, Any]:
    """Equation (5)'s terms of one fixture, rounded for the trace."""
    return {
        "fixture_id": entry.fixture_id,
        "score": round(entry.score, 4),
        "uncertainty": round(entry.uncertainty, 4),
        "proximity": round(entry.proximity, 4),
        "terms": {name: round(value, 4) for name, value in entry.terms.items()},
    }


def _decision_line(step: PlanStep, robot: Robot, result: RolloutResult) -> dict[str, Any]:
    """The trace of one plan: the decision, and the ranking of Q_t with equation (4)'s terms."""
    return {
        "decision": step.decision,
        "reason": step.reason,
        "fixture_id": step.fixture_id,
        "goal": step.goal,
        "deferred": list(step.deferred),
        "keyframes": len(result.keyframes),
        "robot": (round(robot.x, 2), round(robot.y, 2)),
        "target": None if step.target is None else _terms(step.target),
        "ranked": [_terms(entry) for entry in step.ranked],
    }


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
    defaults = Params()
    radius = defaults.planner.robot_radius_m if robot_radius_m is None else robot_radius_m
    robot = Robot(scenario, seed, memory, settings, radius, result)
    verifier = (
        SimulatedVerifier(
            world.fixtures, seed, settings.verifier_error_rate, defaults.fixtures.taxonomy
        )
        if settings.verifier
        else None
    )
    visits: dict[tuple[int, int], int] = {}
    robot.look_around()
    while True:
        if len(result.decisions) >= settings.max_decisions:
            result.stop_reason = "decision bound reached"
            break
        result.verdicts += answer_verifications(verifier, memory)
        begun = time.perf_counter()
        step = memory.plan(robot.pose)
        result.plan_ms.append(1000 * (time.perf_counter() - begun))
        result.decisions.append(_decision_line(step, robot, result))
        if step.decision == "done":
            result.stop_reason = "plan done: " + step.reason
            break
        act = _inspect if step.decision == "inspect" else _explore
        stop = act(robot, memory, step, settings, visits, result, verifier)
        if stop is not None:
            result.stop_reason = stop
            break
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
    parser.add_argument(
        "--keyframe-objects", action="store_true", help="keyframes carry fine detections too"
    )
    parser.add_argument("--no-verifier", action="store_true", help="no simulated VLM")
    parser.add_argument("--verifier-error-rate", type=float, default=0.0)
    arguments = parser.parse_args(argv)
    settings = RolloutSettings(
        keyframe_objects=arguments.keyframe_objects,
        verifier=not arguments.no_verifier,
        verifier_error_rate=arguments.verifier_error_rate,
    )
    scenario = load_scenario(arguments.scenario)
    memory: Memory
    if arguments.via_service:
        # A service that wants a token reads it from $PBDAG_TOKEN, as the robot does.
        client = Client(arguments.via_service, os.environ.get("PBDAG_TOKEN"), timeout=60.0)
        memory = ServiceMemory(client, scenario.name)
    else:
        memory = InProcessMemory(scenario.name)
    via_service = bool(arguments.via_service)
    result = rollout(scenario, arguments.seed, memory, settings, via_service=via_service)
    fixtures = [n for n in result.final_graph if n.kind == "fixture"]
    objects = [n for n in result.final_graph if n.kind == "object"]
    print(
        f"{scenario.name} seed {arguments.seed}: {len(result.keyframes)} keyframes, "
        f"{len(result.captures)} inspections ({len(result.refused)} refused), path {result.path_length_m:.1f} m, "
        f"{len(fixtures)} fixtures, {len(objects)} objects, {len(result.verdicts)} verdicts, "
        f"{result.seconds:.1f} s; "
        f"stop: {result.stop_reason}"
    )


if __name__ == "__main__":
    main()
