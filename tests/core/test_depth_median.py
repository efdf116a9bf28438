"""The occupancy evidence's depth median and its bearing bins' floor division
(core/occupancy_evidence.py). The median is exactly the lower median
of the usable depths around each pixel, by the median of nine where all nine are usable and by
insertion elsewhere."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.occupancy_evidence import _median_depth, floor_divide


def reference_median(
    depth: np.ndarray, rows: np.ndarray, cols: np.ndarray, window: int
) -> np.ndarray:
    """Pixel by pixel: the lower median of the window's usable depths (edges clamped)."""
    height, width = depth.shape
    half = window // 2
    out = []
    for row in rows:
        for col in cols:
            centre = float(depth[row, col])
            if not (np.isfinite(centre) and centre > 0):
                out.append(centre)
                continue
            near = depth[
                np.clip(np.arange(row - half, row + half + 1), 0, height - 1)[:, None],
                np.clip(np.arange(col - half, col + half + 1), 0, width - 1)[None, :],
            ].ravel()
            usable = np.sort(near[np.isfinite(near) & (near > 0)])
            out.append(float(usable[(usable.size - 1) // 2]))
    return np.asarray(out)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize(("window", "stride"), [(1, 4), (3, 4), (3, 1), (5, 3), (9, 4)])
def test_the_median_is_the_lower_median_of_the_usable_depths(
    window: int, stride: int, dtype: type
) -> None:
    rng = np.random.default_rng(window * 10 + stride)
    depth: np.ndarray = (rng.random((37, 53)) * 4 + 0.3).astype(dtype)
    depth[rng.random(depth.shape) < 0.05] = -1.0  # negative: not usable
    depth[-1, 5:10] = np.round(depth[-1, 5:10], 1)  # ties
    depth[rng.random(depth.shape) < 0.2] = 0.0  # holes
    depth[rng.random(depth.shape) < 0.03] = np.nan
    depth[rng.random(depth.shape) < 0.03] = np.inf
    depth[:6, :6] = 0.0  # a corner without depth
    rows, cols = np.arange(0, 37, stride), np.arange(0, 53, stride)
    got = _median_depth(depth, rows, cols, window)
    assert got.dtype == np.float64
    assert np.array_equal(got, reference_median(depth, rows, cols, window), equal_nan=True)


@pytest.mark.parametrize("seed", range(5))
def test_windows_of_nine_usable_depths_give_their_median(seed: int) -> None:
    rng = np.random.default_rng(seed)
    depth = (rng.random((31, 41)) * 4 + 0.3).astype(np.float32)
    depth[rng.random(depth.shape) < 0.02] = 0.0  # a few holes: most windows are whole
    depth[rng.random(depth.shape) < 0.2] = 1.5  # ties
    rows, cols = np.arange(31), np.arange(41)
    got = _median_depth(depth, rows, cols, 3)
    assert np.array_equal(got, reference_median(depth, rows, cols, 3), equal_nan=True)


@settings(max_examples=300, deadline=None)
@given(
    values=st.lists(st.floats(-10, 10, allow_nan=False), min_size=1, max_size=50),
    divisor=st.floats(1e-4, 3.0),
    multiples=st.lists(st.integers(-2000, 2000), max_size=20),
)
def test_the_bearing_bins_floor_division_is_numpy_s(
    values: list[float], divisor: float, multiples: list[int]
) -> None:
    # Exact multiples of the divisor and their neighbours are where a rounded quotient meets an
    # integer (1.0 // 0.1 is 9.0, while floor(1.0 / 0.1) is 10.0).
    near = [k * divisor for k in multiples]
    near += [float(np.nextafter(v, np.inf)) for v in near] + [
        float(np.nextafter(v, -np.inf)) for v in near
    ]
    array = np.array(values + near + [1.0, 0.3, 0.7], dtype=np.float64)
    for d in (divisor, 0.1):
        assert np.array_equal(floor_divide(array, d), array // d)
