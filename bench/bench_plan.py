"""Benchmark: the planner's time per decision (section 3.4) on a 20 m x 20 m map at 5 cm, and the
size of the occupancy evidence a batch appends.

The map is a house of nine 6.7 m rooms behind 1 m doors with twelve fixtures, one room still
unknown (frontiers); the plan is decided from 20 robot poses in known free space (u_i, Prox,
candidate views, J, travel by Dijkstra, frontiers). Goal: < 50 ms per decision.
The evidence: one-frame batches of 640 x 480 rendered depth along a walk through a room.
"""

from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import replace

import numpy as np
import orjson

from bench.perf_common import write_results
from bench.records import EvidenceSizes, PlanResult
from core.navigation import Navigation
from core.observation import Frame, Intrinsics
from core.occupancy import UNKNOWN, MapGeometry, OccupancyGrid
from core.occupancy_evidence import occupancy_evidence
from core.params import Params
from core.planner import plan
from core.state import SceneState, Track
from core.values import ViewPose
from sim.camera import CameraModel, look_at
from sim.render import add_kinect_noise, render
from sim.world import Box, World

SIDE_M = 20.0
RES = 0.05
ROOM_M = SIDE_M / 3


def house(rng: np.random.Generator) -> tuple[np.ndarray, list[Track]]:
    """A 400 x 400 map of int8 cell values (rows = y) and the fixtures standing in it."""
    n = round(SIDE_M / RES)
    values = np.full((n, n), -1, dtype=np.int8)  # free
    wall = 2  # cells (10 cm)
    values[:wall, :] = values[-wall:, :] = values[:, :wall] = values[:, -wall:] = 3
    for k in (1, 2):
        at = round(k * ROOM_M / RES)
        values[at : at + wall, :] = 3
        values[:, at : at + wall] = 3
        for j in range(3):  # a 1 m door in every wall segment
            door = round((j + 0.5) * ROOM_M / RES)
            values[at : at + wall, door - 10 : door + 10] = -1
            values[door - 10 : door + 10, at : at + wall] = -1
    fixtures = []
    labels = ("table", "desk", "counter", "shelf")
    for i in range(12):
        room_x, room_y = i % 3, (i // 3) % 3
        cx = (room_x + rng.uniform(0.3, 0.7)) * ROOM_M
        cy = (room_y + rng.uniform(0.3, 0.7)) * ROOM_M
        dx, dy = rng.uniform(0.6, 1.8), rng.uniform(0.5, 1.0)
        c0, c1 = round((cx - dx / 2) / RES), round((cx + dx / 2) / RES)
        r0, r1 = round((cy - dy / 2) / RES), round((cy + dy / 2) / RES)
        values[r0:r1, c0:c1] = 3
        values[r0 + 2 : r1 - 2, c0 + 2 : c1 - 2] = UNKNOWN  # never seen under the top
        center = (float(cx), float(cy), 0.375)
        fixtures.append(
            Track(
                track_id=f"trk-{i + 1:06d}",
                kind="fixture",
                lifecycle="confirmed",
                class_evidence={labels[i % 4]: 5.0, "cabinet": float(rng.uniform(0, 3))},
                existence_logodds=float(rng.uniform(0.5, 4.0)),
                center=center,
                extent=(float(dx), float(dy), 0.75),
                recent_centers=tuple(
                    (cx + float(rng.normal(0, 0.1)), cy + float(rng.normal(0, 0.1)), 0.375)
                    for _ in range(5)
                ),
                batches_observed=int(rng.integers(3, 15)),
                margin_sum=float(rng.uniform(0.1, 1.5)),
                last_observed=float(rng.uniform(0, 500)),
            )
        )
    corner = round(ROOM_M / RES)
    values[-corner + wall :, -corner + wall :] = UNKNOWN  # the north-east room: unexplored
    return values, fixtures


def planning_state(seed: int) -> SceneState:
    values, fixtures = house(np.random.default_rng(seed))
    values.setflags(write=False)
    half = MapGeometry.of(Params().occupancy).side // 2
    return replace(
        SceneState(head_seq=1000),
        tracks={t.track_id: t for t in fixtures},
        occupancy=OccupancyGrid((half, half), values),
        clock=600.0,
    )


def robot_poses(state: SceneState, count: int, seed: int) -> list[ViewPose]:
    """Poses on free cells at least 0.4 m from anything occupied."""
    rng = np.random.default_rng(seed)
    codes = state.occupancy.codes()
    poses: list[ViewPose] = []
    while len(poses) < count:
        row, col = rng.integers(0, codes.shape[0], size=2)
        window = codes[max(0, row - 8) : row + 9, max(0, col - 8) : col + 9]
        if codes[row, col] == 1 and (window == 1).all():
            poses.append(
                ViewPose(x=(col + 0.5) * RES, y=(row + 0.5) * RES, yaw=float(rng.uniform(-3, 3)))
            )
    return poses


def evidence_sizes(frames: int) -> EvidenceSizes:
    """Bytes and time of the occupancy evidence of one-frame 640 x 480 batches."""
    table = Box("table", "table", (4.0, 3.0, 0.375), (1.6, 0.9, 0.75), kind="fixture")
    shelf = Box("shelf", "shelf", (7.5, 5.5, 0.9), (0.4, 1.2, 1.8), kind="fixture")
    world = World(room_size=(8.0, 6.0, 2.6), fixtures=(table, shelf), objects=())
    camera = CameraModel()
    intrinsics = Intrinsics(camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy)
    params = Params().occupancy
    raw = replace(params, depth_median_px=1)  # the same frames without the depth median
    sizes, times, raw_times = [], [], []
    for i in range(frames):
        angle = 2 * np.pi * i / frames
        eye = (4.0 + 2.6 * np.cos(angle), 3.0 + 1.9 * np.sin(angle), 1.3)
        pose = look_at(eye, (4.0, 3.0, 0.6))
        depth = add_kinect_noise(render(world, camera, pose).depth, np.random.default_rng(i))
        frame = Frame(f"f{i}", float(i), intrinsics, pose, depth.astype(np.float32))
        start = time.perf_counter()
        event = occupancy_evidence([frame], params)
        times.append((time.perf_counter() - start) * 1000)
        start = time.perf_counter()
        occupancy_evidence([frame], raw)
        raw_times.append((time.perf_counter() - start) * 1000)
        assert event is not None
        sizes.append(len(orjson.dumps(event.details())))
    return EvidenceSizes(
        frames=frames,
        bytes_per_batch_median=statistics.median(sizes),
        bytes_per_batch_max=max(sizes),
        evidence_ms_per_frame_median=round(statistics.median(times), 2),
        evidence_ms_per_frame_median_raw_depth=round(statistics.median(raw_times), 2),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--decisions", type=int, default=20)
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args()
    state = planning_state(args.seed)
    params = state.params
    geometry = MapGeometry.of(params.occupancy)
    poses = robot_poses(state, args.decisions, args.seed)
    plan(state, poses[0])  # warm-up: imports, caches
    times, navigation_times, decisions = [], [], []
    for pose in poses:
        start = time.perf_counter()
        Navigation(state.occupancy, geometry, pose, params.planner)
        navigation_times.append((time.perf_counter() - start) * 1000)
        start = time.perf_counter()
        decided = plan(state, pose)
        times.append((time.perf_counter() - start) * 1000)
        decisions.append(decided.decision)
    times.sort()
    rows, columns = state.occupancy.shape
    results = PlanResult(
        map_cells=(rows, columns),
        resolution_m=RES,
        fixtures=len(state.tracks),
        decisions=len(times),
        ms_per_decision_median=round(statistics.median(times), 2),
        ms_per_decision_p90=round(times[int(0.9 * (len(times) - 1))], 2),
        ms_per_decision_max=round(times[-1], 2),
        navigation_ms_median=round(statistics.median(navigation_times), 2),
        outcomes={d: decisions.count(d) for d in sorted(set(decisions))},
        goal_ms=50,
        evidence=evidence_sizes(args.frames),
    )
    print(
        f"plan on a {rows} x {columns} map (5 cm), "
        f"{results.fixtures} fixtures: median {results.ms_per_decision_median} ms, "
        f"p90 {results.ms_per_decision_p90} ms, max {results.ms_per_decision_max} ms per "
        f"decision (navigation {results.navigation_ms_median} ms; goal < 50 ms); "
        f"{results.outcomes}"
    )
    evidence = results.evidence
    print(
        f"occupancy evidence of a 640 x 480 one-frame batch: median "
        f"{evidence.bytes_per_batch_median} bytes, max {evidence.bytes_per_batch_max} "
        f"bytes, {evidence.evidence_ms_per_frame_median} ms per frame "
        f"({evidence.evidence_ms_per_frame_median_raw_depth} ms without the depth median)"
    )
    write_results("bench_plan", results)


if __name__ == "__main__":
    main()
