"""Rigid transforms from ROS messages: quaternions, a tf tree with chain lookup, time sync.

Conventions follow tf2: a transform stamped `parent -> child` is the pose of the child frame in
the parent frame (it maps child coordinates to parent coordinates), so the pose of a camera in
the map is the product of the transforms along the tree path from the map down to the camera.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from pbdag_errors import Refused

Matrix = npt.NDArray[np.float64]


def quaternion_matrix(x: float, y: float, z: float, w: float) -> Matrix:
    """3x3 rotation of a quaternion (normalised first, as ROS tools do)."""
    norm = float(np.sqrt(x * x + y * y + z * z + w * w))
    if norm < 1e-9:
        raise ValueError("a zero quaternion is not a rotation")
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def rigid(translation: Sequence[float], quaternion: Sequence[float]) -> Matrix:
    """4x4 transform of a translation (x, y, z) and a quaternion (x, y, z, w)."""
    matrix = np.eye(4)
    matrix[:3, :3] = quaternion_matrix(*quaternion)
    matrix[:3, 3] = translation
    return matrix


def invert(transform: Matrix) -> Matrix:
    """Inverse of a rigid 4x4 transform."""
    inverse = np.eye(4)
    rotation = transform[:3, :3]
    inverse[:3, :3] = rotation.T
    inverse[:3, 3] = -rotation.T @ transform[:3, 3]
    return inverse


def nearest(stamps: Sequence[int], stamp: int, tolerance: int) -> int | None:
    """Index of the sorted `stamps` entry nearest to `stamp`, if within `tolerance` (same unit)."""
    position = bisect.bisect_left(stamps, stamp)
    candidates = [i for i in (position - 1, position) if 0 <= i < len(stamps)]
    if not candidates:
        return None
    best = min(candidates, key=lambda i: abs(stamps[i] - stamp))
    return best if abs(stamps[best] - stamp) <= tolerance else None


@dataclass
class TimedTransforms:
    """The transforms of one tf edge over time, sorted by stamp (nanoseconds)."""

    stamps: list[int] = field(default_factory=list)
    matrices: list[Matrix] = field(default_factory=list)

    def add(self, stamp: int, matrix: Matrix) -> None:
        """Insert keeping the stamps sorted (bags are nearly sorted: appends are the rule)."""
        position = bisect.bisect_right(self.stamps, stamp)
        self.stamps.insert(position, stamp)
        self.matrices.insert(position, matrix)

    def at(self, stamp: int, tolerance: int) -> Matrix | None:
        """The transform nearest in time to `stamp`, if within `tolerance`."""
        index = nearest(self.stamps, stamp, tolerance)
        return None if index is None else self.matrices[index]


class TransformLookupError(Refused):
    """A transform chain that cannot be composed at a stamp; the message says which link."""


class DisconnectedFrames(TransformLookupError):
    """Frames the tree does not hold or connect at any time (a naming error, not a gap)."""


class TransformTree:
    """A tf tree from /tf (timed) and /tf_static (timeless) transforms."""

    def __init__(self) -> None:
        self.parent_of: dict[str, str] = {}
        self.static: dict[str, Matrix] = {}  # child -> pose in its parent
        self.timed: dict[str, TimedTransforms] = {}  # child -> its poses in its parent over time

    def add(self, parent: str, child: str, stamp: int, matrix: Matrix, *, static: bool) -> None:
        """Record one transform `parent -> child` (a frame has one parent, as in tf2)."""
        parent, child = parent.lstrip("/"), child.lstrip("/")
        known = self.parent_of.get(child)
        if known is not None and known != parent:
            raise TransformLookupError(
                f"frame {child!r} has two parents in the transforms: {known!r} and {parent!r}"
            )
        self.parent_of[child] = parent
        if static:
            self.static[child] = matrix
        else:
            self.timed.setdefault(child, TimedTransforms()).add(stamp, matrix)

    def frames(self) -> set[str]:
        """Every frame named by a transform."""
        return set(self.parent_of) | set(self.parent_of.values())

    def _ancestors(self, frame: str) -> list[str]:
        """The frame, its parent, its grandparent... up to the root."""
        chain = [frame]
        while chain[-1] in self.parent_of:
            chain.append(self.parent_of[chain[-1]])
            if len(chain) > len(self.parent_of) + 1:
                raise TransformLookupError(f"the transforms form a loop through {frame!r}")
        return chain

    def _edge(self, child: str, stamp: int, tolerance: int) -> Matrix:
        """Pose of `child` in its parent at `stamp`."""
        if child in self.static:
            return self.static[child]
        found = self.timed[child].at(stamp, tolerance)
        if found is None:
            parent = self.parent_of[child]
            raise TransformLookupError(
                f"no transform {parent!r} -> {child!r} within {tolerance / 1e9:g} s of "
                f"t = {stamp / 1e9:.3f} s"
            )
        return found

    def lookup(self, target: str, source: str, stamp: int, tolerance: int) -> Matrix:
        """Pose of frame `source` in frame `target` at `stamp` (ns): maps source to target
        coordinates. Each timed link is taken at its nearest stamp within `tolerance` (ns)."""
        target, source = target.lstrip("/"), source.lstrip("/")
        known = self.frames()
        for role, name in (("target", target), ("source", source)):
            if name not in known:
                raise DisconnectedFrames(
                    f"frame {name!r} ({role}) is not in the transforms; frames seen: "
                    f"{', '.join(sorted(known)) or 'none'}"
                )
        up_from_source = self._ancestors(source)
        up_from_target = self._ancestors(target)
        common = next((frame for frame in up_from_source if frame in up_from_target), None)
        if common is None:
            raise DisconnectedFrames(
                f"frames {target!r} and {source!r} are not connected: their roots are "
                f"{up_from_target[-1]!r} and {up_from_source[-1]!r}"
            )
        # Pose of each frame in the common ancestor: the product of the links down to it.
        source_in_common = np.eye(4)
        for child in up_from_source[: up_from_source.index(common)]:
            source_in_common = self._edge(child, stamp, tolerance) @ source_in_common
        target_in_common = np.eye(4)
        for child in up_from_target[: up_from_target.index(common)]:
            target_in_common = self._edge(child, stamp, tolerance) @ target_in_common
        return invert(target_in_common) @ source_in_common


def quaternion_of(rotation: Matrix) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a 3x3 rotation (Shepperd's method: the largest diagonal term first)."""
    m = np.asarray(rotation, dtype=np.float64)
    trace = float(m[0, 0] + m[1, 1] + m[2, 2])
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        w, x = 0.25 * s, (m[2, 1] - m[1, 2]) / s
        y, z = (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        w, x = (m[2, 1] - m[1, 2]) / s, 0.25 * s
        y, z = (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        w, x = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s
        y, z = 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        w, x = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s
        y, z = (m[1, 2] + m[2, 1]) / s, 0.25 * s
    return float(x), float(y), float(z), float(w)
