"""Support-parent evidence from geometry (section 3.3, p_parent): what an object rests on."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from core.fixtures import footprint_of
from core.params import FixtureParams


@dataclass(frozen=True)
class SupportSurface:
    """A fixture's top surface: its identity, planar box and top height."""

    track_id: str
    center: tuple[float, float, float]
    extent: tuple[float, float, float]

    @property
    def top_z(self) -> float:
        """Height of the top surface."""
        return self.center[2] + self.extent[2] / 2


def support_of(
    center: Sequence[float] | npt.NDArray[np.float64],
    bottom_z: float,
    surfaces: Sequence[SupportSurface],
    params: FixtureParams,
) -> str | None:
    """The fixture whose top the object's bottom rests on, with its center over the footprint.

    Among candidates, the closest top wins (ties by id), so a shelf above a counter is not
    taken for the counter.
    """
    best: tuple[float, str] | None = None
    for surface in surfaces:
        box = footprint_of(surface.center, surface.extent, params.support_footprint_margin_m)
        if not (box[0] <= center[0] <= box[2] and box[1] <= center[1] <= box[3]):
            continue
        gap = abs(bottom_z - surface.top_z)
        if gap <= params.support_height_tolerance_m and (
            best is None or (gap, surface.track_id) < best
        ):
            best = (gap, surface.track_id)
    return None if best is None else best[1]
