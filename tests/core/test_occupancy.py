"""The occupancy map A_t: cells from a synthetic depth frame, the fold rule, runs, frontiers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from core.decide import decide
from core.errors import InvalidParams
from core.events import OccupancyEvidence
from core.evolve import fold
from core.navigation import Navigation
from core.observation import Batch, Frame, Intrinsics
from core.occupancy import (
    CODE_FREE,
    CODE_OCCUPIED,
    CODE_UNKNOWN,
    MapGeometry,
    OccupancyGrid,
    flat_of,
    runs_of,
)
from core.occupancy_evidence import frame_cells, occupancy_evidence
from core.params import Params
from core.state import SceneState
from core.values import ViewPose
from tests.core.maps import grid_of

PARAMS = Params()
GEOMETRY = MapGeometry.of(PARAMS.occupancy)  # 5 cm cells, 4000 per side
# Every 4th pixel at 250 px focal length: 4.8 cm apart at 3 m, so every 5 cm cell of the wall
# gets a point.
INTRINSICS = Intrinsics(width=320, height=240, fx=250.0, fy=250.0, cx=159.5, cy=119.5)
EYE_HEIGHT = 1.0
WALL_X = 3.01  # inside the cell x in [3.00, 3.05), clear of its border


def level_pose(x: float = 0.0, y: float = 0.0) -> np.ndarray:
    """A camera at (x, y, 1 m) looking along +x, level (OpenCV axes: x right = -y world,
    y down = -z world, z forward = +x world)."""
    pose = np.eye(4)
    pose[:3, :3] = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]
    pose[:3, 3] = (x, y, EYE_HEIGHT)
    return pose


def wall_and_floor_depth(wall: float = WALL_X) -> np.ndarray:
    """A wall `wall` metres ahead of the camera, facing it, and the floor (z = 0) below it."""
    v = np.arange(INTRINSICS.height, dtype=np.float64)[:, None]
    depth = np.full((INTRINSICS.height, INTRINSICS.width), wall)
    below = v > INTRINSICS.cy
    # A pixel row below the horizon meets the floor at depth 1 m * fy / (v - cy).
    with np.errstate(divide="ignore"):
        floor = EYE_HEIGHT * INTRINSICS.fy / (v - INTRINSICS.cy)
    depth = np.where(below & (floor < wall), floor, depth)
    return depth.astype(np.float32)


def wall_frame(frame_id: str = "f0", t: float = 0.0) -> Frame:
    return Frame(frame_id, t, INTRINSICS, level_pose(), wall_and_floor_depth())


def code_at(grid: OccupancyGrid, x: float, y: float) -> int:
    row, col, inside = GEOMETRY.cell_of(np.array([x]), np.array([y]))
    assert inside[0]
    r, c = int(row[0]) - grid.origin[0], int(col[0]) - grid.origin[1]
    if not (0 <= r < grid.shape[0] and 0 <= c < grid.shape[1]):
        return CODE_UNKNOWN
    return int(grid.codes()[r, c])


def test_a_wall_seen_over_the_floor_is_occupied_behind_free_space() -> None:
    evidence = occupancy_evidence([wall_frame()], PARAMS.occupancy)
    assert evidence is not None
    grid = fold(SceneState(), [evidence]).occupancy
    half_width = WALL_X * (INTRINSICS.width / 2) / INTRINSICS.fx  # 1.93 m at the wall
    # The wall's cells (x in [3.00, 3.05)) across the field of view are occupied.
    for y in (-1.8, -1.0, 0.0, 1.0, 1.8):
        assert code_at(grid, WALL_X, y) == CODE_OCCUPIED, y
    # Between the camera and the wall: free; behind the wall and outside the view: unknown.
    for x in (0.5, 1.5, 2.5, 2.9):
        assert code_at(grid, x, 0.0) == CODE_FREE, x
    assert code_at(grid, 2.0, 0.5 * 2.0 * half_width / WALL_X) == CODE_FREE
    assert code_at(grid, 4.0, 0.0) == CODE_UNKNOWN
    assert code_at(grid, 1.5, 2.5) == CODE_UNKNOWN  # 59 deg off axis; the half-FOV is 32.6
    assert code_at(grid, -0.5, 0.0) == CODE_UNKNOWN  # behind the camera
    # Occupied cells are the wall's alone: a band 1 cell deep over the field of view.
    codes = grid.codes()
    rows, cols = np.nonzero(codes == CODE_OCCUPIED)
    x, y = GEOMETRY.center_of(rows + grid.origin[0], cols + grid.origin[1])
    assert np.all(np.isclose(x, 3.025))
    assert float(np.abs(y).max()) <= half_width + 0.05
    assert len(rows) == pytest.approx(2 * half_width / 0.05, abs=3)


def test_depth_noise_in_front_of_a_wall_does_not_grow_it() -> None:
    # The wall's depth with axial noise: a few pixels read 25 cm short (1 in 50, scattered).
    depth = wall_and_floor_depth()
    rng = np.random.default_rng(3)
    wall = depth >= WALL_X - 1e-3
    outliers = wall & (rng.random(depth.shape) < 0.02)
    depth[outliers] -= 0.25
    noisy = Frame("f0", 0.0, INTRINSICS, level_pose(), depth)
    # Each sampled depth is a median over 3 x 3 pixels: the wall stays one cell deep.
    _free, occupied = frame_cells(noisy, PARAMS.occupancy)
    rows, cols = np.divmod(occupied, GEOMETRY.side)
    x, _y = GEOMETRY.center_of(rows, cols)
    assert np.all(np.isclose(x, 3.025))
    # Raw pixels (window 1) put the outliers' cells in front of it, where no ray clears them.
    raw = Params.from_dict({"occupancy": {"depth_median_px": 1}}).occupancy
    _free, occupied = frame_cells(noisy, raw)
    rows, cols = np.divmod(occupied, GEOMETRY.side)
    x, _y = GEOMETRY.center_of(rows, cols)
    assert np.any(x < 2.9)
    with pytest.raises(InvalidParams, match=r"params\.occupancy: depth_median_px must be odd"):
        Params.from_dict({"occupancy": {"depth_median_px": 2}})


def test_points_outside_the_height_band_are_not_obstacles() -> None:
    # The wall spans z = 1 m +- 119.5 / 250 x 3.01 m, up to 2.44 m: all of it is below a band
    # from 2.9 m, "floor" to such a robot: no obstacle, and rays reach it.
    high = Params.from_dict({"occupancy": {"band_min_z_m": 2.9, "band_max_z_m": 3.0}})
    free, occupied = frame_cells(wall_frame(), high.occupancy)
    assert occupied.size == 0
    assert free.size > 0


def test_no_valid_depth_or_a_pose_beyond_the_map_says_nothing() -> None:
    empty = Frame("e", 0.0, INTRINSICS, level_pose(), np.zeros((240, 320), np.float32))
    assert occupancy_evidence([empty], PARAMS.occupancy) is None
    far = Frame("far", 0.0, INTRINSICS, level_pose(x=9000.0), wall_and_floor_depth())
    assert occupancy_evidence([far], PARAMS.occupancy) is None


def test_decide_emits_the_batch_evidence_and_fold_applies_the_clamped_rule() -> None:
    state = SceneState()
    events = decide(state, Batch("b0", (wall_frame("f0", 5.0),)))
    [evidence] = [e for e in events if isinstance(e, OccupancyEvidence)]
    assert evidence.timestamp == 5.0 and evidence.side == 4000 and evidence.resolution_m == 0.05
    state = fold(state, events)
    assert state.clock == 5.0
    row, col, _inside = GEOMETRY.cell_of(np.array([WALL_X]), np.array([0.0]))
    r, c = int(row[0]) - state.occupancy.origin[0], int(col[0]) - state.occupancy.origin[1]
    assert state.occupancy.values[r, c] == 2  # occupied_hit
    free_cell = GEOMETRY.cell_of(np.array([1.0]), np.array([0.0]))
    fr = int(free_cell[0][0]) - state.occupancy.origin[0]
    fc = int(free_cell[1][0]) - state.occupancy.origin[1]
    assert state.occupancy.values[fr, fc] == -1  # free_hit, clamped at min_value
    # Three more batches: the wall clamps at max_value 6; the free cell stays at -1.
    for i in range(3):
        state = fold(state, decide(state, Batch(f"b{i + 1}", (wall_frame(f"f{i + 1}"),))))
    assert state.occupancy.values[r, c] == 6 and state.occupancy.values[fr, fc] == -1
    # Free rays through the wall cell: 6 batches take it to 0, free.
    flat = (int(row[0]) * 4000 + int(col[0]),)
    through = OccupancyEvidence(
        resolution_m=0.05, side=4000, free=(flat[0], 1), occupied=(), timestamp=9.0
    )
    for expected in (5, 4, 3, 2, 1, 0):
        state = fold(state, [through])
        assert state.occupancy.values[r, c] == expected
    assert state.occupancy.codes()[r, c] == CODE_FREE and state.clock == 9.0


def test_within_a_batch_occupied_wins_over_free() -> None:
    # The second frame stands 1 m further back and sees a wall 2 m ahead of it, at x = 1.01 m,
    # where the first frame's rays pass: the batch says occupied there.
    near = Frame("near", 0.0, INTRINSICS, level_pose(x=-1.0), wall_and_floor_depth(2.01))
    row, col, _inside = GEOMETRY.cell_of(np.array([1.01]), np.array([0.0]))
    cell = int(row[0]) * GEOMETRY.side + int(col[0])
    first_free, _ = frame_cells(wall_frame(), PARAMS.occupancy)
    _, second_occupied = frame_cells(near, PARAMS.occupancy)
    assert cell in first_free and cell in second_occupied
    evidence = occupancy_evidence([wall_frame(), near], PARAMS.occupancy)
    assert evidence is not None
    free, occupied = flat_of(evidence.free), flat_of(evidence.occupied)
    assert cell in occupied and cell not in free
    assert np.intersect1d(free, occupied).size == 0


@given(st.lists(st.integers(min_value=0, max_value=5000), max_size=300))
def test_runs_round_trip(cells: list[int]) -> None:
    flat = np.unique(np.asarray(cells, dtype=np.int64))
    runs = runs_of(flat)
    assert all(isinstance(value, int) and value >= 0 for value in runs)
    assert np.array_equal(flat_of(runs), flat)


def test_runs_are_compact_for_contiguous_cells() -> None:
    assert runs_of(np.arange(100, 200, dtype=np.int64)) == (100, 100)
    assert runs_of(np.array([3, 4, 5, 9], dtype=np.int64)) == (3, 3, 3, 1)
    with pytest.raises(ValueError):
        flat_of((1, 0))


def test_frontiers_are_clusters_of_free_cells_beside_unknown_ones() -> None:
    grid = grid_of(
        [
            "############",
            "#..........?",
            "#..........?",
            "#..........?",
            "#..........#",
            "#..........#",
            "#....?.....#",
            "#..........#",
            "############",
        ]
    )
    robot = ViewPose(x=0.125, y=0.125, yaw=0.0)  # cell (2, 2)
    navigation = Navigation(grid, GEOMETRY, robot, Params.from_dict({}).planner)
    frontiers = navigation.frontiers(min_cells=1)
    # The open east side: 3 cells of column 10 beside the unknown column 11; the hole in the
    # floor: its 4 neighbours (an isolated unknown cell is a frontier too, of 4 cells).
    assert sorted(f.size for f in frontiers) == [3, 4]
    east = next(f for f in frontiers if f.size == 3)
    # Column 10, rows 5-7 from the bottom: centre x = 10.5 * 0.05, y = 6.5 * 0.05.
    assert east.centroid == pytest.approx((0.525, 0.325))
    hole = next(f for f in frontiers if f.size == 4)
    assert hole.centroid == pytest.approx((0.275, 0.125))
    # With the default 0.25 m robot radius nothing in a 0.5 m room is traversable but the
    # robot's own footprint: the frontiers are seen, not reachable from there.
    assert navigation.frontiers(min_cells=4)[0].size == 4


def test_a_room_seen_from_inside_has_a_reachable_frontier_at_its_open_door() -> None:
    # A 4 m x 3 m room, walled but for a 1 m door on the east side that opens on the unknown.
    lines = ["#" * 80]
    for i in range(58):
        lines.append("#" + "." * 78 + ("?" if 20 <= i < 40 else "#"))
    lines.append("#" * 80)
    grid = grid_of(lines)
    robot = ViewPose(x=0.5, y=1.0, yaw=0.0)
    navigation = Navigation(grid, GEOMETRY, robot, PARAMS.planner)
    [door] = navigation.frontiers(PARAMS.planner.min_frontier_cells)
    assert door.size == 20
    # The door's free cells: column 78 (x centre 3.925), rows 19-38 from the bottom (y 1.45).
    assert door.centroid == pytest.approx((3.925, 1.45))
    assert door.goal is not None and door.travel_m is not None
    # The goal is a 10 cm travel cell beside the door, at least the robot radius clear of the
    # walls; the travel distance is at least the straight line and at most the octile bound.
    assert 3.9 - 0.25 - 0.1 <= door.goal[0] <= 3.95
    assert abs(door.goal[1] - 1.45) <= 0.1
    straight = math.hypot(door.goal[0] - robot.x, door.goal[1] - robot.y)
    assert straight - 1e-9 <= door.travel_m <= straight * 1.083 + 0.1
    # Closing the door: no frontier is left.
    closed = grid_of([line.replace("?", "#") for line in lines])
    assert Navigation(closed, GEOMETRY, robot, PARAMS.planner).frontiers(1) == []
