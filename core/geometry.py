"""Back-projection, robust proposal centers, box sampling and projection (sections 3.2, 3.3)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from core.masks import Mask
from core.observation import Detection, DetectionKind, Frame, Intrinsics
from core.params import ProposalParams

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Proposal:
    """A grounded 3D proposal mu_j from one detection."""

    label: str
    score: float
    kind: DetectionKind
    center: FloatArray  # (3,) world
    extent: FloatArray  # (3,) world axis-aligned box size
    embedding: FloatArray | None  # l2-normalized, or None
    valid_pixels: int
    frame_id: str
    timestamp: float
    bottom_z: float  # low percentile of the inlier heights: where the object rests
    detection_index: int = -1  # which detection of its frame it grounds
    class_scores: Mapping[str, float] | None = None  # the detector's scores of other classes


def backproject_pixels(
    flat_index: npt.NDArray[np.intp], depth_m: FloatArray, intrinsics: Intrinsics
) -> FloatArray:
    """Camera-frame points (n, 3) of flat pixel indices with their z-depths."""
    v, u = np.divmod(flat_index, intrinsics.width)
    x = (u - intrinsics.cx) / intrinsics.fx * depth_m
    y = (v - intrinsics.cy) / intrinsics.fy * depth_m
    return np.column_stack((x, y, depth_m))


def camera_to_world(points: FloatArray, pose: FloatArray) -> FloatArray:
    """Apply T_t (camera-to-world) to camera-frame points (n, 3)."""
    return points @ pose[:3, :3].T + pose[:3, 3]


def world_to_camera(points: FloatArray, pose: FloatArray) -> FloatArray:
    """Inverse of `camera_to_world` for a rigid pose."""
    rotation = pose[:3, :3]
    return (points - pose[:3, 3]) @ rotation


def interior_pixels(
    mask: Mask | npt.NDArray[np.bool_],
    mask_index: npt.NDArray[np.intp],
    flat_index: npt.NDArray[np.intp],
    width: int,
    erosion_px: int,
) -> npt.NDArray[np.intp]:
    """Flat indices of the mask eroded by `erosion_px`, on the bounding box of `flat_index` only
    (sorted, C-order). `mask` is decoded already (an array) or not (then `mask_index` builds
    the box's pixels)."""
    if flat_index.size == 0 or erosion_px <= 0:
        return flat_index
    r0, r1 = int(flat_index[0] // width), int(flat_index[-1] // width) + 1
    cols = flat_index % width
    c0, c1 = int(cols.min()), int(cols.max()) + 1
    if isinstance(mask, np.ndarray):
        crop = mask[r0:r1, c0:c1]
    else:
        # The mask drawn on its own bounding box (which holds the valid pixels' box), then cut.
        rows_all, cols_all = np.divmod(mask_index, width)
        top, left = int(rows_all[0]), int(cols_all.min())
        whole = np.zeros((int(rows_all[-1]) + 1 - top, int(cols_all.max()) + 1 - left), bool)
        whole[rows_all - top, cols_all - left] = True
        crop = whole[r0 - top : r1 - top, c0 - left : c1 - left]
    local_rows, local_cols = np.nonzero(erode_square(crop, erosion_px))
    flat: npt.NDArray[np.intp] = (local_rows + r0) * width + (local_cols + c0)
    return flat


def erode_square(mask: npt.NDArray[np.bool_], radius: int) -> npt.NDArray[np.bool_]:
    """Binary erosion by a (2r+1)^2 square, separable: outside the array counts as background."""
    height, width = mask.shape
    padded = np.zeros((height + 2 * radius, width + 2 * radius), dtype=bool)
    padded[radius : radius + height, radius : radius + width] = mask
    across = padded[:, :width].copy()
    for shift in range(1, 2 * radius + 1):
        across &= padded[:, shift : shift + width]
    eroded = across[:height].copy()
    for shift in range(1, 2 * radius + 1):
        eroded &= across[shift : shift + height]
    return eroded


def column_quantiles(points: FloatArray, fractions: tuple[float, ...]) -> FloatArray:
    """Linear-interpolated quantiles (numpy's default method) of each column of (n, d) points,
    one row per fraction: the order statistics they read are selected, not the columns sorted."""
    last = points.shape[0] - 1
    positions = [fraction * last for fraction in fractions]
    low = [math.floor(position) for position in positions]
    high = [min(index + 1, last) for index in low]
    rows = np.ascontiguousarray(points.T)  # a selection along contiguous memory is faster
    selected = np.partition(rows, sorted({*low, *high}), axis=1)
    weight = np.array([position - index for position, index in zip(positions, low, strict=True)])
    result: FloatArray = (selected[:, low] * (1.0 - weight) + selected[:, high] * weight).T
    return result


def median_of(values: FloatArray) -> float:
    """`np.median` of a non-empty 1-D array without NaN (the same value), by selection."""
    middle = values.size // 2
    if values.size % 2:
        return float(np.partition(values, middle)[middle])
    pair = np.partition(values, (middle - 1, middle))
    return float((pair[middle - 1] + pair[middle]) / 2)


def robust_depth_inliers(
    depth_m: FloatArray, reference_depth_m: FloatArray, params: ProposalParams
) -> npt.NDArray[np.bool_]:
    """Median/MAD gate on mask depths around a reference: drops background leaked into the mask."""
    median = median_of(reference_depth_m)
    mad = 1.4826 * median_of(np.abs(reference_depth_m - median))  # robust sigma
    band = max(params.depth_inlier_min_band_m, params.depth_inlier_mad_k * mad)
    return np.abs(depth_m - median) <= band


def ground_detection(
    detection: Detection,
    frame: Frame,
    params: ProposalParams,
    min_range_m: float,
    max_range_m: float,
    detection_index: int = -1,
) -> Proposal | None:
    """Back-project a mask's valid depth through (K, T); None when valid-depth support is too small."""
    # A large mask is decoded whole (linear in the frame); a small one from its runs.
    mask: Mask | npt.NDArray[np.bool_] = detection.mask
    if detection.mask.area * 16 > detection.mask.height * detection.mask.width:
        mask = detection.mask.to_array()
        mask_index = np.flatnonzero(mask)
    else:
        mask_index = detection.mask.flat_indices()
    depth_m = frame.depth.reshape(-1)[mask_index].astype(np.float64)
    in_range = (depth_m >= min_range_m) & (depth_m <= max_range_m)
    valid = int(in_range.sum())
    if valid < params.min_valid_depth_pixels:
        return None
    # A large mask is sampled on a regular stride: its robust statistics barely change, and the
    # work per mask is bounded (a batch may carry hundreds of full-frame masks).
    stride = -(-valid // params.max_mask_samples)
    flat_index, depth_m = mask_index[in_range], depth_m[in_range]
    # Leakage sits on the mask's rim: anchor the median on the interior when it is large enough.
    interior_index = interior_pixels(
        mask, mask_index, flat_index, frame.intrinsics.width, params.boundary_erosion_px
    )
    flat_index, depth_m = flat_index[::stride], depth_m[::stride]
    interior_depth = frame.depth.reshape(-1)[interior_index[::stride]]
    interior: FloatArray = interior_depth[
        (interior_depth >= min_range_m) & (interior_depth <= max_range_m)
    ].astype(np.float64)
    reference = interior if interior.size >= params.min_interior_pixels else depth_m
    inliers = robust_depth_inliers(depth_m, reference, params)
    inlier_pixels = int(inliers.sum()) * stride  # estimated for a sampled mask
    if inlier_pixels < params.min_valid_depth_pixels:
        return None
    points = camera_to_world(
        backproject_pixels(flat_index[inliers], depth_m[inliers], frame.intrinsics), frame.pose
    )
    # One selection per column gives the robust median center and the percentile box.
    low_fraction, high_fraction = (p / 100.0 for p in params.extent_percentiles)
    low, median, high = column_quantiles(points, (low_fraction, 0.5, high_fraction))
    extent = np.maximum(high - low, params.min_extent_m)
    embedding = None
    if detection.embedding is not None:
        norm = float(np.linalg.norm(detection.embedding))
        embedding = detection.embedding / norm if norm > 0 else None
    return Proposal(
        label=detection.label,
        score=detection.score,
        kind=detection.kind,
        center=median,
        extent=extent,
        embedding=embedding,
        valid_pixels=inlier_pixels,
        frame_id=frame.frame_id,
        timestamp=frame.timestamp,
        bottom_z=float(low[2]),
        detection_index=detection_index,
        class_scores=detection.class_scores,
    )


def box_samples(centers: FloatArray, extents: FloatArray, per_axis: int) -> FloatArray:
    """(n, per_axis**3, 3) grid samples of axis-aligned boxes (corners included)."""
    steps = np.linspace(-0.5, 0.5, per_axis) if per_axis > 1 else np.zeros(1)
    grid = np.stack(np.meshgrid(steps, steps, steps, indexing="ij"), axis=-1).reshape(-1, 3)
    return centers[:, None, :] + grid[None, :, :] * extents[:, None, :]


def project(points_camera: FloatArray, intrinsics: Intrinsics) -> tuple[FloatArray, FloatArray]:
    """Pixel coordinates (u, v) of camera-frame points with z > 0."""
    z = points_camera[..., 2]
    u = intrinsics.fx * points_camera[..., 0] / z + intrinsics.cx
    v = intrinsics.fy * points_camera[..., 1] / z + intrinsics.cy
    return u, v
