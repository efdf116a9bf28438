"""The occupancy map as the planner reads it around one robot pose (section 3.4).

- Clearance: the distance from each cell to the nearest occupied cell (a Euclidean distance
  transform).
- Traversable cells: known free and at least the robot radius clear of occupied cells (the map
  inflated by the robot radius), on a travel grid `travel_cell_factor` map cells wide.
- Travel distance D_t from the robot: Dijkstra over the 8-connected traversable travel cells.
- Line of sight on the map, and frontiers (Yamauchi): clusters of free cells bordering unknown
  ones.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from core.occupancy import CODE_FREE, CODE_OCCUPIED, CODE_UNKNOWN, MapGeometry, OccupancyGrid
from core.params import PlannerParams
from core.values import ViewPose

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class Frontier:
    """A cluster of free cells bordering unknown ones: its size, centroid and goal."""

    size: int  # cells
    centroid: tuple[float, float]  # world x, y
    goal: tuple[float, float] | None  # the reachable travel cell nearest the centroid
    travel_m: float | None  # D_t to the goal; None when unreachable


class Navigation:
    """The map around one robot pose: codes, clearance, traversability and travel distances.

    Fine arrays are indexed (row, col) from `origin` in the scene's grid; the travel grid's
    cell (R, C) holds fine rows k*R .. k*R + k - 1 and columns likewise.
    """

    def __init__(
        self,
        grid: OccupancyGrid,
        geometry: MapGeometry,
        robot: ViewPose,
        params: PlannerParams,
    ) -> None:
        self.geometry = geometry
        self.params = params
        self.robot = robot
        res = geometry.resolution_m
        k = self.factor = params.travel_cell_factor
        robot_row, robot_col, _inside = geometry.cell_of(np.array([robot.x]), np.array([robot.y]))
        rows, cols = grid.shape
        # The window: the known map and the robot's cell, a travel cell of unknown around it,
        # aligned to the travel grid.
        r0 = min(int(robot_row[0]), grid.origin[0] if rows else int(robot_row[0])) - k
        c0 = min(int(robot_col[0]), grid.origin[1] if cols else int(robot_col[0])) - k
        r1 = max(int(robot_row[0]), grid.origin[0] + rows - 1) + k
        c1 = max(int(robot_col[0]), grid.origin[1] + cols - 1) + k
        r0, c0 = r0 // k * k, c0 // k * k
        r1, c1 = (r1 // k + 1) * k, (c1 // k + 1) * k
        self.origin = (r0, c0)
        codes = np.full((r1 - r0, c1 - c0), CODE_UNKNOWN, dtype=np.uint8)
        if rows:
            dr, dc = grid.origin[0] - r0, grid.origin[1] - c0
            codes[dr : dr + rows, dc : dc + cols] = grid.codes()
        self.codes = codes
        self.occupied: BoolArray = codes == CODE_OCCUPIED
        self.free: BoolArray = codes == CODE_FREE
        # Clearance of a cell: from its centre to the nearest occupied cell's edge.
        if self.occupied.any():
            edt = ndimage.distance_transform_edt(~self.occupied)
            self.clearance: FloatArray = np.maximum(np.asarray(edt) * res - res / 2, 0.0)
        else:
            self.clearance = np.full(codes.shape, np.inf)
        traversable = self.free & (self.clearance >= params.robot_radius_m)
        shape = (codes.shape[0] // k, codes.shape[1] // k)
        # Known-free travel cells clear of obstacles by the robot radius: where views may be.
        self.known_ok: BoolArray = traversable.reshape(shape[0], k, shape[1], k).all(axis=(1, 3))
        # The robot stands where it is: the cells under its footprint that are not occupied
        # are traversable (known or not), so that it can move off them.
        self.robot_cell = (int(robot_row[0]) - r0, int(robot_col[0]) - c0)
        traversable |= self._disc(self.robot_cell, params.robot_radius_m) & ~self.occupied
        traversable[self.robot_cell] = not self.occupied[self.robot_cell]
        self.travel_ok: BoolArray = traversable.reshape(shape[0], k, shape[1], k).all(axis=(1, 3))
        start = (self.robot_cell[0] // k, self.robot_cell[1] // k)
        self.travel_ok[start] = not self.occupied[self.robot_cell]
        self.travel: FloatArray = self._distances(start)

    def _disc(self, cell: tuple[int, int], radius_m: float) -> BoolArray:
        rows, cols = np.ogrid[: self.codes.shape[0], : self.codes.shape[1]]
        res = self.geometry.resolution_m
        inside: BoolArray = (rows - cell[0]) ** 2 + (cols - cell[1]) ** 2 <= (radius_m / res) ** 2
        return inside

    def _distances(self, start: tuple[int, int]) -> FloatArray:
        """D_t over the travel grid (metres; inf where unreachable)."""
        ok = self.travel_ok
        height, width = ok.shape
        step = self.geometry.resolution_m * self.factor
        index = np.arange(height * width).reshape(height, width)
        sources, targets, weights = [], [], []
        for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
            a = (slice(0, height - dr), slice(max(0, -dc), width - max(0, dc)))
            b = (slice(dr, height), slice(max(0, dc), width + min(0, dc)))
            both = ok[a] & ok[b]
            if dr and dc:  # no corner cutting: both orthogonal neighbours traversable
                both &= ok[a[0], b[1]] & ok[b[0], a[1]]
            sources.append(index[a][both])
            targets.append(index[b][both])
            weights.append(np.full(int(both.sum()), step * math.hypot(dr, dc)))
        graph = csr_matrix(
            (np.concatenate(weights), (np.concatenate(sources), np.concatenate(targets))),
            shape=(height * width, height * width),
        )
        distances = dijkstra(graph, directed=False, indices=index[start])
        result: FloatArray = np.asarray(distances, dtype=np.float64).reshape(height, width)
        return result

    # -- travel cells --------------------------------------------------------------------------

    def travel_centers(self) -> tuple[FloatArray, FloatArray]:
        """World x, y of every travel cell's centre, (rows, cols) arrays."""
        k = self.factor
        rows = np.arange(self.travel.shape[0]) * k + (k - 1) / 2 + self.origin[0]
        cols = np.arange(self.travel.shape[1]) * k + (k - 1) / 2 + self.origin[1]
        x, y = self.geometry.center_of(rows[:, None], cols[None, :])
        return np.broadcast_to(x, self.travel.shape), np.broadcast_to(y, self.travel.shape)

    def travel_cell_of(self, x: float, y: float) -> tuple[int, int] | None:
        """The travel cell holding a world point, None outside the window."""
        row, col, inside = self.geometry.cell_of(np.array([x]), np.array([y]))
        r, c = int(row[0]) - self.origin[0], int(col[0]) - self.origin[1]
        if not inside[0] or not (0 <= r < self.codes.shape[0] and 0 <= c < self.codes.shape[1]):
            return None
        return r // self.factor, c // self.factor

    def clearance_at(self, x: FloatArray, y: FloatArray) -> FloatArray:
        """Clr at world points (0 outside the window)."""
        rows, cols, keep = self._fine(x, y)
        clearance = np.zeros(x.shape)
        clearance[keep] = self.clearance[rows[keep], cols[keep]]
        return clearance

    def _fine(self, x: FloatArray, y: FloatArray) -> tuple[IntArray, IntArray, BoolArray]:
        """Window rows and columns of finite world points, and whether inside the window."""
        res, half = self.geometry.resolution_m, self.geometry.side // 2
        col = np.floor(x / res).astype(np.int64) + (half - self.origin[1])
        row = np.floor(y / res).astype(np.int64) + (half - self.origin[0])
        height, width = self.codes.shape
        keep = (row >= 0) & (row < height) & (col >= 0) & (col < width)
        return np.where(keep, row, 0), np.where(keep, col, 0), keep

    # -- line of sight -------------------------------------------------------------------------

    def line_of_sight(
        self,
        start: FloatArray,
        end: FloatArray,
        ignore: tuple[float, float, float, float],
    ) -> BoolArray:
        """Per pair of (n, 2) world points: no occupied cell on the segment between them,
        except inside `ignore` (x min, y min, x max, y max: the target's own footprint)."""
        if start.shape[0] == 0:
            return np.zeros(0, dtype=bool)
        step = self.geometry.resolution_m / 2
        length = np.hypot(*(end - start).T)
        count = math.ceil(float(length.max()) / step) + 1
        t = np.linspace(0.0, 1.0, count)
        x = start[:, 0, None] + (end[:, 0] - start[:, 0])[:, None] * t[None, :]
        y = start[:, 1, None] + (end[:, 1] - start[:, 1])[:, None] * t[None, :]
        rows, cols, keep = self._fine(x, y)
        blocked = keep & self.occupied[rows, cols]
        blocked &= ~((x >= ignore[0]) & (x <= ignore[2]) & (y >= ignore[1]) & (y <= ignore[3]))
        clear: BoolArray = np.logical_not(np.any(blocked, axis=1))
        return clear

    # -- frontiers -----------------------------------------------------------------------------

    def frontiers(self, min_cells: int) -> list[Frontier]:
        """Frontier clusters of at least `min_cells`, largest first, each with its goal."""
        clusters = FrontierCells.of(self.codes, self.origin, self.geometry)
        goals = self._frontier_goals(clusters)
        found = [
            Frontier(
                size, centroid, None if goal is None else goal[0], None if goal is None else goal[1]
            )
            for size, centroid, goal in zip(clusters.sizes, clusters.centroids, goals, strict=True)
            if size >= min_cells
        ]
        return sorted(found, key=lambda f: (-f.size, f.centroid))

    def _frontier_goals(
        self, clusters: FrontierCells
    ) -> list[tuple[tuple[float, float], float] | None]:
        """Per cluster, the reachable travel cell (holding or beside one of its cells) nearest
        its centroid, with D_t there."""
        k = self.factor
        height, width = self.travel.shape
        centers_x, centers_y = self.travel_centers()
        parts = []
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                r, c = clusters.rows // k + dr, clusters.cols // k + dc
                keep = (r >= 0) & (r < height) & (c >= 0) & (c < width)
                r, c, i = r[keep], c[keep], clusters.ids[keep]
                reachable = np.isfinite(self.travel[r, c])
                parts.append((r[reachable], c[reachable], i[reachable]))
        r = np.concatenate([p[0] for p in parts])
        c = np.concatenate([p[1] for p in parts])
        i = np.concatenate([p[2] for p in parts])
        goals: list[tuple[tuple[float, float], float] | None] = [None] * len(clusters.sizes)
        if i.size == 0:
            return goals
        x, y = centers_x[r, c], centers_y[r, c]
        cx = np.array([centroid[0] for centroid in clusters.centroids])
        cy = np.array([centroid[1] for centroid in clusters.centroids])
        distance = np.hypot(x - cx[i], y - cy[i])
        order = np.lexsort((c, r, distance, i))  # per cluster: nearest, then by cell
        first = order[np.concatenate(([True], i[order][1:] != i[order][:-1]))]
        for j in first:
            goals[int(i[j])] = ((float(x[j]), float(y[j])), float(self.travel[r[j], c[j]]))
        return goals


@dataclass(frozen=True)
class FrontierCells:
    """Frontier cells of a window of the map, clustered: free cells with an unknown
    4-neighbour (outside the window is unknown), in 8-connected clusters."""

    rows: IntArray  # window rows and columns of the frontier cells
    cols: IntArray
    ids: IntArray  # each cell's cluster
    sizes: list[int]  # per cluster
    centroids: list[tuple[float, float]]  # per cluster, world x, y

    @classmethod
    def of(
        cls, codes: npt.NDArray[np.uint8], origin: tuple[int, int], geometry: MapGeometry
    ) -> FrontierCells:
        """The frontier clusters of a window of codes whose cell (0, 0) is `origin`."""
        unknown = np.pad(codes == CODE_UNKNOWN, 1, constant_values=True)
        cross = ndimage.generate_binary_structure(2, 1)
        bordering = np.asarray(ndimage.binary_dilation(unknown, structure=cross), dtype=bool)
        frontier = (codes == CODE_FREE) & bordering[1:-1, 1:-1]
        labels, count = ndimage.label(frontier, structure=np.ones((3, 3), dtype=bool))
        rows, cols = np.nonzero(labels)
        ids = (labels[rows, cols] - 1).astype(np.int64)
        sizes = np.bincount(ids, minlength=count)
        centroid_row = np.bincount(ids, weights=rows, minlength=count) / np.maximum(sizes, 1)
        centroid_col = np.bincount(ids, weights=cols, minlength=count) / np.maximum(sizes, 1)
        cx, cy = geometry.center_of(centroid_row + origin[0], centroid_col + origin[1])
        return cls(
            rows.astype(np.int64),
            cols.astype(np.int64),
            ids,
            [int(size) for size in sizes],
            [(float(x), float(y)) for x, y in zip(cx, cy, strict=True)],
        )


def frontier_clusters(grid: OccupancyGrid, geometry: MapGeometry, min_cells: int) -> list[Frontier]:
    """The map's frontier clusters (size and centroid; no goal without a robot), largest first."""
    clusters = FrontierCells.of(grid.codes(), grid.origin, geometry)
    found = [
        Frontier(size, centroid, None, None)
        for size, centroid in zip(clusters.sizes, clusters.centroids, strict=True)
        if size >= min_cells
    ]
    return sorted(found, key=lambda f: (-f.size, f.centroid))
