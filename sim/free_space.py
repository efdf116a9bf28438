"""The simulator's true free space, on which the simulated robot drives (the paper's navigation
proxy): the room minus walls and fixtures, inflated by the robot's radius. The planner never
sees it; it sees only the map A_t built from what the robot posted.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from scipy import sparse
from scipy.sparse import csgraph

from sim.world import Box, World

FloatArray = npt.NDArray[np.float64]


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
