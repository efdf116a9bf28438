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
