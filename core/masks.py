"""Binary masks kept as COCO run lengths, decoded one at a time when a stage needs the pixels.

A batch may carry hundreds of masks of a multi-megapixel frame; decoded all at once they would
take gigabytes. Run lengths are small, and the overlap of two masks (non-maximum suppression)
is computed on the runs themselves, as pycocotools' `rleIou` does, without decoding either.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt

IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True, eq=False)
class Mask:
    """A height x width binary mask: COCO run lengths, zeros first, column-major."""

    height: int
    width: int
    runs: IntArray  # validated: non-negative, summing to height * width

    @classmethod
    def from_array(cls, mask: BoolArray) -> Mask:
        """Run lengths of a boolean (height, width) array."""
        height, width = mask.shape
        column_major = np.asarray(mask, dtype=bool).T.reshape(-1)
        changes = np.flatnonzero(column_major[1:] != column_major[:-1]) + 1
        bounds = np.concatenate(([0], changes, [column_major.size]))
        runs = np.diff(bounds).astype(np.int64)
        if column_major.size and column_major[0]:
            runs = np.concatenate(([0], runs))  # COCO runs start with the zeros
        return cls(height, width, runs)

    def to_array(self) -> BoolArray:
        """The (height, width) boolean array, C-ordered (decoded anew on every call)."""
        values = np.arange(self.runs.size) % 2 == 1
        column_major = np.repeat(values, self.runs)
        return np.ascontiguousarray(column_major.reshape(self.width, self.height).T)

    @cached_property
    def intervals(self) -> tuple[IntArray, IntArray]:
        """[start, end) of each run of ones, in column-major pixel order."""
        ends = np.cumsum(self.runs)
        starts = ends - self.runs
        ones = np.arange(self.runs.size) % 2 == 1
        keep = ones & (self.runs > 0)
        return starts[keep], ends[keep]

    def flat_indices(self) -> npt.NDArray[np.intp]:
        """Sorted C-order flat indices of the pixels set.

        A small mask is expanded from its runs (work in proportion to its area, then a sort); a
        large one is decoded whole, which is linear in the frame and needs no sort.
        """
        if self.area * 16 > self.height * self.width:
            dense: npt.NDArray[np.intp] = np.flatnonzero(self.to_array())
            return dense
        starts, ends = self.intervals
        lengths = ends - starts
        offsets = np.arange(int(lengths.sum())) - np.repeat(np.cumsum(lengths) - lengths, lengths)
        column_major = np.repeat(starts, lengths) + offsets
        column, row = np.divmod(column_major, self.height)
        flat: npt.NDArray[np.intp] = (row * self.width + column).astype(np.intp)
        flat.sort()
        return flat

    def strided_indices(self, stride: int) -> npt.NDArray[np.intp]:
        """Sorted C-order flat indices of the pixels set whose row and column are multiples of
        `stride`: `flat_indices()` thinned to that lattice, found by looking each lattice pixel
        up in the runs (work in proportion to the lattice, not to the mask's area)."""
        starts, ends = self.intervals
        if starts.size == 0:
            return np.zeros(0, dtype=np.intp)
        rows = np.arange(0, self.height, stride)
        first, last = starts[0] // self.height, (ends[-1] - 1) // self.height  # columns set
        columns = np.arange(-(-first // stride) * stride, last + 1, stride)
        column_major = (columns[None, :] * self.height + rows[:, None]).ravel()
        run = np.searchsorted(ends, column_major, side="right")
        inside = run < ends.size
        inside[inside] = starts[run[inside]] <= column_major[inside]
        flat: npt.NDArray[np.intp] = (
            (rows[:, None] * self.width + columns[None, :]).ravel()[inside].astype(np.intp)
        )
        return flat

    @property
    def area(self) -> int:
        """Number of pixels set."""
        return int(self.runs[1::2].sum())


def intersection_area(a: Mask, b: Mask) -> int:
    """Pixels set in both masks, from their runs (both of one frame size)."""
    a_start, a_end = a.intervals
    b_start, b_end = b.intervals
    if a_start.size == 0 or b_start.size == 0:
        return 0
    # For each run of a, the runs of b that may overlap it form a contiguous range (runs of one
    # mask are sorted and disjoint); walk the overlapping pairs with one searchsorted each side.
    first = np.searchsorted(b_end, a_start, side="right")
    last = np.searchsorted(b_start, a_end, side="left")
    counts = np.maximum(last - first, 0)
    if not counts.any():
        return 0
    a_index = np.repeat(np.arange(a_start.size), counts)
    offsets = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    b_index = np.repeat(first, counts) + offsets
    overlap = np.minimum(a_end[a_index], b_end[b_index]) - np.maximum(
        a_start[a_index], b_start[b_index]
    )
    return int(np.maximum(overlap, 0).sum())


def mask_iou(a: Mask, b: Mask) -> float:
    """Intersection over union of two masks (0 when both are empty)."""
    intersection = intersection_area(a, b)
    union = a.area + b.area - intersection
    return intersection / union if union else 0.0
