"""The occupancy evidence's depth median (core/occupancy_evidence.py): a sorting network across
the window's planes gives exactly the lower median of the usable depths around each pixel."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from core.occupancy_evidence import _median_depth, _sorting_network


def sorted_by_network(values: np.ndarray) -> np.ndarray:
    wires = list(values)
    for low, high in _sorting_network(len(wires)):
        wires[low], wires[high] = min(wires[low], wires[high]), max(wires[low], wires[high])
    return np.asarray(wires)


def test_the_network_of_nine_sorts_every_zero_one_input() -> None:
    # The 0-1 principle: a comparator network that sorts every 0-1 input sorts every input.
    for bits in itertools.product((0, 1), repeat=9):
        assert list(sorted_by_network(np.asarray(bits))) == sorted(bits)


@pytest.mark.parametrize("inputs", [2, 5, 25, 49, 81])
def test_the_networks_of_every_window_sort(inputs: int) -> None:
    rng = np.random.default_rng(inputs)
    for _ in range(200):
        values = rng.integers(0, 6, inputs)  # ties included
        assert np.array_equal(sorted_by_network(values), np.sort(values))


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


@pytest.mark.parametrize(("window", "stride"), [(1, 4), (3, 4), (3, 1), (5, 3), (9, 4)])
def test_the_median_is_the_lower_median_of_the_usable_depths(window: int, stride: int) -> None:
    rng = np.random.default_rng(window * 10 + stride)
    depth = (rng.random((37, 53)) * 4 + 0.3).astype(np.float32)
    depth[rng.random(depth.shape) < 0.2] = 0.0  # holes
    depth[rng.random(depth.shape) < 0.03] = np.nan
    depth[rng.random(depth.shape) < 0.03] = np.inf
    depth[:6, :6] = 0.0  # a corner without depth
    rows, cols = np.arange(0, 37, stride), np.arange(0, 53, stride)
    got = _median_depth(depth, rows, cols, window)
    assert got.dtype == np.float64
    assert np.array_equal(got, reference_median(depth, rows, cols, window), equal_nan=True)
