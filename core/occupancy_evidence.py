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

import functools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.ndimage import minimum_filter1d

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
    points, dx, dy, reach = points[near], dx[near], dy[near], reach[near]
    obstacle = (points[:, 2] >= params.band_min_z_m) & (points[:, 2] <= params.band_max_z_m)
    floor = points[:, 2] < params.band_min_z_m
    occupied = window.cells(points[obstacle, 0], points[obstacle, 1])
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
    median keeps edges where a plain mean would blur them.

    The window's depths are kept as one plane per offset and sorted across the planes by a
    sorting network (whole-array minima and maxima): the lower median of the usable depths,
    with unusable ones sorted last, is then the plane its count of usable depths names.
    """
    height, width = depth.shape
    centre = depth[rows[:, None], cols[None, :]].astype(np.float64)
    if window <= 1:
        return centre.ravel()
    half = window // 2
    planes: list[npt.NDArray[Any]] = []
    usable_count = np.zeros((rows.size, cols.size), np.intp)
    for row_offset in range(-half, half + 1):
        band = depth[np.clip(rows + row_offset, 0, height - 1)]
        for col_offset in range(-half, half + 1):
            plane = band[:, np.clip(cols + col_offset, 0, width - 1)]
            usable = (plane > 0) & (plane < np.inf)  # NaN compares false
            usable_count += usable
            planes.append(np.where(usable, plane, np.inf))
    for low, high in _sorting_network(window * window):
        planes[low], planes[high] = (
            np.minimum(planes[low], planes[high]),
            np.maximum(planes[low], planes[high]),
        )
    middle = np.maximum(usable_count - 1, 0) // 2  # the lower median of the usable
    lower_half = np.stack(planes[: (window * window + 1) // 2])
    median = np.take_along_axis(lower_half, middle[None], axis=0)[0].astype(np.float64)
    has_depth = np.isfinite(centre) & (centre > 0)
    result: FloatArray = np.where(has_depth, median, centre).ravel()
    return result


@functools.cache
def _sorting_network(inputs: int) -> tuple[tuple[int, int], ...]:
    """Batcher's odd-even merge sort for `inputs` wires: compare-exchange pairs (low, high),
    in order, after which the wires hold their values sorted."""
    pairs = []
    span = 1
    while span < inputs:
        step = span
        while step >= 1:
            for first in range(step % span, inputs - step, 2 * step):
                for offset in range(min(step, inputs - first - step)):
                    low = first + offset
                    if low // (2 * span) == (low + step) // (2 * span):
                        pairs.append((low, low + step))
            step //= 2
        span *= 2
    return tuple(pairs)


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

    def cells(self, x: FloatArray, y: FloatArray) -> IntArray:
        """Sorted unique flat grid indices of the points' cells (those inside the grid)."""
        res = self.geometry.resolution_m
        col = np.floor(x / res).astype(np.int64) - self.base_col
        row = np.floor(y / res).astype(np.int64) - self.base_row
        keep = (col >= 0) & (col < self.size) & (row >= 0) & (row < self.size)
        mark = np.zeros((self.size, self.size), dtype=bool)
        mark[row[keep], col[keep]] = True
        local_row, local_col = np.nonzero(mark)  # row-major: sorted flat indices
        half, side = self.geometry.side // 2, self.geometry.side
        grid_row = local_row.astype(np.int64) + self.base_row + half
        grid_col = local_col.astype(np.int64) + self.base_col + half
        inside = (grid_row >= 0) & (grid_row < side) & (grid_col >= 0) & (grid_col < side)
        flat: IntArray = grid_row[inside] * side + grid_col[inside]
        return flat


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
    bins = np.minimum((np.arctan2(dy, dx) + math.pi) // bin_width, count - 1).astype(np.intp)
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
