"""One mask's valid, interior and inlier depth, and its percentile box (section 3.2), compiled
by numba.

The rule (`core.geometry.ground_detection`): the mask's pixels with depth in range, the
interior left by a square erosion of the mask cut to the valid pixels' box, the median and MAD
of the interior's depth (or of all valid depth when the interior is small), and the points of
the pixels within the band; their median and percentile box. In numpy those were some thirty
array operations on a mask of a few thousand pixels, where each operation's own cost outweighed
its work. These kernels walk the mask's run lengths once and compute the same values, bit for
bit: integer steps and order statistics are exact, and each floating-point expression is the
numpy one's, in its order, with depth compared in its own precision as numpy compares an array
with a Python float. tests/core/test_grounding_kernel.py keeps the numpy statement of the rule
and compares the two on random masks and depth.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from core.compiled import compiled

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


@compiled()
def _select(values: FloatArray, k: int) -> None:  # pragma: no cover - compiled
    """Rearrange `values` in place so that values[k] is its k-th smallest, none left of it
    larger and none right of it smaller (Hoare's selection with a median-of-three pivot)."""
    lo, hi = 0, values.size
    while hi - lo > 2:
        mid = (lo + hi - 1) // 2
        a, b, c = values[lo], values[mid], values[hi - 1]
        pivot = max(min(a, b), min(max(a, b), c))
        i, j = lo, hi - 1
        while i <= j:
            # The bounds are checked too: no value scanned past the array's ends, whatever it
            # holds (a NaN, which compares false both ways, could not stop a plain scan).
            while i < hi and values[i] < pivot:
                i += 1
            while j >= lo and values[j] > pivot:
                j -= 1
            if i <= j:
                values[i], values[j] = values[j], values[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j + 1
        elif k >= i:
            lo = i
        else:
            return
    if hi - lo == 2 and values[lo] > values[lo + 1]:
        values[lo], values[lo + 1] = values[lo + 1], values[lo]


@compiled()
def _select_in(values: FloatArray, k: int, lo: int, hi: int) -> None:  # pragma: no cover
    """`_select` within values[lo:hi] (k in it): the rest of the array is left as it is."""
    _select(values[lo:hi], k - lo)


@compiled()
def _least(values: FloatArray, lo: int, hi: int) -> float:  # pragma: no cover - compiled
    """The least of values[lo:hi] (not empty)."""
    least = values[lo]
    for index in range(lo + 1, hi):
        if values[index] < least:
            least = values[index]
    return float(least)


@compiled()
def percentile_box(points: FloatArray, low: float, high: float) -> FloatArray:  # pragma: no cover
    """Rows: each column's `low`, median and `high` quantiles (fractions, low < high), linearly
    interpolated as numpy's default method is (between the order statistics a and b around the
    position, a (1 - w) + b w; np.quantile rounds its own formula differently). The middle of
    the three order statistics is selected first, the least of them left of it and the greatest
    right of it; the statistic after each is the least value between it and the next selected."""
    count = points.shape[0]
    last = count - 1
    result = np.empty((3, points.shape[1]))
    column = np.empty(count)
    fractions = (low, 0.5, high)
    ks = sorted([int(np.floor(fraction * last)) for fraction in fractions])
    for axis in range(points.shape[1]):
        for row in range(count):
            column[row] = points[row, axis]
        _select(column, ks[1])
        if ks[0] < ks[1]:
            _select_in(column, ks[0], 0, ks[1])
        if ks[2] > ks[1]:
            _select_in(column, ks[2], ks[1] + 1, count)
        for index in range(3):
            position = fractions[index] * last
            k = int(np.floor(position))
            weight = position - k
            value = column[k]
            # The next order statistic: the least value after k, up to the next one selected.
            end = count
            for selected in ks:
                if selected > k:
                    end = selected + 1
                    break
            following = value if k + 1 > last else _least(column, k + 1, end)
            result[index, axis] = value * (1.0 - weight) + following * weight
    return result


@compiled()
def _median(values: FloatArray) -> float:  # pragma: no cover - compiled
    """`np.median` of a non-empty array without NaN, rearranging it: the middle order statistic,
    or the mean of the two middle ones (the lower is the largest value left of the upper)."""
    count = values.size
    middle = count // 2
    _select(values, middle)
    if count % 2:
        return float(values[middle])
    lower = values[0]
    for index in range(1, middle):
        lower = max(lower, values[index])
    return float((lower + values[middle]) / 2)


@compiled()
def _mask_box(runs: IntArray, height: int) -> tuple[int, int, int, int]:  # pragma: no cover
    """(top, bottom, left, right), inclusive, of the pixels a COCO run-length mask sets
    (column-major runs, zeros first); (0, -1, 0, -1) for an empty mask."""
    top, bottom, left, right = height, -1, -1, -1
    position = 0
    for index in range(runs.size):
        length = runs[index]
        if index % 2 == 1 and length > 0:
            first, last = position, position + length - 1
            if left < 0:
                left = first // height
            right = last // height
            if last // height > first // height:  # the run wraps over a column's end
                top, bottom = 0, height - 1
            else:
                top = min(top, first % height)
                bottom = max(bottom, last % height)
        position += length
    if left < 0:
        return 0, -1, 0, -1
    return top, bottom, left, right


@compiled()
def _draw(
    runs: IntArray, height: int, top: int, left: int, rows: int, cols: int
) -> npt.NDArray[np.bool_]:  # pragma: no cover
    """The mask drawn on its own box (rows x cols from (top, left))."""
    drawn = np.zeros((rows, cols), np.bool_)
    position = 0
    for index in range(runs.size):
        length = runs[index]
        if index % 2 == 1:
            for pixel in range(position, position + length):
                drawn[pixel % height - top, pixel // height - left] = True
        position += length
    return drawn


@compiled()
def _eroded(crop: npt.NDArray[np.bool_], radius: int) -> npt.NDArray[np.bool_]:  # pragma: no cover
    """Binary erosion by a (2r+1)^2 square, outside the array counting as background (as
    scipy's `binary_erosion` with `border_value=0`; the tests compare the two)."""
    rows, cols = crop.shape
    across = np.zeros((rows, cols), np.bool_)
    for row in range(rows):
        run = 0  # set pixels ending here
        for col in range(cols):
            run = run + 1 if crop[row, col] else 0
            centre = col - radius
            if centre >= radius and run >= 2 * radius + 1:
                across[row, centre] = True
    eroded = np.zeros((rows, cols), np.bool_)
    for col in range(radius, cols - radius):
        run = 0
        for row in range(rows):
            run = run + 1 if across[row, col] else 0
            centre = row - radius
            if centre >= radius and run >= 2 * radius + 1:
                eroded[centre, col] = True
    return eroded


@compiled()
def mask_points(
    runs: IntArray,
    height: int,
    width: int,
    depth: npt.NDArray[np.floating],
    near: np.floating,
    far: np.floating,
    camera: tuple[float, float, float, float],
    rules: tuple[int, int, int, int, float, float],
) -> tuple[FloatArray, int]:  # pragma: no cover - compiled
    """Camera-frame points (n, 3) of a mask's inlier depth and the inlier pixel count
    (estimated for a sampled mask), or an empty array and -1 when the mask has too little
    valid depth or too few inliers. `depth` is the frame's, flat; `near` and `far` are the range
    in its dtype; `camera` is (fx, fy, cx, cy); `rules` is (min valid pixels, max samples,
    erosion px, min interior pixels, inlier MAD k, inlier min band)."""
    min_valid, max_samples, erosion, min_interior, mad_k, min_band = rules
    fx, fy, cx, cy = camera
    none = np.zeros((0, 3))
    top, bottom, left, right = _mask_box(runs, height)
    rows, cols = bottom - top + 1, right - left + 1
    if rows <= 0:
        return none, -1
    drawn = _draw(runs, height, top, left, rows, cols)
    # The mask's pixels with depth in range, in C order, with their box.
    flat = np.empty(rows * cols, np.int64)
    valid_depth = np.empty(rows * cols)
    valid = 0
    r0, r1, c0, c1 = rows, -1, cols, -1
    for row in range(rows):
        for col in range(cols):
            if drawn[row, col]:
                index = (top + row) * width + left + col
                value = depth[index]
                if value >= near and value <= far:
                    flat[valid] = index
                    valid_depth[valid] = np.float64(value)
                    valid += 1
                    r0, r1 = min(r0, row), max(r1, row)
                    c0, c1 = min(c0, col), max(c1, col)
    if valid < min_valid:
        return none, -1
    stride = -(-valid // max_samples)
    sampled = (valid + stride - 1) // stride
    sample_index = flat[:valid:stride].copy()
    sample_depth = valid_depth[:valid:stride].copy()
    # The interior: the mask cut to the valid pixels' box, eroded; its pixels with depth in
    # range, sampled on the same stride among all interior pixels.
    interior = np.empty(sampled if erosion <= 0 else (r1 - r0 + 1) * (c1 - c0 + 1))
    inside = 0
    if erosion <= 0:
        interior[:sampled] = sample_depth
        inside = sampled
    else:
        eroded = _eroded(drawn[r0 : r1 + 1, c0 : c1 + 1], erosion)
        counted = 0
        for row in range(r1 - r0 + 1):
            for col in range(c1 - c0 + 1):
                if eroded[row, col]:
                    if counted % stride == 0:
                        value = depth[(top + r0 + row) * width + left + c0 + col]
                        if value >= near and value <= far:
                            interior[inside] = np.float64(value)
                            inside += 1
                    counted += 1
    reference = interior[:inside] if inside >= min_interior else sample_depth
    median = _median(reference.copy())
    mad = 1.4826 * _median(np.abs(reference - median))
    band = max(min_band, mad_k * mad)
    keep = np.abs(sample_depth - median) <= band
    count = int(keep.sum())
    if count * stride < min_valid:
        return none, -1
    points = np.empty((count, 3))
    written = 0
    for sample in range(sampled):
        if keep[sample]:
            v, u = divmod(sample_index[sample], width)
            value = sample_depth[sample]
            points[written, 0] = (u - cx) / fx * value
            points[written, 1] = (v - cy) / fy * value
            points[written, 2] = value
            written += 1
    return points, count * stride
