"""Domain -> wire: the occupancy map A_t (section 3.2) as the API serves it, runs or a PNG."""

from __future__ import annotations

import io

import numpy as np
from PIL import Image

from api_schema import Frontier, Occupancy
from core.navigation import Frontier as CoreFrontier
from core.navigation import frontier_clusters
from core.occupancy import CODE_FREE, CODE_OCCUPIED, CODE_UNKNOWN, MapGeometry, OccupancyGrid
from core.state import SceneState


def _known_window(grid: OccupancyGrid) -> tuple[tuple[int, int], np.ndarray]:
    """The codes of the bounding box of the known cells, and its origin (row, col)."""
    codes = grid.codes()
    rows, cols = np.nonzero(codes != CODE_UNKNOWN)
    if rows.size == 0:
        return grid.origin, np.zeros((0, 0), dtype=np.uint8)
    r0, r1, c0, c1 = int(rows.min()), int(rows.max()) + 1, int(cols.min()), int(cols.max()) + 1
    return (grid.origin[0] + r0, grid.origin[1] + c0), codes[r0:r1, c0:c1]


def frontier_out(frontier: CoreFrontier) -> Frontier:
    """A frontier cluster and where to stand to see it."""
    return Frontier(
        size=frontier.size,
        centroid=list(frontier.centroid),
        goal=None if frontier.goal is None else list(frontier.goal),
        travel_m=frontier.travel_m,
    )


def occupancy_out(scene_id: str, state: SceneState) -> Occupancy:
    """The map's known window as (code, count) runs, with its frontier clusters."""
    geometry = MapGeometry.of(state.params.occupancy)
    origin, codes = _known_window(state.occupancy)
    flat = codes.ravel()
    runs: list[int] = []
    if flat.size:
        starts = np.concatenate(([0], np.flatnonzero(flat[1:] != flat[:-1]) + 1))
        lengths = np.diff(np.concatenate((starts, [flat.size])))
        runs = np.column_stack((flat[starts], lengths)).ravel().tolist()
    x0, y0 = geometry.center_of(origin[0], origin[1])
    half = geometry.resolution_m / 2
    counts = np.bincount(flat, minlength=3) if flat.size else np.zeros(3, np.int64)
    min_cells = state.params.planner.min_frontier_cells
    return Occupancy(
        scene_id=scene_id,
        seq=state.head_seq,
        resolution_m=geometry.resolution_m,
        origin=[float(x0) - half, float(y0) - half],
        shape=[int(codes.shape[0]), int(codes.shape[1])],
        encoding="rle",
        cells=runs,
        counts={
            "unknown": int(counts[CODE_UNKNOWN]),
            "free": int(counts[CODE_FREE]),
            "occupied": int(counts[CODE_OCCUPIED]),
        },
        frontiers=[
            frontier_out(f) for f in frontier_clusters(state.occupancy, geometry, min_cells)
        ],
    )


# Grey levels of the PNG (as ROS map_server writes maps): occupied black, free white.
PNG_LEVELS = np.array([205, 254, 0], dtype=np.uint8)  # unknown, free, occupied


def occupancy_png(state: SceneState) -> tuple[bytes, list[float]]:
    """The known window as an 8-bit grey PNG, north (+y) up, and its origin (x, y)."""
    geometry = MapGeometry.of(state.params.occupancy)
    origin, codes = _known_window(state.occupancy)
    if codes.size == 0:
        codes = np.zeros((1, 1), dtype=np.uint8)  # one unknown cell: PNG has no empty image
    image = Image.fromarray(np.ascontiguousarray(PNG_LEVELS[codes][::-1]))
    buffer = io.BytesIO()
    image.save(buffer, format="PNG")
    x0, y0 = geometry.center_of(origin[0], origin[1])
    half = geometry.resolution_m / 2
    return buffer.getvalue(), [float(x0) - half, float(y0) - half]
