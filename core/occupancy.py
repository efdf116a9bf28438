"""The 2D occupancy map A_t (sections 3.1, 3.2): cells unknown, free or occupied.

The map is a square grid of `side` x `side` cells of `resolution_m`, centred on the world origin
(core/params.py, OccupancyParams). A cell is named by its row (y) and column (x), or by its flat
index `row * side + col`; cell (row, col) covers x in [(col - side // 2) * res, ... + res) and
likewise y. The state keeps only the window of the grid that evidence has reached, as one int8
per cell: UNKNOWN until some batch spoke of the cell, then a clamped integer, occupied above 0.

A batch's evidence (`occupancy_evidence`) lists the cells its depth saw free and occupied as
runs of sorted flat indices (gap, length, gap, length, ...): a view cone is a few hundred runs.
"""

from __future__ import annotations

import base64
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from core.params import OccupancyParams

Int8Array = npt.NDArray[np.int8]
IntArray = npt.NDArray[np.int64]
UNKNOWN = -128  # the value of a cell no batch has spoken of
# Codes of the map as served (JSON runs, PNG): one per cell.
CODE_UNKNOWN, CODE_FREE, CODE_OCCUPIED = 0, 1, 2
# The window grows in blocks of this many cells (aligned to the grid), so it depends only on
# which cells were ever touched, never on how the log was folded (snapshot or replay).
BLOCK = 32


def side_of(params: OccupancyParams) -> int:
    """Cells per side of the scene's grid."""
    return round(2 * params.half_extent_m / params.resolution_m)


@dataclass(frozen=True)
class MapGeometry:
    """Where the cells of a grid are in the world."""

    resolution_m: float
    side: int

    @classmethod
    def of(cls, params: OccupancyParams) -> MapGeometry:
        """The geometry of a scene's grid."""
        return cls(params.resolution_m, side_of(params))

    def cell_of(
        self, x: npt.NDArray[np.float64], y: npt.NDArray[np.float64]
    ) -> tuple[IntArray, IntArray, npt.NDArray[np.bool_]]:
        """Rows, columns and whether inside the grid, of world points."""
        half = self.side // 2
        with np.errstate(invalid="ignore"):
            col = np.floor(x / self.resolution_m)
            row = np.floor(y / self.resolution_m)
        inside = (
            np.isfinite(col)
            & np.isfinite(row)
            & (col >= -half)
            & (col < self.side - half)
            & (row >= -half)
            & (row < self.side - half)
        )
        col = np.where(inside, col, -half) + half
        row = np.where(inside, row, -half) + half
        return row.astype(np.int64), col.astype(np.int64), inside

    def center_of(self, row: Any, col: Any) -> tuple[Any, Any]:
        """World x, y of cell centres (scalars or arrays)."""
        half = self.side // 2
        return (
            (np.asarray(col, dtype=np.float64) - half + 0.5) * self.resolution_m,
            (np.asarray(row, dtype=np.float64) - half + 0.5) * self.resolution_m,
        )


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """The known window of the map: `values[r, c]` is the cell (origin[0] + r, origin[1] + c)."""

    origin: tuple[int, int]  # (row, col) of values[0, 0] in the scene's grid
    values: Int8Array  # read-only; UNKNOWN, or a clamped count (occupied above 0)

    @classmethod
    def empty(cls) -> OccupancyGrid:
        """A map where every cell is unknown."""
        values = np.zeros((0, 0), dtype=np.int8)
        values.setflags(write=False)
        return cls((0, 0), values)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) of the window."""
        rows, cols = self.values.shape
        return int(rows), int(cols)

    def codes(self) -> npt.NDArray[np.uint8]:
        """Per cell of the window: CODE_UNKNOWN, CODE_FREE or CODE_OCCUPIED."""
        codes = np.full(self.values.shape, CODE_FREE, dtype=np.uint8)
        codes[self.values > 0] = CODE_OCCUPIED
        codes[self.values == UNKNOWN] = CODE_UNKNOWN
        return codes

    def known_cells(self) -> int:
        """How many cells some batch has spoken of."""
        return int(np.count_nonzero(self.values != UNKNOWN))

    def to_dict(self) -> dict[str, Any]:
        """JSON-able form (snapshots): origin, shape, the int8 values as base64."""
        return {
            "origin": list(self.origin),
            "shape": list(self.shape),
            "values": base64.b64encode(np.ascontiguousarray(self.values).tobytes()).decode(),
        }

    @classmethod
    def from_dict(cls, record: Mapping[str, Any]) -> OccupancyGrid:
        """Inverse of `to_dict`."""
        rows, cols = (int(v) for v in record["shape"])
        values = np.frombuffer(base64.b64decode(record["values"]), dtype=np.int8)
        values = values.reshape(rows, cols).copy()
        values.setflags(write=False)
        return cls((int(record["origin"][0]), int(record["origin"][1])), values)

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, OccupancyGrid)
            and self.origin == other.origin
            and np.array_equal(self.values, other.values)
        )

    __hash__ = None  # type: ignore[assignment]


def runs_of(flat: IntArray) -> tuple[int, ...]:
    """Sorted unique flat indices as runs: gap from the previous run's end, length, ..."""
    if flat.size == 0:
        return ()
    breaks = np.flatnonzero(np.diff(flat) != 1) + 1
    starts = flat[np.concatenate(([0], breaks))]
    ends = flat[np.concatenate((breaks - 1, [flat.size - 1]))] + 1
    gaps = starts - np.concatenate(([0], ends[:-1]))
    return tuple(np.column_stack((gaps, ends - starts)).ravel().tolist())


def flat_of(runs: Sequence[int]) -> IntArray:
    """Inverse of `runs_of` (ValueError for a malformed run list)."""
    pairs = np.asarray(runs, dtype=np.int64)
    if pairs.size == 0:
        return np.zeros(0, np.int64)
    if pairs.size % 2 or (pairs < 0).any() or (pairs[1::2] < 1).any():
        raise ValueError("runs are pairs of a gap >= 0 and a length >= 1")
    gaps, lengths = pairs[0::2], pairs[1::2]
    starts = np.cumsum(gaps + np.concatenate(([0], lengths[:-1])))
    offsets = np.arange(int(lengths.sum())) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    flat: IntArray = np.repeat(starts, lengths) + offsets
    return flat


class GridWork:
    """A grid being folded: grown and updated in place, frozen at the end of a fold."""

    def __init__(self, grid: OccupancyGrid) -> None:
        self.origin = grid.origin
        self.values: Int8Array = grid.values.copy()

    def apply(
        self, side: int, free: Sequence[int], occupied: Sequence[int], params: OccupancyParams
    ) -> None:
        """One batch's evidence: free cells lose `free_hit`, occupied ones gain `occupied_hit`."""
        free_flat, occupied_flat = flat_of(free), flat_of(occupied)
        if free_flat.size + occupied_flat.size == 0:
            return
        both = np.concatenate((free_flat, occupied_flat))
        if both.max() >= side * side:
            raise ValueError(f"occupancy cell {int(both.max())} is outside a {side}-cell grid")
        rows, cols = np.divmod(both, side)
        self._cover(int(rows.min()), int(cols.min()), int(rows.max()), int(cols.max()))
        rows -= self.origin[0]
        cols -= self.origin[1]
        cells = self.values[rows, cols].astype(np.int16)
        cells[cells == UNKNOWN] = 0
        delta = np.concatenate(
            (
                np.full(free_flat.size, -params.free_hit, np.int16),
                np.full(occupied_flat.size, params.occupied_hit, np.int16),
            )
        )
        # A batch names a cell at most once (free and occupied are disjoint).
        self.values[rows, cols] = np.clip(cells + delta, params.min_value, params.max_value)

    def _cover(self, row_min: int, col_min: int, row_max: int, col_max: int) -> None:
        """Grow the window to the BLOCK-aligned box holding itself and these cells."""
        rows, cols = self.values.shape
        if rows:
            row_min, col_min = min(row_min, self.origin[0]), min(col_min, self.origin[1])
            row_max = max(row_max, self.origin[0] + rows - 1)
            col_max = max(col_max, self.origin[1] + cols - 1)
        r0, c0 = row_min // BLOCK * BLOCK, col_min // BLOCK * BLOCK
        r1, c1 = (row_max // BLOCK + 1) * BLOCK, (col_max // BLOCK + 1) * BLOCK
        if rows and (r0, c0) == self.origin and (r1 - r0, c1 - c0) == (rows, cols):
            return
        grown = np.full((r1 - r0, c1 - c0), UNKNOWN, dtype=np.int8)
        if rows:
            dr, dc = self.origin[0] - r0, self.origin[1] - c0
            grown[dr : dr + rows, dc : dc + cols] = self.values
        self.origin, self.values = (r0, c0), grown

    def frozen(self) -> OccupancyGrid:
        """The grid as state (read-only)."""
        values = self.values
        values.setflags(write=False)
        return OccupancyGrid(self.origin, values)
