"""Core frames rendered by the simulator: fixtures seen partially, with class-score masks."""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

from core.masks import Mask
from core.observation import Batch, Detection, Frame, Intrinsics
from core.state import Vec3
from sim.camera import CameraModel, look_at
from sim.render import render
from sim.world import Box, World, object_on

CAMERA = CameraModel(width=320, height=240, fx=200.0, fy=200.0, cx=159.5, cy=119.5)
INTRINSICS = Intrinsics(CAMERA.width, CAMERA.height, CAMERA.fx, CAMERA.fy, CAMERA.cx, CAMERA.cy)
TABLE = Box("table", "table", (2.0, 2.0, 0.375), (1.4, 0.8, 0.75), kind="fixture")
COUNTER = Box("counter", "counter", (4.6, 3.7, 0.45), (2.0, 0.6, 0.9), kind="fixture")
MUG = object_on(TABLE, "mug", "mug", (0.1, 0.1, 0.1), at=(0.3, 0.0))
ROOM = World(room_size=(6.0, 5.0, 2.6), fixtures=(TABLE, COUNTER), objects=(MUG,))
SCORES = {
    "table": {"table": 0.62, "desk": 0.31, "counter": 0.22},
    "counter": {"counter": 0.60, "table": 0.30, "cabinet": 0.28},
}
# Viewpoints that each see part of a fixture, never all of it.
TABLE_VIEWS = [
    ((1.2, 0.9, 1.3), (1.6, 2.0, 0.7)),
    ((2.8, 0.9, 1.3), (2.4, 2.0, 0.7)),
    ((2.0, 3.2, 1.3), (2.0, 2.0, 0.7)),
]
COUNTER_VIEWS = [
    ((3.8, 2.2, 1.4), (4.1, 3.7, 0.8)),
    ((5.4, 2.2, 1.4), (5.1, 3.7, 0.8)),
    ((4.6, 2.0, 1.5), (4.6, 3.7, 0.8)),
]


def frame(
    world: World,
    eye: Vec3,
    target: Vec3,
    frame_id: str,
    scores: Mapping[str, Mapping[str, float]] = SCORES,
    objects: bool = True,
) -> Frame:
    """A rendered frame with fixture masks (class scores) and object masks."""
    pose = look_at(eye, target)
    view = render(world, CAMERA, pose)
    detections = []
    for index, fixture in enumerate(world.fixtures):
        mask = view.fixture_instance == index
        if mask.sum() >= 200:
            fixture_scores = scores[fixture.id]
            top = max(fixture_scores, key=fixture_scores.__getitem__)
            detections.append(
                Detection(
                    top, fixture_scores[top], "fixture", Mask.from_array(mask), None, fixture_scores
                )
            )
    if objects:
        for index, box in enumerate(world.objects):
            mask = view.instance == index
            if mask.sum() >= 30:
                detections.append(Detection(box.label, 0.9, "object", Mask.from_array(mask), None))
    return Frame(frame_id, 0.0, INTRINSICS, pose, view.depth.astype(np.float32), tuple(detections))


def batches(
    world: World,
    views: Iterable[tuple[Vec3, Vec3]],
    prefix: str,
    scores: Mapping[str, Mapping[str, float]] = SCORES,
    objects: bool = True,
) -> list[Batch]:
    """One single-frame batch per viewpoint."""
    return [
        Batch(f"{prefix}{i}", (frame(world, eye, target, f"{prefix}{i}", scores, objects),))
        for i, (eye, target) in enumerate(views)
    ]
