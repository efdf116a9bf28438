"""The visibility gate's window depth (core/visibility.py `_window_depth`): the median of the
valid depths in the window around each pixel, the window clamped at the image's edges, 0 where
none is valid; against numpy pixel by pixel."""

from __future__ import annotations

import numpy as np
import pytest

from core.params import VisibilityParams
from core.visibility import _window_depth


def reference(depth: np.ndarray, u: np.ndarray, v: np.ndarray, p: VisibilityParams) -> np.ndarray:
    height, width = depth.shape
    half = p.depth_window_px // 2
    out = []
    for col, row in zip(u, v, strict=True):
        rows = np.clip(np.arange(row - half, row + half + 1), 0, height - 1)
        cols = np.clip(np.arange(col - half, col + half + 1), 0, width - 1)
        values = depth[rows[:, None], cols[None, :]].astype(np.float64).ravel()
        valid = values[(values >= p.min_range_m) & (values <= p.max_range_m)]
        out.append(float(np.median(valid)) if valid.size else 0.0)
    return np.asarray(out)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("window", [1, 3, 5])
def test_the_window_depth_is_the_median_of_the_valid_depths(dtype: type, window: int) -> None:
    rng = np.random.default_rng(window)
    params = VisibilityParams(depth_window_px=window)
    depth: np.ndarray = rng.uniform(0.0, 7.0, (30, 40)).astype(dtype)
    depth[rng.random(depth.shape) < 0.2] = 0.0
    depth[rng.random(depth.shape) < 0.05] = np.nan
    depth[rng.random(depth.shape) < 0.05] = np.inf
    depth[rng.random(depth.shape) < 0.05] = params.min_range_m  # on the range's edges
    depth[rng.random(depth.shape) < 0.05] = params.max_range_m
    depth[:4, :4] = 0.0  # a corner with no valid depth
    depth[10:14, 10:20] = np.round(depth[10:14, 10:20], 0)  # ties
    u = np.concatenate((rng.integers(0, 40, 300), [0, 39, 0, 39, 1]))
    v = np.concatenate((rng.integers(0, 30, 300), [0, 0, 29, 29, 1]))
    got = _window_depth(depth, u.astype(np.intp), v.astype(np.intp), params)
    assert np.array_equal(got, reference(depth, u, v, params))


def test_each_box_s_projected_area_is_its_samples_bounding_box() -> None:
    from core.visibility import _bbox_area

    rng = np.random.default_rng(3)
    owner = rng.integers(0, 40, 500).astype(np.intp)
    u, v = rng.uniform(-50, 700, 500), rng.uniform(-50, 500, 500)
    u[7] = np.nan  # its box's extremes are NaN: not seen, area 0 (as numpy's minimum.at gave)
    got = _bbox_area(owner, u, v, 45)  # boxes 40-44 have no samples
    for box in range(45):
        mine = owner == box
        if not mine.any() or np.isnan(u[mine]).any():
            assert got[box] == 0.0
            continue
        expected = (np.max(u[mine]) - np.min(u[mine]) + 1) * (np.max(v[mine]) - np.min(v[mine]) + 1)
        assert np.array_equal(got[box], expected, equal_nan=True)


def _turned(yaw: float, pitch: float, position: np.ndarray) -> np.ndarray:
    """A camera-to-world pose looking along a yaw and a pitch (OpenCV axes)."""
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    forward = np.array([cy * cp, sy * cp, sp])
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    pose = np.eye(4)
    pose[:3, :3] = np.column_stack((right, down, forward))
    pose[:3, 3] = position
    return pose


@pytest.mark.parametrize("seed", range(6))
def test_boxes_out_of_range_are_left_out_without_changing_any_column(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`sample_columns` makes samples only for the boxes that may reach the camera's range
    (`_within_range`); every column is the same, bit for bit, as when every box is sampled, and
    a box left out has no sample in range."""
    import core.visibility as visibility
    from core.geometry import box_samples, world_to_camera
    from core.observation import Frame, Intrinsics

    rng = np.random.default_rng(seed)
    params = VisibilityParams()
    intrinsics = Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)
    depth = rng.uniform(0.2, 8.0, (48, 64)).astype(np.float32)
    depth[rng.random(depth.shape) < 0.1] = 0.0
    pose = _turned(rng.uniform(-np.pi, np.pi), rng.uniform(-0.6, 0.2), rng.uniform(-2, 2, 3))
    frame = Frame("f", 0.0, intrinsics, pose, depth)
    forward = pose[:3, 2]
    # Boxes all around the camera, and boxes whose extent puts a face right on either end of
    # the range along the optical axis.
    around = pose[:3, 3] + rng.uniform(-9.0, 9.0, (300, 3))
    extents = rng.uniform(0.02, 1.5, (400, 3))
    ends = np.repeat([params.min_range_m, params.max_range_m], 50)
    reach = 0.5 * np.abs(extents[300:]) @ np.abs(forward)
    sign = rng.choice([-1.0, 1.0], 100)
    on_edges = pose[:3, 3] + (ends + sign * reach)[:, None] * forward
    centers = np.concatenate((around, on_edges))
    got = visibility.sample_columns(centers, extents, frame, params)
    kept = visibility._within_range(centers, extents, pose, params)
    assert 0 < kept.size < centers.shape[0]
    monkeypatch.setattr(visibility, "_within_range", lambda c, *_: np.arange(c.shape[0]))
    every = visibility.sample_columns(centers, extents, frame, params)
    for name in every._fields:
        assert np.array_equal(getattr(got, name), getattr(every, name)), name
    samples = world_to_camera(
        box_samples(centers, extents, params.box_samples_per_axis).reshape(-1, 3), pose
    )[:, 2].reshape(centers.shape[0], -1)
    in_range = ((samples >= params.min_range_m) & (samples <= params.max_range_m)).any(axis=1)
    assert set(np.flatnonzero(in_range).tolist()) <= set(kept.tolist())
