"""The geometric visibility gate V_i(t) of equation (3) (section 3.3)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from core.geometry import box_samples, project, world_to_camera
from core.observation import Frame
from core.params import VisibilityParams

FloatArray = npt.NDArray[np.float64]


def samples_passed(
    centers: FloatArray,
    extents: FloatArray,
    frame: Frame,
    params: VisibilityParams,
    occlusion_test: bool = True,
) -> npt.NDArray[np.int64]:
    """For each stored box, how many of its samples are observable and unoccluded in `frame`.

    A sample passes when it lies in the valid camera range, projects inside the image, has
    valid depth in a 5x5 window, and d_meas + 0.15 m >= d_expected (no closer surface hides it).
    """
    count = centers.shape[0]
    passed = np.zeros(count, dtype=np.int64)
    if count == 0:
        return passed
    per_track = params.box_samples_per_axis**3
    samples = world_to_camera(
        box_samples(centers, extents, params.box_samples_per_axis).reshape(-1, 3), frame.pose
    )
    expected = samples[:, 2]
    in_range = (expected >= params.min_range_m) & (expected <= params.max_range_m)
    if not in_range.any():
        return passed
    candidate = np.flatnonzero(in_range)
    u, v = project(samples[candidate], frame.intrinsics)
    width, height = frame.intrinsics.width, frame.intrinsics.height
    inside = (u >= 0) & (u <= width - 1) & (v >= 0) & (v <= height - 1)
    candidate, u, v = candidate[inside], u[inside], v[inside]
    if candidate.size == 0:
        return passed
    if not occlusion_test:  # the ablation: in range and inside the image is enough
        np.add.at(passed, candidate // per_track, 1)
        return passed
    measured = _window_depth(
        frame.depth, np.rint(u).astype(np.intp), np.rint(v).astype(np.intp), params
    )
    has_depth = measured > 0
    unoccluded = measured + params.occlusion_margin_m >= expected[candidate]
    ok = candidate[has_depth & unoccluded]
    np.add.at(passed, ok // per_track, 1)
    return passed


def _window_depth(
    depth: npt.NDArray[np.float32],
    u: npt.NDArray[np.intp],
    v: npt.NDArray[np.intp],
    params: VisibilityParams,
) -> FloatArray:
    """Median of the valid depths in the window around each pixel; 0 where none is valid."""
    half = params.depth_window_px // 2
    offsets = np.arange(-half, half + 1)
    height, width = depth.shape
    rows = np.clip(v[:, None, None] + offsets[None, :, None], 0, height - 1)
    cols = np.clip(u[:, None, None] + offsets[None, None, :], 0, width - 1)
    window = depth[rows, cols].reshape(len(u), -1).astype(np.float64)
    valid = (window >= params.min_range_m) & (window <= params.max_range_m)
    # Median of the valid values per row: invalid ones sort to the end as +inf.
    window = np.sort(np.where(valid, window, np.inf), axis=1)
    counts = valid.sum(axis=1)
    rows_index = np.arange(len(u))
    upper = window[rows_index, counts // 2]
    lower = window[rows_index, np.maximum(counts - 1, 0) // 2]
    measured: FloatArray = np.where(counts > 0, 0.5 * (upper + lower), 0.0)
    return measured


def is_visible(samples_ok: int, params: VisibilityParams) -> bool:
    """V_i(t) = 1 only when at least two samples pass."""
    return samples_ok >= params.min_samples_passed
