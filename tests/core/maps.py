"""Hand-built occupancy maps for planner tests: strings of '.', '#' and '?'."""

from __future__ import annotations

import numpy as np

from core.occupancy import UNKNOWN, MapGeometry, OccupancyGrid
from core.params import Params

GEOMETRY = MapGeometry.of(Params().occupancy)  # 5 cm cells, 4000 per side


def grid_of(lines: list[str]) -> OccupancyGrid:
    """A map: '.' free, '#' occupied, '?' unknown. The first string is the top row (largest y);
    the bottom-left cell is the one at the world origin, x and y in [0, 0.05)."""
    rows = len(lines)
    values = np.full((rows, len(lines[0])), UNKNOWN, dtype=np.int8)
    for i, line in enumerate(lines):
        for j, char in enumerate(line):
            if char != "?":
                values[rows - 1 - i, j] = 3 if char == "#" else -1
    values.setflags(write=False)
    half = GEOMETRY.side // 2
    return OccupancyGrid((half, half), values)


def paint(lines: list[str], x0: float, y0: float, x1: float, y1: float, char: str) -> list[str]:
    """The map with the cells whose centres lie in [x0, x1] x [y0, y1] set to `char`."""
    rows = [list(line) for line in lines]
    height = len(rows)
    for i in range(height):
        y = (height - 1 - i + 0.5) * 0.05
        for j in range(len(rows[i])):
            x = (j + 0.5) * 0.05
            if x0 <= x <= x1 and y0 <= y <= y1:
                rows[i][j] = char
    return ["".join(row) for row in rows]


def room(width_m: float, depth_m: float) -> list[str]:
    """A walled room: free inside, one cell of wall on every side."""
    cols, rows = round(width_m / 0.05), round(depth_m / 0.05)
    return ["#" * cols, *("#" + "." * (cols - 2) + "#" for _ in range(rows - 2)), "#" * cols]
