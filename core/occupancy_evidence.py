"""What one batch's depth says of the occupancy map A_t (section 3.2), as one event.

Per frame, every `pixel_stride`-th valid depth pixel is back-projected into the world. Points in
the robot's height band mark their cells occupied. Free cells come from rays: the points are
binned by their bearing from the camera, as a laser scan is made from depth, and each bin is
clear from the camera up to its nearest obstacle point (stopped a little short), or, with no
obstacle in it, up to its farthest floor point; points above the band clear nothing (the floor
under a ceiling point was not seen). The disc the robot stands on, under the camera, is free.
Over the frames of a batch occupied wins over free.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.ndimage import minimum_filter1d

from core.compiled import compiled
from core.events import OccupancyEvidence
from core.geometry import backproject_pixels, camera_to_world
from core.observation import Frame
from core.occupancy import MapGeometry, runs_of
from core.params import OccupancyParams

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]


def frame_cells(frame: Frame, params: OccupancyParams) -> tuple[IntArray, IntArray]:
    """Flat indices of the cells one frame sees free and occupied (each sorted, unique)."""
    stride = params.pixel_stride
    height, width = frame.depth.shape
    rows = np.arange(0, height, stride)
    cols = np.arange(0, width, stride)
    flat_index = (rows[:, None] * width + cols[None, :]).ravel().astype(np.intp)
    depth = _median_depth(frame.depth, rows, cols, params.depth_median_px)
    valid = np.isfinite(depth) & (depth >= params.min_range_m) & (depth <= params.max_range_m)
    none = np.zeros(0, np.int64)
    if not valid.any():
        return none, none
    points = camera_to_world(
        backproject_pixels(flat_index[valid], depth[valid], frame.intrinsics), frame.pose
    )
    window = _Window(frame.pose[:3, 3], params)
    dx, dy = points[:, 0] - window.camera[0], points[:, 1] - window.camera[1]
    reach = np.hypot(dx, dy)
    # Within the sensor's range of the camera (odd intrinsics can spread points wider).
    near = np.isfinite(reach) & (reach <= params.max_range_m) & np.isfinite(points[:, 2])
    if not near.all():  # (almost always all are: then nothing to copy)
        points, dx, dy, reach = points[near], dx[near], dy[near], reach[near]
    obstacle = (points[:, 2] >= params.band_min_z_m) & (points[:, 2] <= params.band_max_z_m)
    floor = points[:, 2] < params.band_min_z_m
    occupied = window.cells(points[:, 0], points[:, 1], obstacle)
    # Neighbouring sampled pixels are stride / f radians apart; a bin narrower than that may
    # hold a floor point behind an obstacle whose points fell in the bins beside it.
    spread = params.pixel_stride / min(frame.intrinsics.fx, frame.intrinsics.fy)
    rays_x, rays_y = _rays(window.camera, dx, dy, reach, obstacle, floor, spread, params)
    foot_x, foot_y = _footprint(window.camera, params)
    free = window.cells(np.concatenate((rays_x, foot_x)), np.concatenate((rays_y, foot_y)))
    return np.setdiff1d(free, occupied, assume_unique=True), occupied


def _median_depth(
    depth: npt.NDArray[Any], rows: IntArray, cols: IntArray, window: int
) -> FloatArray:
    """The depth at the sampled pixels, each the median of the valid depths in the window
    around it (a pixel without depth stays without: holes are not filled).

    Axial noise puts a few points of every surface in front of it; each marks its cell occupied,
    and no free ray clears it (rays stop at the nearest point of their bearing), so over a run
    the obstacles' boundaries would grow by the noise's extremes (10 cm at 4 m, measured). The
    median keeps edges where a plain mean would blur them. It is the lower median of the
    window's usable depths (positive and finite), the window clamped at the image's edges.
    """
    if window <= 1:
        return depth[rows[:, None], cols[None, :]].astype(np.float64).ravel()
    medians: FloatArray = _lower_usable_medians(depth, rows, cols, window // 2)
    return medians


@compiled(inline="always")
def _usable(value: float) -> bool:  # pragma: no cover - compiled
    return (value > 0) & (value < np.inf)  # NaN compares false


@compiled(inline="always")
def _ordered(a: float, b: float) -> tuple[float, float]:  # pragma: no cover - compiled
    return min(a, b), max(a, b)


@compiled()
def _median_of_nine(
    p0: float,
    p1: float,
    p2: float,
    p3: float,
    p4: float,
    p5: float,
    p6: float,
    p7: float,
    p8: float,
) -> float:  # pragma: no cover - compiled
    """The median of nine values by Paeth's 19 compare-exchanges (no branch to mispredict)."""
    p1, p2 = _ordered(p1, p2)
    p4, p5 = _ordered(p4, p5)
    p7, p8 = _ordered(p7, p8)
    p0, p1 = _ordered(p0, p1)
    p3, p4 = _ordered(p3, p4)
    p6, p7 = _ordered(p6, p7)
    p1, p2 = _ordered(p1, p2)
    p4, p5 = _ordered(p4, p5)
    p7, p8 = _ordered(p7, p8)
    p0, p3 = _ordered(p0, p3)
    p5, p8 = _ordered(p5, p8)
    p4, p7 = _ordered(p4, p7)
    p3, p6 = _ordered(p3, p6)
    p1, p4 = _ordered(p1, p4)
    p2, p5 = _ordered(p2, p5)
    p4, p7 = _ordered(p4, p7)
    p4, p2 = _ordered(p4, p2)
    p6, p4 = _ordered(p6, p4)
    p4, p2 = _ordered(p4, p2)
    return p4


@compiled()
def _lower_usable_medians(
    depth: npt.NDArray[Any], rows: IntArray, cols: IntArray, half: int
) -> FloatArray:  # pragma: no cover - compiled
    """`_median_depth` on the grid rows x cols (flat, row-major) for a window of 2 * half + 1.
    A 3x3 window of nine usable depths, the common case, takes the median of nine; any other
    is sorted by insertion as it is read (a few dozen values at most)."""
    height, width = depth.shape
    result = np.empty(rows.size * cols.size)
    usable = np.empty((2 * half + 1) ** 2)
    for i in range(rows.size):
        top, row, bottom = max(rows[i] - 1, 0), rows[i], min(rows[i] + 1, height - 1)
        for j in range(cols.size):
            at = i * cols.size + j
            centre = np.float64(depth[row, cols[j]])
            if not _usable(centre):
                result[at] = centre
                continue
            if half == 1:
                left, col, right = max(cols[j] - 1, 0), cols[j], min(cols[j] + 1, width - 1)
                p0, p1, p2 = depth[top, left], depth[top, col], depth[top, right]
                p3, p5 = depth[row, left], depth[row, right]
                p6, p7, p8 = depth[bottom, left], depth[bottom, col], depth[bottom, right]
                if (
                    _usable(p0)
                    & _usable(p1)
                    & _usable(p2)
                    & _usable(p3)
                    & _usable(p5)
                    & _usable(p6)
                    & _usable(p7)
                    & _usable(p8)
                ):
                    result[at] = _median_of_nine(
                        np.float64(p0), np.float64(p1), np.float64(p2), np.float64(p3),
                        centre, np.float64(p5), np.float64(p6), np.float64(p7), np.float64(p8),
                    )  # fmt: skip
                    continue
            count = 0
            for near_row in range(rows[i] - half, rows[i] + half + 1):
                clamped = min(max(near_row, 0), height - 1)
                for near_col in range(cols[j] - half, cols[j] + half + 1):
                    value = np.float64(depth[clamped, min(max(near_col, 0), width - 1)])
                    if _usable(value):
                        slot = count
                        while slot > 0 and usable[slot - 1] > value:
                            usable[slot] = usable[slot - 1]
                            slot -= 1
                        usable[slot] = value
                        count += 1
            result[at] = usable[(count - 1) // 2]
    return result


def _footprint(camera: FloatArray, params: OccupancyParams) -> tuple[FloatArray, FloatArray]:
    """Points on a grid of half a cell over the disc the robot stood on, under the camera."""
    radius = params.footprint_radius_m
    if radius <= 0:
        return np.zeros(0), np.zeros(0)
    offsets = np.arange(-radius, radius + 1e-9, params.resolution_m / 2)
    dx, dy = np.meshgrid(offsets, offsets)
    inside = dx**2 + dy**2 <= radius**2
    return camera[0] + dx[inside], camera[1] + dy[inside]


class _Window:
    """The cells within the sensor's range of one camera, marked in a small dense array."""

    def __init__(self, camera: FloatArray, params: OccupancyParams) -> None:
        self.geometry = MapGeometry.of(params)
        self.camera = camera
        res = self.geometry.resolution_m
        self.radius = math.ceil(params.max_range_m / res) + 1
        self.size = 2 * self.radius + 1
        self.base_col = math.floor(camera[0] / res) - self.radius
        self.base_row = math.floor(camera[1] / res) - self.radius

    def cells(
        self, x: FloatArray, y: FloatArray, chosen: npt.NDArray[np.bool_] | None = None
    ) -> IntArray:
        """Sorted unique flat grid indices of the cells of the points (the `chosen` ones) that
        are inside the grid."""
        flat: IntArray = _marked_cells(
            x,
            y,
            np.ones(x.size, np.bool_) if chosen is None else chosen,
            self.geometry.resolution_m,
            (self.base_row, self.base_col, self.size),
            (self.geometry.side // 2, self.geometry.side),
        )
        return flat


@compiled()
def _marked_cells(
    x: FloatArray,
    y: FloatArray,
    chosen: npt.NDArray[np.bool_],
    resolution: float,
    window: tuple[int, int, int],
    grid: tuple[int, int],
) -> IntArray:  # pragma: no cover - compiled
    """The chosen points' cells marked in the window (base row, base column, size), then read back in
    row-major order (sorted and unique) as flat indices of the grid (half, side)."""
    base_row, base_col, size = window
    half, side = grid
    mark = np.zeros((size, size), np.bool_)
    for index in range(x.size):
        if not chosen[index]:
            continue
        at_col = np.int64(np.floor(x[index] / resolution)) - base_col
        at_row = np.int64(np.floor(y[index] / resolution)) - base_row
        if at_col >= 0 and at_col < size and at_row >= 0 and at_row < size:
            mark[at_row, at_col] = True
    flat = np.empty(int(mark.sum()), np.int64)
    written = 0
    for row in range(size):
        grid_row = row + base_row + half
        for col in range(size):
            if mark[row, col]:
                grid_col = col + base_col + half
                if grid_row >= 0 and grid_row < side and grid_col >= 0 and grid_col < side:
                    flat[written] = grid_row * side + grid_col
                    written += 1
    return flat[:written]


def _rays(
    camera: FloatArray,
    dx: FloatArray,
    dy: FloatArray,
    reach: FloatArray,
    obstacle: npt.NDArray[np.bool_],
    floor: npt.NDArray[np.bool_],
    spread: float,
    params: OccupancyParams,
) -> tuple[FloatArray, FloatArray]:
    """Points along the rays of the frame's bearing bins, each as far as its bin is clear: up to
    its nearest obstacle or its farthest floor point, and never past an obstacle in the bins
    within `spread` radians of it."""
    bin_width = params.resolution_m / (params.ray_bins_per_cell_at_max_range * params.max_range_m)
    count = math.ceil(2 * math.pi / bin_width)
    bins = np.minimum(floor_divide(np.arctan2(dy, dx) + math.pi, bin_width), count - 1).astype(
        np.intp
    )
    nearest_obstacle = np.full(count, np.inf)
    np.minimum.at(nearest_obstacle, bins[obstacle], reach[obstacle])
    farthest_floor = np.zeros(count)
    np.maximum.at(farthest_floor, bins[floor], reach[floor])
    neighbours = min(math.ceil(spread / bin_width), count // 2)
    blocked = minimum_filter1d(nearest_obstacle, 2 * neighbours + 1, mode="wrap")
    seen = np.where(np.isfinite(nearest_obstacle), nearest_obstacle, farthest_floor)
    clear = np.minimum(seen, blocked - params.ray_stop_short_m)
    active = np.flatnonzero(clear > 0)
    if active.size == 0:
        return np.zeros(0), np.zeros(0)
    step = params.resolution_m / 2
    steps = np.arange(math.ceil(float(clear[active].max()) / step) + 1) * step
    angle = (active + 0.5) * bin_width - math.pi
    along = steps[None, :] <= clear[active, None]
    x = camera[0] + np.cos(angle)[:, None] * steps[None, :]
    y = camera[1] + np.sin(angle)[:, None] * steps[None, :]
    return x[along], y[along]


def floor_divide(values: FloatArray, divisor: float) -> FloatArray:
    """`values // divisor` (numpy's floor division, exactly), at the cost of a true division:
    floor(values / divisor) differs from it only where the rounded quotient lies within a
    rounding error of an integer, and only there is the floor division itself computed."""
    quotient = values / divisor
    result: FloatArray = np.floor(quotient)
    doubtful = np.flatnonzero(np.abs(quotient - np.rint(quotient)) <= 1e-6 * np.abs(quotient))
    result[doubtful] = values[doubtful] // divisor
    return result


def occupancy_evidence(
    frames: Sequence[Frame], params: OccupancyParams
) -> OccupancyEvidence | None:
    """The batch's evidence for the map (None when its depth says nothing inside the grid)."""
    free_parts: list[IntArray] = [np.zeros(0, np.int64)]
    occupied_parts: list[IntArray] = [np.zeros(0, np.int64)]
    for frame in frames:
        free, occupied = frame_cells(frame, params)
        free_parts.append(free)
        occupied_parts.append(occupied)
    occupied = np.unique(np.concatenate(occupied_parts))
    # Occupied wins within a batch.
    free = np.setdiff1d(np.unique(np.concatenate(free_parts)), occupied, assume_unique=True)
    if free.size + occupied.size == 0:
        return None
    geometry = MapGeometry.of(params)
    return OccupancyEvidence(
        frame_id=frames[-1].frame_id,
        resolution_m=geometry.resolution_m,
        side=geometry.side,
        free=runs_of(free),
        occupied=runs_of(occupied),
        timestamp=max(frame.timestamp for frame in frames),
    )
