"""The compiled grounding of one mask (core/grounding_kernel.py) against the rule written in
numpy, as `core.geometry.ground_detection` computed it before the kernel: the same proposal,
bit for bit, on random masks and depth with holes, NaN, inf and values on the range's edges."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from core.geometry import camera_to_world, ground_detection
from core.grounding_kernel import _eroded, _median, percentile_box
from core.masks import Mask
from core.observation import Detection, Frame, Intrinsics
from core.params import ProposalParams

NEAR, FAR = 0.3, 6.0


def erode_square(mask: np.ndarray, radius: int) -> np.ndarray:
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


def reference_grounding(
    mask: np.ndarray, depth: np.ndarray, intrinsics: Intrinsics, pose: np.ndarray, p: ProposalParams
) -> tuple[np.ndarray, np.ndarray, int, float] | None:
    """(center, extent, valid pixels, bottom z) by the numpy rule, or None."""
    width = intrinsics.width
    mask_index = np.flatnonzero(mask)
    depth_m = depth.reshape(-1)[mask_index].astype(np.float64)
    in_range = (depth_m >= NEAR) & (depth_m <= FAR)
    valid = int(in_range.sum())
    if valid < p.min_valid_depth_pixels:
        return None
    stride = -(-valid // p.max_mask_samples)
    flat_index, depth_m = mask_index[in_range], depth_m[in_range]
    if p.boundary_erosion_px <= 0:
        interior_index = flat_index
    else:
        r0, r1 = int(flat_index[0] // width), int(flat_index[-1] // width) + 1
        cols = flat_index % width
        c0, c1 = int(cols.min()), int(cols.max()) + 1
        rows_e, cols_e = np.nonzero(erode_square(mask[r0:r1, c0:c1], p.boundary_erosion_px))
        interior_index = (rows_e + r0) * width + (cols_e + c0)
    flat_index, depth_m = flat_index[::stride], depth_m[::stride]
    interior_depth = depth.reshape(-1)[interior_index[::stride]]
    interior = interior_depth[(interior_depth >= NEAR) & (interior_depth <= FAR)].astype(np.float64)
    reference = interior if interior.size >= p.min_interior_pixels else depth_m
    median = float(np.median(reference))
    mad = 1.4826 * float(np.median(np.abs(reference - median)))
    band = max(p.depth_inlier_min_band_m, p.depth_inlier_mad_k * mad)
    inliers = np.abs(depth_m - median) <= band
    inlier_pixels = int(inliers.sum()) * stride
    if inlier_pixels < p.min_valid_depth_pixels:
        return None
    v, u = np.divmod(flat_index[inliers], width)
    d = depth_m[inliers]
    camera = np.column_stack(
        ((u - intrinsics.cx) / intrinsics.fx * d, (v - intrinsics.cy) / intrinsics.fy * d, d)
    )
    points = camera_to_world(camera, pose)
    low, median_point, high = column_quantiles(
        points, (p.extent_percentiles[0] / 100.0, 0.5, p.extent_percentiles[1] / 100.0)
    )
    return median_point, np.maximum(high - low, p.min_extent_m), inlier_pixels, float(low[2])


def column_quantiles(points: np.ndarray, fractions: tuple[float, ...]) -> np.ndarray:
    """Each column's quantiles at `fractions` (rows), numpy's linear method as a (1 - w) + b w
    between the order statistics a and b around the position, selected by np.partition."""
    last = points.shape[0] - 1
    positions = [fraction * last for fraction in fractions]
    low = [math.floor(position) for position in positions]
    high = [min(index + 1, last) for index in low]
    selected = np.partition(points.T, sorted({*low, *high}), axis=1)
    weight = np.array([position - index for position, index in zip(positions, low, strict=True)])
    result: np.ndarray = (selected[:, low] * (1.0 - weight) + selected[:, high] * weight).T
    return result


EDGE_DEPTHS = (0.0, np.nan, np.inf, -np.inf, NEAR, FAR, np.nextafter(NEAR, 0), 6.0000005)


def random_case(
    seed: int, height: int, width: int, dtype: type
) -> tuple[np.ndarray, np.ndarray, Intrinsics, np.ndarray]:
    """A blob mask (or scattered pixels), depth around 1-3 m with leaked background, holes and
    edge values, and a random pose."""
    rng = np.random.default_rng(seed)
    if rng.random() < 0.8:
        mask = ndimage.binary_dilation(rng.random((height, width)) > 0.97, iterations=3)
    else:
        mask = rng.random((height, width)) > 0.6
    depth = rng.normal(rng.uniform(1, 3), 0.02, (height, width))
    leaked = rng.random((height, width)) < 0.15
    depth[leaked] = rng.uniform(0.2, 7.0, int(leaked.sum()))
    odd = rng.random((height, width)) < 0.1
    depth[odd] = rng.choice(EDGE_DEPTHS, int(odd.sum()))
    angle = rng.uniform(0, 2 * math.pi)
    pose = np.eye(4)
    pose[:3, :3] = np.array(
        [
            [math.cos(angle), 0, math.sin(angle)],
            [0, 1, 0],
            [-math.sin(angle), 0, math.cos(angle)],
        ]
    )
    pose[:3, 3] = rng.uniform(-5, 5, 3)
    intrinsics = Intrinsics(
        width, height, 0.9 * width, 0.9 * width, width / 2 - 0.5, height / 2 + 0.25
    )
    return mask, depth.astype(dtype), intrinsics, pose


@settings(max_examples=150, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    size=st.tuples(st.integers(1, 40), st.integers(1, 50)),
    dtype=st.sampled_from([np.float32, np.float64]),
    erosion=st.integers(0, 3),
    samples=st.sampled_from([100, 20_000]),
    min_valid=st.sampled_from([1, 5, 40]),
    min_interior=st.sampled_from([1, 9, 400]),
)
def test_the_kernel_grounds_a_mask_as_the_numpy_rule_does(
    seed: int,
    size: tuple[int, int],
    dtype: type,
    erosion: int,
    samples: int,
    min_valid: int,
    min_interior: int,
) -> None:
    height, width = size
    mask, depth, intrinsics, pose = random_case(seed, height, width, dtype)
    params = ProposalParams(
        min_valid_depth_pixels=min_valid,
        boundary_erosion_px=erosion,
        min_interior_pixels=min_interior,
        max_mask_samples=samples,
    )
    frame = Frame("f", 0.0, intrinsics, pose, depth, ())
    detection = Detection("mug", 0.9, "object", Mask.from_array(mask), None)
    expected = reference_grounding(mask, depth, intrinsics, pose, params)
    proposal = ground_detection(detection, frame, params, NEAR, FAR)
    if expected is None:
        assert proposal is None
        return
    assert proposal is not None
    center, extent, valid_pixels, bottom_z = expected
    assert np.array_equal(proposal.center, center)
    assert np.array_equal(proposal.extent, extent)
    assert (proposal.valid_pixels, proposal.bottom_z) == (valid_pixels, bottom_z)


def test_a_large_mask_is_sampled_and_still_grounded_as_the_numpy_rule_does() -> None:
    mask, depth, intrinsics, pose = random_case(3, 240, 320, np.float32)
    mask[20:220, 30:300] = True  # 54,000 pixels, over the default 20,000 samples
    params = ProposalParams()
    proposal = ground_detection(
        Detection("table", 0.9, "object", Mask.from_array(mask), None),
        Frame("f", 0.0, intrinsics, pose, depth, ()),
        params,
        NEAR,
        FAR,
    )
    expected = reference_grounding(mask, depth, intrinsics, pose, params)
    assert proposal is not None and expected is not None
    assert np.array_equal(proposal.center, expected[0])
    assert proposal.valid_pixels == expected[2] and proposal.valid_pixels % 3 == 0  # stride 3


@pytest.mark.parametrize("radius", [1, 2, 3])
def test_the_kernel_s_erosion_matches_scipy(radius: int) -> None:
    rng = np.random.default_rng(radius)
    structure = np.ones((2 * radius + 1, 2 * radius + 1), bool)
    for _ in range(20):
        mask = ndimage.binary_dilation(rng.random((30, 40)) > 0.93, iterations=3)
        expected = ndimage.binary_erosion(mask, structure=structure, border_value=0)
        assert np.array_equal(_eroded(mask, radius), expected)
        assert np.array_equal(erode_square(mask, radius), expected)  # the reference's, too


def test_depth_exactly_on_the_band_s_edge_is_an_inlier() -> None:
    intrinsics = Intrinsics(20, 20, 18.0, 18.0, 9.5, 9.5)
    depth = np.full((20, 20), 1.0, np.float32)
    depth[:, 15:] = 1.5  # |1.5 - 1.0| is the band, exactly
    mask = np.zeros((20, 20), bool)
    mask[2:18, 2:18] = True
    params = ProposalParams(depth_inlier_min_band_m=0.5, min_valid_depth_pixels=10)
    proposal = ground_detection(
        Detection("box", 0.9, "object", Mask.from_array(mask), None),
        Frame("f", 0.0, intrinsics, np.eye(4), depth, ()),
        params,
        NEAR,
        FAR,
    )
    assert proposal is not None and proposal.valid_pixels == 16 * 16


def test_the_kernel_s_median_is_numpy_s() -> None:
    rng = np.random.default_rng(5)
    for size in [*range(1, 12), 100, 101, 2000]:
        for rounding in (None, 1, 0):
            values = rng.normal(2.0, 1.0, size)
            if rounding is not None:
                values = np.round(values, rounding)  # ties, and many equal values
            assert _median(values.copy()) == float(np.median(values))


@pytest.mark.parametrize(
    "fractions",
    # Both below or both above the median too: a scene may set any low < high.
    [(0.05, 0.95), (0.0, 1.0), (0.49, 0.51), (0.01, 0.99), (0.6, 0.9), (0.1, 0.3), (0.5, 1.0)],
)
def test_the_percentile_box_is_numpy_s_quantiles(fractions: tuple[float, float]) -> None:
    rng = np.random.default_rng(9)
    low, high = fractions
    for size in [*range(1, 25), 100, 101, 1999]:
        for rounding in (None, 1):
            points = rng.normal(0.0, 2.0, (size, 3))
            if rounding is not None:
                points = np.round(points, rounding)  # ties
            expected = column_quantiles(points, (low, 0.5, high))
            assert np.array_equal(percentile_box(points, low, high), expected)
            # numpy's own quantiles, to its rounding
            assert np.allclose(expected, np.quantile(points, [low, 0.5, high], axis=0))


def test_a_mask_of_another_size_than_the_depth_is_refused() -> None:
    intrinsics = Intrinsics(20, 10, 18.0, 18.0, 9.5, 4.5)
    frame = Frame("f", 0.0, intrinsics, np.eye(4), np.ones((10, 20), np.float32), ())
    transposed = Detection("box", 0.9, "object", Mask.from_array(np.ones((20, 10), bool)), None)
    with pytest.raises(ValueError, match="20 x 10 mask"):
        ground_detection(transposed, frame, ProposalParams(), NEAR, FAR)
