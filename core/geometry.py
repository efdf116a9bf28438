"""Back-projection, robust proposal centers, box sampling and projection (sections 3.2, 3.3)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from core.grounding_kernel import mask_points, percentile_box
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


def ground_detection(
    detection: Detection,
    frame: Frame,
    params: ProposalParams,
    min_range_m: float,
    max_range_m: float,
    detection_index: int = -1,
) -> Proposal | None:
    """Back-project a mask's valid depth through (K, T); None when valid-depth support is too small.

    The mask's pixels with depth in range; the interior, where boundary leakage does not reach
    (the mask cut to those pixels' box, eroded by a square); a median/MAD gate on the depth
    around the interior's median (all valid depth's, when the interior is small), which drops
    background leaked into the mask. A mask with more valid pixels than `max_mask_samples` is
    sampled on a regular stride: its robust statistics barely change, and the work per mask is
    bounded (a batch may carry hundreds of full-frame masks). `core.grounding_kernel` computes
    this in one pass over the mask's runs."""
    depth = frame.depth.reshape(-1)
    if (detection.mask.height, detection.mask.width) != frame.depth.shape:  # as the codec does
        raise ValueError(
            f"a {detection.mask.height} x {detection.mask.width} mask on a depth image of "
            f"{frame.depth.shape}"
        )
    if depth.dtype != np.float32:
        depth = depth.astype(np.float64)
    in_dtype = depth.dtype.type  # the range compared in the depth's precision, as numpy would
    intrinsics = frame.intrinsics
    camera_points, inlier_pixels = mask_points(
        detection.mask.runs,
        detection.mask.height,
        detection.mask.width,
        depth,
        in_dtype(min_range_m),
        in_dtype(max_range_m),
        (float(intrinsics.fx), float(intrinsics.fy), float(intrinsics.cx), float(intrinsics.cy)),
        (
            params.min_valid_depth_pixels,
            params.max_mask_samples,
            params.boundary_erosion_px,
            params.min_interior_pixels,
            float(params.depth_inlier_mad_k),
            float(params.depth_inlier_min_band_m),
        ),
    )
    if inlier_pixels < 0:
        return None
    points = camera_to_world(camera_points, frame.pose)
    # Selection per column gives the robust median center and the percentile box.
    low_fraction, high_fraction = (p / 100.0 for p in params.extent_percentiles)
    low, median, high = percentile_box(points, low_fraction, high_fraction)
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
