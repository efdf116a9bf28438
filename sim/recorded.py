"""Recorded backgrounds: real 7-Scenes depth and poses, gravity-aligned, with virtual boxes on top."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

from sim.camera import CameraModel
from sim.render import Render

FLOOR_PERCENTILE = 2.0  # of point heights: low enough for the floor, robust to stray returns
FLOOR_SAMPLE_FRAMES = 12  # frames back-projected for the floor estimate
FLOOR_PIXEL_STRIDE = 8  # every 8th pixel in both directions: ~4800 points per frame
MILLIMETRES_PER_METRE = 1000.0


def read_depth(path: Path) -> np.ndarray:
    """A 16-bit millimetre depth PNG as float32 metres (0 stays 0: no measurement)."""
    with Image.open(path) as image:
        millimetres = np.asarray(image, dtype=np.uint16)
    return (millimetres.astype(np.float32) / np.float32(MILLIMETRES_PER_METRE)).astype(np.float32)


def rotation_onto(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vector `source` onto unit vector `target`."""
    source = source / np.linalg.norm(source)
    target = target / np.linalg.norm(target)
    axis = np.cross(source, target)
    sine, cosine = np.linalg.norm(axis), float(source @ target)
    if sine < 1e-12:
        if cosine > 0:
            return np.eye(3)
        # Opposite vectors: turn half way round any axis perpendicular to `source`.
        helper = np.eye(3)[np.argmin(np.abs(source))]
        perpendicular = np.cross(source, helper)
        perpendicular /= np.linalg.norm(perpendicular)
        return 2.0 * np.outer(perpendicular, perpendicular) - np.eye(3)
    skew = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    rotation: np.ndarray = np.eye(3) + skew + skew @ skew * ((1.0 - cosine) / sine**2)
    return rotation


def back_project(
    depth: np.ndarray, camera: CameraModel, pose: np.ndarray, stride: int = 1
) -> np.ndarray:
    """World points (M, 3) of the valid pixels on a `stride` grid, for camera-to-world `pose`."""
    rows, cols = np.mgrid[0 : camera.height : stride, 0 : camera.width : stride]
    z = depth[rows, cols]
    valid = z > 0
    x = (cols[valid] - camera.cx) / camera.fx * z[valid]
    y = (rows[valid] - camera.cy) / camera.fy * z[valid]
    points = np.column_stack([x, y, z[valid]])
    world_points: np.ndarray = points @ pose[:3, :3].T + pose[:3, 3]
    return world_points


@dataclass(frozen=True, eq=False)
class RecordedSequence:
    """Selected frames of a recording, with poses already in the gravity-aligned scenario frame."""

    folder: Path
    source_frames: tuple[int, ...]  # frame numbers in the recording
    camera: CameraModel
    poses: np.ndarray  # (N, 4, 4) camera-to-world, scenario frame
    alignment: np.ndarray  # (4, 4) world_scenario <- world_recording
    up: np.ndarray  # (3,) up in the recording's world frame

    def depth(self, index: int) -> np.ndarray:
        """Real depth (float32 metres) of the index-th selected frame."""
        return read_depth(self.folder / f"frame-{self.source_frames[index]:06d}.depth.png")


def _read_pose(folder: Path, frame: int) -> np.ndarray:
    """The recording's 4x4 camera-to-world pose of one frame."""
    return np.loadtxt(folder / f"frame-{frame:06d}.pose.txt").reshape(4, 4)


@functools.lru_cache(maxsize=4)
def load_recorded(
    folder: Path, frames: tuple[int, int, int], min_depth: float = 0.3, max_depth: float = 6.0
) -> RecordedSequence:
    """Poses and intrinsics of `range(*frames)`, plus the transform that puts up at +z, floor at 0."""
    source_frames = tuple(range(*frames))
    first_depth = read_depth(folder / f"frame-{source_frames[0]:06d}.depth.png")
    intrinsic = np.loadtxt(folder / "camera-intrinsics.txt").reshape(3, 3)
    camera = CameraModel(
        width=first_depth.shape[1],
        height=first_depth.shape[0],
        fx=float(intrinsic[0, 0]),
        fy=float(intrinsic[1, 1]),
        cx=float(intrinsic[0, 2]),
        cy=float(intrinsic[1, 2]),
        min_depth=min_depth,
        max_depth=max_depth,
    )
    raw_poses = np.stack([_read_pose(folder, frame) for frame in source_frames])
    gravity = np.loadtxt(folder / "gravity-direction.txt").reshape(3)
    up = -gravity / np.linalg.norm(gravity)
    rotation = rotation_onto(up, np.array([0.0, 0.0, 1.0]))
    # The floor is the low tail of the real points' heights; a handful of frames suffices.
    picks = np.unique(np.linspace(0, len(source_frames) - 1, FLOOR_SAMPLE_FRAMES).astype(int))
    points = np.vstack(
        [
            back_project(
                first_depth
                if index == 0
                else read_depth(folder / f"frame-{source_frames[index]:06d}.depth.png"),
                camera,
                raw_poses[index],
                FLOOR_PIXEL_STRIDE,
            )
            for index in picks
        ]
    )
    floor_height = float(np.percentile(points @ rotation[2], FLOOR_PERCENTILE))
    mean_xy = (raw_poses[:, :3, 3] @ rotation.T)[:, :2].mean(axis=0)
    alignment = np.eye(4)
    alignment[:3, :3] = rotation
    alignment[:3, 3] = -np.array([mean_xy[0], mean_xy[1], floor_height])
    poses = alignment @ raw_poses
    return RecordedSequence(folder, source_frames, camera, poses, alignment, up)


def composite(virtual: Render, real_depth: np.ndarray) -> tuple[Render, np.ndarray]:
    """Virtual boxes merged into real depth by a per-pixel depth test; also the winning pixels."""
    # Real occluders in front of a virtual box hide it; holes in the real depth never do.
    wins = (virtual.depth > 0) & ((real_depth <= 0) | (virtual.depth < real_depth))
    depth = np.where(wins, virtual.depth, real_depth).astype(np.float32)
    instance = np.where(wins, virtual.instance, -1).astype(np.int32)
    fixture_instance = np.where(wins, virtual.fixture_instance, -1).astype(np.int32)
    occluder_instance = (
        None
        if virtual.occluder_instance is None
        else np.where(wins, virtual.occluder_instance, -1).astype(np.int32)
    )
    composited = Render(
        depth, instance, fixture_instance, virtual.camera, virtual.pose, occluder_instance
    )
    return composited, wins
