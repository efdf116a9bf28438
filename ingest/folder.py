"""Frames of a 7-Scenes / TUM-like folder: `frame-NNNNNN.depth.png` (16-bit), its
`frame-NNNNNN.pose.txt` (4x4 camera-to-world) and one `camera-intrinsics.txt` (3x3 K).

Every file is read inside the folder: one that a symbolic link leads out of it is an error.
`check()` goes over the selected frames before anything is sent: each pose file (a rigid
transform within the service's tolerances), each depth PNG's header (16-bit single channel, at
most `MAX_IMAGE_SIDE` pixels a side, read before any pixel is decoded) and chunk checksums (a
truncated PNG fails them), and the intrinsics for each image size. `frames()` decodes the pixels;
a PNG whose compressed data is corrupt behind valid checksums is found only then, still as one
error naming the frame and the file.
"""

from __future__ import annotations

import contextlib
import functools
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

import numpy as np
import numpy.typing as npt
from PIL import Image

from ingest.checks import (
    BadFile,
    bad_file_error,
    frame_error,
    intrinsics_problem,
    open_png,
    outside_problem,
    pose_problem,
    read_matrix,
)
from ingest.frames import (
    CameraIntrinsics,
    IngestError,
    SourceCounts,
    SourceFrame,
    check_reading_options,
    frame_window,
)

DEPTH_NAME = re.compile(r"frame-(\d+)\.depth\.png")
INTRINSICS_FILE = "camera-intrinsics.txt"
DEPTH_MODES = frozenset({"I;16", "I;16B", "I"})
UINT16_MAX = 65535
POSE_FIX = (
    "write the frame's 4x4 camera-to-world transform there (a rotation and a translation in "
    "metres, last row 0 0 0 1), or delete the file to skip the frame"
)
DEPTH_FIX = "replace it with the frame's 16-bit single-channel depth PNG, or delete the frame"
INTRINSICS_FIX = (
    "write the depth camera's 3x3 K matrix there (fx 0 cx / 0 fy cy / 0 0 1, in pixels, "
    "focal lengths positive, principal point inside the image)"
)
LINK_FIX = "copy the file into the folder instead of linking to it"
_T = TypeVar("_T")


class FolderSource:
    """The frames of a folder in the 7-Scenes layout, in frame-number order.

    `depth_scale` is metres per depth PNG unit (0.001: millimetres, as 7-Scenes; TUM uses 1/5000).
    `fps` turns frame numbers into timestamps (the layout has none). A frame without a pose file,
    or whose pose is not finite (tracking lost), is skipped and counted.
    """

    def __init__(
        self,
        path: Path,
        *,
        depth_scale: float = 0.001,
        stride: int = 1,
        limit: int | None = None,
        fps: float = 30.0,
    ) -> None:
        check_reading_options(stride, limit, depth_scale)
        if not path.is_dir():
            raise IngestError(f"folder {path} does not exist")
        self.path = path
        self.name = path.name or "folder"
        self.depth_scale = depth_scale
        self.stride, self.limit, self.fps = stride, limit, fps
        self.counts = SourceCounts()
        numbered = []
        for entry in path.iterdir():
            match = DEPTH_NAME.fullmatch(entry.name)
            if match:
                numbered.append((int(match.group(1)), entry))
        if not numbered:
            raise IngestError(f"folder {path} has no frame-NNNNNN.depth.png files")
        self.depth_files = [entry for _, entry in sorted(numbered)]
        self.numbers = [number for number, _ in sorted(numbered)]
        if not (path / INTRINSICS_FILE).is_file():
            raise IngestError(f"folder {path} has no {INTRINSICS_FILE} (a 3x3 K matrix)")
        self._intrinsics_by_size: dict[tuple[int, int], CameraIntrinsics] = {}

    def expected_frames(self) -> int | None:
        """Frames the stride and limit select."""
        selected = len(range(0, len(self.depth_files), self.stride))
        return selected if self.limit is None else min(selected, self.limit)

    def check(self, extra_topics: tuple[str, ...] = ()) -> None:
        """Check every selected frame as `frames()` reads it, decoding no pixel: the pose file,
        the depth PNG's header and checksums, the intrinsics for its size."""
        _no_topics(extra_topics)
        for number, depth_file in self._selected():
            frame = f"frame {number}"
            if isinstance(self._pose(frame, depth_file), str):
                continue
            with self._depth_png(frame, depth_file) as image:
                width, height = image.size
                _decoding(frame, depth_file, image.verify)
            self._intrinsics(frame, width, height)
            self._colour(frame, depth_file)

    def frames(self, extra_topics: tuple[str, ...] = ()) -> Iterator[SourceFrame]:
        """Each selected frame, its depth decoded; skipped frames are counted."""
        _no_topics(extra_topics)
        for number, depth_file in self._selected():
            frame = f"frame {number}"
            pose = self._pose(frame, depth_file)
            if isinstance(pose, str):
                self.counts.skip(pose)
                continue
            with self._depth_png(frame, depth_file) as image:
                pixels = _decoding(frame, depth_file, functools.partial(np.asarray, image))
                expected = (image.height, image.width)
            if pixels.shape != expected:
                raise frame_error(frame, depth_file, "holds more than one channel", DEPTH_FIX)
            if pixels.min() < 0 or pixels.max() > UINT16_MAX:  # mode I holds 32-bit values
                raise frame_error(
                    frame, depth_file, f"holds depth values outside 0..{UINT16_MAX}", DEPTH_FIX
                )
            depth: npt.NDArray[np.uint16] = pixels.astype(np.uint16)
            intrinsics = self._intrinsics(frame, width=depth.shape[1], height=depth.shape[0])
            self.counts.read += 1
            yield SourceFrame(
                index=number,
                frame_id=_beside(depth_file, "").name,
                timestamp=number / self.fps,
                depth=depth,
                intrinsics=intrinsics,
                pose=pose,
                depth_scale=self.depth_scale,
                colour_path=self._colour(frame, depth_file),
            )

    def _selected(self) -> Iterator[tuple[int, Path]]:
        """(frame number, depth file) of each frame the stride and limit select."""
        for position, (number, depth_file) in enumerate(
            zip(self.numbers, self.depth_files, strict=True)
        ):
            take, stop = frame_window(position, self.stride, self.limit)
            if stop:
                return
            if take:
                yield number, depth_file

    def _inside(self, frame: str, path: Path) -> None:
        """Refuse a file that a symbolic link leads out of the folder."""
        problem = outside_problem(path, self.path)
        if problem is not None:
            raise frame_error(frame, path, problem, LINK_FIX)

    def _pose(self, frame: str, depth_file: Path) -> npt.NDArray[np.float64] | str:
        """The frame's checked pose, or why the frame is skipped (no pose file, tracking lost)."""
        pose_file = _beside(depth_file, ".pose.txt")
        self._inside(frame, pose_file)
        if not pose_file.is_file():
            return "no pose file"
        try:
            pose = read_matrix(pose_file, 4, 4)
        except BadFile as bad:
            raise bad_file_error(frame, pose_file, bad, POSE_FIX) from bad
        if not np.isfinite(pose).all():
            return "pose is not finite (tracking lost)"
        problem = pose_problem(pose)
        if problem is not None:
            raise frame_error(frame, pose_file, problem, POSE_FIX)
        return pose

    @contextlib.contextmanager
    def _depth_png(self, frame: str, depth_file: Path) -> Iterator[Image.Image]:
        """The frame's depth PNG with its header read and checked: inside the folder, within
        the size limit, 16-bit single channel."""
        self._inside(frame, depth_file)
        try:
            with open_png(depth_file) as image:
                if image.mode not in DEPTH_MODES:
                    raise BadFile(f"is not a 16-bit single-channel PNG (Pillow mode {image.mode})")
                yield image
        except BadFile as bad:
            raise bad_file_error(frame, depth_file, bad, DEPTH_FIX) from bad

    def _intrinsics(self, frame: str, width: int, height: int) -> CameraIntrinsics:
        """The checked intrinsics of a `width` x `height` depth image (read once per size)."""
        known = self._intrinsics_by_size.get((width, height))
        if known is not None:
            return known
        path = self.path / INTRINSICS_FILE
        self._inside(frame, path)
        try:
            k = read_matrix(path, 3, 3)
        except BadFile as bad:
            raise bad_file_error(frame, path, bad, INTRINSICS_FIX) from bad
        intrinsics = CameraIntrinsics(
            width=width,
            height=height,
            fx=float(k[0, 0]),
            fy=float(k[1, 1]),
            cx=float(k[0, 2]),
            cy=float(k[1, 2]),
        )
        problem = intrinsics_problem(intrinsics)
        if problem is not None:
            problem = f"{problem}, for the frame's {width} x {height} depth image"
            raise frame_error(frame, path, problem, INTRINSICS_FIX)
        self._intrinsics_by_size[width, height] = intrinsics
        return intrinsics

    def _colour(self, frame: str, depth_file: Path) -> Path | None:
        """The colour image beside the depth (for detectors), if there is one."""
        colour = _beside(depth_file, ".color.jpg")
        self._inside(frame, colour)
        return colour if colour.is_file() else None


def _beside(depth_file: Path, suffix: str) -> Path:
    """The file of the same frame as `depth_file` with this suffix (`.pose.txt`...)."""
    return depth_file.with_name(depth_file.name.removesuffix(".depth.png") + suffix)


def _no_topics(extra_topics: tuple[str, ...]) -> None:
    """A folder has no topics for a detector to ask for."""
    if extra_topics:
        raise IngestError(
            f"a folder has no topics; the detector asks for {', '.join(extra_topics)}"
        )


def _decoding(frame: str, path: Path, step: Callable[[], _T]) -> _T:
    """`step` (decoding or verifying the PNG at `path`); any failure is one error naming it."""
    try:
        return step()
    except Exception as error:  # Pillow reports corrupt data through many types
        raise frame_error(
            frame, path, f"is truncated or corrupt ({type(error).__name__})", DEPTH_FIX
        ) from error
