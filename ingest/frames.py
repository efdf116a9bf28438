"""What a frame source yields: one posed depth frame, and the interface every source follows."""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np
import numpy.typing as npt

from api_schema.requests import Intrinsics
from pbdag_errors import Refused


class IngestError(Refused):
    """A problem with the user's input (a missing file or topic, a bad option, a bad frame): one
    line that never quotes a file's content, no traceback."""


def one_line(text: str) -> str:
    """`text` with its control characters (newlines included) written as escapes."""
    return re.sub(r"[\x00-\x1f\x7f]", lambda match: repr(match.group())[1:-1], text)


class SkipFrame(Exception):
    """Raised by a detector (or a source) when a frame cannot be used; the reason is counted.
    A signal within `ingest`, not an error: it never leaves the source, so it stays outside the
    project's hierarchy.

    A frame without its detections must not be sent with none: the service would take every
    object in view as missed.
    """

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics of the depth image, in pixels."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def wire(self) -> Intrinsics:
        """The wire's intrinsics (its model checks the bounds: ValidationError beyond them)."""
        return Intrinsics(
            width=self.width,
            height=self.height,
            fx=float(self.fx),
            fy=float(self.fy),
            cx=float(self.cx),
            cy=float(self.cy),
        )


@dataclass(frozen=True)
class SourceFrame:
    """One posed depth frame.

    `depth` is either uint16 (metres = value x `depth_scale`, 0 = no measurement) or float32
    metres (0 or NaN = no measurement). `pose` is the 4x4 camera-to-world transform, OpenCV
    camera axes (x right, y down, z forward), metres.
    """

    index: int  # position in the source's depth stream (before stride and limit)
    frame_id: str
    timestamp: float  # seconds
    depth: npt.NDArray[np.uint16] | npt.NDArray[np.float32]
    intrinsics: CameraIntrinsics
    pose: npt.NDArray[np.float64]
    depth_scale: float = 0.001
    stamp_ns: int | None = None  # the ROS header stamp, for bags
    colour_path: Path | None = None  # an image file beside the depth, for folders
    # Messages of the extra topics a detector asked for, synchronised to this frame's stamp.
    messages: Mapping[str, object] = field(default_factory=dict)

    def depth_metres(self) -> npt.NDArray[np.float32]:
        """Depth in metres, 0 where there is no measurement."""
        if self.depth.dtype == np.uint16:
            return (self.depth.astype(np.float64) * self.depth_scale).astype(np.float32)
        metres = np.asarray(self.depth, dtype=np.float32).copy()
        metres[~np.isfinite(metres)] = 0.0
        return metres


@dataclass
class SourceCounts:
    """What a source read and what it had to skip, by reason."""

    read: int = 0
    skipped: dict[str, int] = field(default_factory=dict)

    def skip(self, reason: str) -> None:
        """Count one skipped frame."""
        self.skipped[reason] = self.skipped.get(reason, 0) + 1


class FrameSource(Protocol):
    """A recording that yields posed depth frames in time order."""

    name: str  # short name of the recording (used in batch ids)
    counts: SourceCounts

    def expected_frames(self) -> int | None:
        """How many frames `frames()` will try (for the progress bar), when known."""
        ...

    def check(self, extra_topics: tuple[str, ...] = ()) -> None:
        """Go over the frames `frames()` would yield, keeping none, and raise IngestError for the
        first bad one (a file, pose, intrinsics or image size), so that nothing is sent."""
        ...

    def frames(self, extra_topics: tuple[str, ...] = ()) -> Iterator[SourceFrame]:
        """The frames, with the messages of `extra_topics` synchronised (bags only)."""
        ...


def frame_window(position: int, stride: int, limit: int | None) -> tuple[bool, bool]:
    """(take this position, stop now): every `stride`-th frame of the stream, the first `limit`
    of those (skipped ones count: `--limit 20` looks at 20 frames)."""
    if limit is not None and position >= limit * stride:
        return False, True
    return position % stride == 0, False


def check_reading_options(stride: int, limit: int | None, depth_scale: float) -> None:
    """Reject a stride below 1, a negative limit or a depth scale outside (0, 1] metres per unit
    with a clear message."""
    if not 0 < depth_scale <= 1:
        raise IngestError(f"--depth-scale must be in (0, 1] metres per unit, got {depth_scale}")
    if stride < 1:
        raise IngestError(f"--stride must be at least 1, got {stride}")
    if limit is not None and limit < 0:
        raise IngestError(f"--limit must not be negative, got {limit}")
