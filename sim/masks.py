"""Mask errors of a real segmenter: boundary leaks, bleeding onto neighbours, parts and splits.

Every function takes and returns boolean (H, W) masks and works on the mask's bounding box only,
so a 640 x 480 frame with a dozen detections stays cheap.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

# 8-connected growth, so a leak of k pixels reaches k pixels out diagonally too.
LEAK_STRUCTURE = np.ones((3, 3), dtype=bool)


def bounding_slices(mask: np.ndarray, margin: int) -> tuple[slice, slice]:
    """Row and column slices around the mask's true pixels, grown by `margin` and clipped."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    height, width = mask.shape
    return (
        slice(max(rows[0] - margin, 0), min(rows[-1] + margin + 1, height)),
        slice(max(cols[0] - margin, 0), min(cols[-1] + margin + 1, width)),
    )


def leak(mask: np.ndarray, leak_px: int) -> np.ndarray:
    """The mask dilated by `leak_px` pixels onto whatever is around it."""
    if leak_px <= 0 or not mask.any():
        return mask
    rows, cols = bounding_slices(mask, leak_px)
    grown = mask.copy()
    grown[rows, cols] = ndimage.binary_dilation(
        mask[rows, cols], structure=LEAK_STRUCTURE, iterations=leak_px
    )
    return grown


def bleed(mask: np.ndarray, onto: np.ndarray, bleed_px: int) -> np.ndarray:
    """The mask grown by `bleed_px` pixels, but only over the pixels of `onto` (a neighbour)."""
    if bleed_px <= 0 or not mask.any():
        return mask
    grown: np.ndarray = mask | (leak(mask, bleed_px) & onto)
    return grown


def _along(mask: np.ndarray, angle: float) -> tuple[tuple[slice, slice], np.ndarray]:
    """The mask's bounding box and each of its pixels' coordinate along direction `angle`."""
    rows, cols = bounding_slices(mask, 0)
    grid_rows, grid_cols = np.mgrid[rows, cols]
    return (rows, cols), grid_cols * math.cos(angle) + grid_rows * math.sin(angle)


def partial(mask: np.ndarray, keep: float, angle: float) -> np.ndarray:
    """The part of the mask on one side of a line: about `keep` of its pixels (a part, not all)."""
    if not mask.any():
        return mask
    (rows, cols), coordinate = _along(mask, angle)
    inside = mask[rows, cols]
    cut = np.quantile(coordinate[inside], keep)
    kept = np.zeros_like(mask)
    kept[rows, cols] = inside & (coordinate <= cut)
    return kept


def split(mask: np.ndarray, angle: float) -> tuple[np.ndarray, np.ndarray]:
    """The mask cut in two halves across direction `angle` (an over-segmented object)."""
    first = partial(mask, 0.5, angle)
    return first, mask & ~first


def principal_angle(mask: np.ndarray) -> float:
    """Direction (as `partial` takes it) of the mask's longest extent: split across it, a long
    table comes apart into its two ends."""
    if not mask.any():
        return 0.0
    rows, cols = np.nonzero(mask[bounding_slices(mask, 0)])
    if rows.size < 2:
        return 0.0
    covariance = np.cov(np.vstack([cols, rows]).astype(np.float64))
    values, vectors = np.linalg.eigh(covariance)
    along = vectors[:, int(np.argmax(values))]
    return math.atan2(float(along[1]), float(along[0]))
