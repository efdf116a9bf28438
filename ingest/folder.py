"""Frames of a 7-Scenes / TUM-like folder: `frame-NNNNNN.depth.png` (16-bit), its
`frame-NNNNNN.pose.txt` (4x4 camera-to-world) and one `camera-intrinsics.txt` (3x3 K)."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from PIL import Image

from ingest.frames import (
    CameraIntrinsics,
    IngestError,
    SourceCounts,
    SourceFrame,
    check_reading_options,
    frame_window,
)

DEPTH_NAME = re.compile(r"^frame-(\d+)\.depth\.png$")
INTRINSICS_FILE = "camera-intrinsics.txt"
UINT16_MAX = 65535


def read_intrinsics(path: Path, width: int, height: int) -> CameraIntrinsics:
    """Intrinsics from a 3x3 K matrix file (the image size comes from the depth image)."""
    try:
        matrix = np.loadtxt(path, dtype=np.float64)
    except ValueError as error:
        raise IngestError(f"{path}: not a 3x3 matrix of numbers ({error})") from error
    if matrix.shape != (3, 3):
        raise IngestError(f"{path}: expected a 3x3 K matrix, got shape {list(matrix.shape)}")
    return CameraIntrinsics(
        width=width,
        height=height,
        fx=float(matrix[0, 0]),
        fy=float(matrix[1, 1]),
        cx=float(matrix[0, 2]),
        cy=float(matrix[1, 2]),
    )


def read_pose(path: Path) -> np.ndarray:
    """A 4x4 camera-to-world pose file."""
    try:
        pose = np.loadtxt(path, dtype=np.float64)
    except ValueError as error:
        raise IngestError(f"{path}: not a 4x4 matrix of numbers ({error})") from error
    if pose.shape != (4, 4):
        raise IngestError(f"{path}: expected a 4x4 pose matrix, got shape {list(pose.shape)}")
    return pose


class FolderSource:
    """The frames of a folder in the 7-Scenes layout, in frame-number order.

    `depth_scale` is metres per depth PNG unit (0.001: millimetres, as 7-Scenes; TUM uses 1/5000).
    `fps` turns frame numbers into timestamps (the layout has none).
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
            match = DEPTH_NAME.match(entry.name)
            if match:
                numbered.append((int(match.group(1)), entry))
        if not numbered:
            raise IngestError(f"folder {path} has no frame-NNNNNN.depth.png files")
        self.depth_files = [entry for _, entry in sorted(numbered)]
        self.numbers = [number for number, _ in sorted(numbered)]
        if not (path / INTRINSICS_FILE).is_file():
            raise IngestError(f"folder {path} has no {INTRINSICS_FILE} (a 3x3 K matrix)")

    def expected_frames(self) -> int | None:
        """Frames the stride and limit select."""
        selected = len(range(0, len(self.depth_files), self.stride))
        return selected if self.limit is None else min(selected, self.limit)

    def frames(self, extra_topics: tuple[str, ...] = ()) -> Iterator[SourceFrame]:
        """Each selected frame; one without a pose file is skipped and counted."""
        if extra_topics:
            raise IngestError(
                f"a folder has no topics; the detector asks for {', '.join(extra_topics)}"
            )
        intrinsics: CameraIntrinsics | None = None
        for position, (number, depth_file) in enumerate(
            zip(self.numbers, self.depth_files, strict=True)
        ):
            take, stop = frame_window(position, self.stride, self.limit)
            if stop:
                return
            if not take:
                continue
            stem = depth_file.name.removesuffix(".depth.png")
            pose_file = depth_file.with_name(f"{stem}.pose.txt")
            if not pose_file.is_file():
                self.counts.skip("no pose file")
                continue
            pose = read_pose(pose_file)
            if not np.isfinite(pose).all():
                self.counts.skip("pose is not finite (tracking lost)")
                continue
            with Image.open(depth_file) as image:
                if image.mode not in ("I;16", "I;16B", "I"):
                    raise IngestError(
                        f"{depth_file}: expected a 16-bit single-channel PNG, got mode {image.mode}"
                    )
                pixels = np.asarray(image)
            if pixels.min() < 0 or pixels.max() > UINT16_MAX:  # mode I holds 32-bit values
                raise IngestError(f"{depth_file}: depth values outside 0..{UINT16_MAX}")
            depth = pixels.astype(np.uint16)
            if intrinsics is None or (intrinsics.height, intrinsics.width) != depth.shape:
                intrinsics = read_intrinsics(
                    self.path / INTRINSICS_FILE, width=depth.shape[1], height=depth.shape[0]
                )
            colour = depth_file.with_name(f"{stem}.color.jpg")
            self.counts.read += 1
            yield SourceFrame(
                index=number,
                frame_id=stem,
                timestamp=number / self.fps,
                depth=depth,
                intrinsics=intrinsics,
                pose=pose,
                depth_scale=self.depth_scale,
                colour_path=colour if colour.is_file() else None,
            )
