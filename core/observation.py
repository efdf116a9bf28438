"""Decoded observations: what `decide` consumes (the service's codec builds these from the wire)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import numpy.typing as npt

from core.masks import Mask

DetectionKind = Literal["object", "fixture"]


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of one frame, in pixels."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float


@dataclass(frozen=True, eq=False)
class Detection:
    """One 2D detection: a boolean mask of the frame's size plus its label evidence."""

    label: str
    score: float
    kind: DetectionKind
    mask: Mask  # the frame's size; run lengths, decoded by the stage that needs the pixels
    embedding: npt.NDArray[np.float64] | None = None  # raw appearance vector, not normalized
    class_scores: Mapping[str, float] | None = None


@dataclass(frozen=True, eq=False)
class Frame:
    """One posed depth frame with its detections."""

    frame_id: str
    timestamp: float
    intrinsics: Intrinsics
    pose: npt.NDArray[np.float64]  # (4, 4) camera-to-world, OpenCV camera axes, metres
    depth: npt.NDArray[np.float32]  # (height, width) metres; 0 marks an invalid pixel
    detections: tuple[Detection, ...] = field(default_factory=tuple)


@dataclass(frozen=True, eq=False)
class Batch:
    """One semantic update batch: the unit t of equation (3)."""

    batch_id: str
    frames: tuple[Frame, ...]
