"""A table with a 10 cm mug, rendered by the simulator and encoded in the wire format."""

from __future__ import annotations

from typing import Any

import numpy as np

from sim.camera import CameraModel, look_at
from sim.detector import detect
from sim.render import add_kinect_noise, render
from sim.wire import make_batch, make_frame
from sim.world import Box, World, object_on

CAMERA = CameraModel(width=320, height=240, fx=262.5, fy=262.5, cx=159.5, cy=119.5)
TABLE = Box("table", "table", (3.0, 2.5, 0.375), (1.2, 0.8, 0.75), kind="fixture")
MUG = object_on(TABLE, "mug", "mug", (0.1, 0.1, 0.1), at=(0.0, 0.0))
MUG_CENTER = np.array(MUG.center)
WORLD = World(room_size=(6.0, 5.0, 2.6), fixtures=(TABLE,), objects=(MUG,))
# Undetected and closer to the camera than the mug: hides it completely.
OCCLUDER = Box("screen", "screen", (3.0, 1.9, 0.95), (0.6, 0.05, 0.5), kind="occluder")


def eye_for(index: int) -> tuple[float, float, float]:
    """Viewpoints in front of the table, varied per batch."""
    return (2.7 + 0.15 * (index % 5), 1.2, 1.4)


def frame(world: World, index: int, *, look_away: bool = False, seed: int = 0) -> dict[str, Any]:
    """One rendered, noised and detected frame."""
    eye = eye_for(index)
    target = (eye[0], -3.0, 1.0) if look_away else tuple(MUG_CENTER)
    pose = look_at(eye, target)
    view = render(world, CAMERA, pose)
    rng = np.random.default_rng(seed + index)
    detections = detect(
        view, world, rng, min_visible_pixels=30, boundary_leak_px=1, embedding_noise=0.05
    )
    depth = add_kinect_noise(view.depth, rng)
    return make_frame(f"f{index:05d}", float(index), CAMERA, pose, depth, detections)


def batch(batch_id: str, world: World, index: int, **kwargs: Any) -> dict[str, Any]:
    """A one-frame batch."""
    return make_batch(batch_id, [frame(world, index, **kwargs)])
