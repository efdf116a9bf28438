"""Values: what events and states are made of. This module imports nothing of the core.

Events hold only these (besides numbers, strings, tuples and mappings), so what the log stores
never changes when an in-memory record (a `Track`, the scene state) does.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import numpy as np
import numpy.typing as npt
from pydantic import ConfigDict, Field

Vec3 = tuple[float, float, float]


def vec3(values: Sequence[float] | npt.NDArray[np.float64]) -> Vec3:
    """Three floats from an array or sequence."""
    return (float(values[0]), float(values[1]), float(values[2]))


# "retired": a hypothesis never published and no longer believed (a false positive, a glimpse):
# it leaves the association pool and the visibility gate for good.
LifecycleState = Literal["tentative", "confirmed", "demoted", "removed", "retired"]
TrackKind = Literal["object", "fixture"]
VerificationStatus = Literal["pending", "confirmed", "rejected"]
InspectionStatus = Literal["completed", "abandoned"]

# Only finite numbers are stored: a log with NaN or infinity could not be replayed.
FINITE = ConfigDict(allow_inf_nan=False)


def _absent_when_none(value: object) -> bool:
    return value is None


# A payload key that the log omits (rather than storing null) when it does not apply.
Omitted = Field(exclude_if=_absent_when_none)


@dataclass(frozen=True, kw_only=True)
class ViewPose:
    """A planar robot pose in the world frame: metres and radians (yaw about z, from +x)."""

    __pydantic_config__ = FINITE
    x: float
    y: float
    yaw: float

    def to_dict(self) -> dict[str, float]:
        """JSON-able form."""
        return {"x": self.x, "y": self.y, "yaw": self.yaw}

    @classmethod
    def from_dict(cls, record: Mapping[str, Any]) -> ViewPose:
        """Inverse of `to_dict`."""
        return cls(x=float(record["x"]), y=float(record["y"]), yaw=float(record["yaw"]))


@dataclass(frozen=True, kw_only=True)
class Observation:
    """One grounded observation of a track in a batch (a proposal, or a fixture cluster)."""

    __pydantic_config__ = FINITE
    frame_id: str
    label: str
    score: float
    center: Vec3
    extent: Vec3
    valid_pixels: int  # inlier pixels of an object mask; voxels of a fixture cluster
    parent: str | None  # support parent from geometry, None when on nothing known
    # The detector's scores of other classes, when it gave them: the observation's unit of
    # class evidence is spread over them (older logs: the label alone).
    class_scores: Annotated[Mapping[str, float] | None, Omitted] = None


@dataclass(frozen=True, kw_only=True)
class VoxelDetection:
    """One fixture mask's contribution to the voxel map: class similarities and covered voxels."""

    __pydantic_config__ = FINITE
    frame_id: str
    class_scores: tuple[float, ...]  # in the order of params.fixtures.taxonomy
    voxels: tuple[int, ...]  # flat (x, y, z) integer voxel keys


@dataclass(frozen=True, kw_only=True)
class BaselineSource:
    """The frozen package a session started from."""

    __pydantic_config__ = FINITE
    scene_id: str
    version: int
    sha256: str


@dataclass(frozen=True, kw_only=True)
class BaselineFixture:
    """A fixture of a frozen baseline, as a new session loads it (sections 3.1, 3.2): its
    identity, class evidence, existence and box. Loaded, it is confirmed, pinned and published
    where it stands (core/baseline.py builds the track)."""

    __pydantic_config__ = FINITE
    track_id: str
    class_evidence: Mapping[str, float]
    existence_logodds: float
    center: Vec3
    extent: Vec3
