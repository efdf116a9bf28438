"""Core frames of a room with a table and a counter, ray cast here in numpy (boxes without yaw,
as the simulator's scenes place them): fixtures seen partially, with class-score masks.

The core tests use their own small ray caster rather than the simulator's (open3d), so they run
in a service-only install; tests/sim checks the simulator's renderer itself.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from core.masks import Mask
from core.observation import Batch, Detection, Frame, Intrinsics
from core.values import Vec3
from sim.camera import CameraModel, look_at


@dataclass(frozen=True)
class Box:
    """An axis-aligned box."""

    id: str
    label: str
    center: Vec3
    size: Vec3
    kind: str = "object"

    @property
    def top_z(self) -> float:
        """Height of the upper face."""
        return self.center[2] + self.size[2] / 2.0


@dataclass(frozen=True)
class World:
    """A room (corner at the origin) with fixtures and objects."""

    room_size: Vec3
    fixtures: tuple[Box, ...]
    objects: tuple[Box, ...]

    def with_object(self, box: Box) -> World:
        """One more object, appended (existing instance indices stay put)."""
        return dataclasses.replace(self, objects=(*self.objects, box))

    def moved(self, object_id: str, new_center: Vec3) -> World:
        """One object placed at a new center (same index, same size)."""
        objects = tuple(
            dataclasses.replace(box, center=new_center) if box.id == object_id else box
            for box in self.objects
        )
        return dataclasses.replace(self, objects=objects)


def object_on(
    fixture: Box, object_id: str, label: str, size: Vec3, at: tuple[float, float] = (0.0, 0.0)
) -> Box:
    """An object resting on the fixture's top, offset by `at`."""
    center = (
        fixture.center[0] + at[0],
        fixture.center[1] + at[1],
        fixture.top_z + size[2] / 2.0,
    )
    return Box(object_id, label, center, size)


@dataclass(frozen=True)
class Render:
    """z-depth (0 = no return) and the index of the object or fixture each pixel sees (-1)."""

    depth: np.ndarray
    instance: np.ndarray
    fixture_instance: np.ndarray


def _slabs(origin: np.ndarray, directions: np.ndarray, box: Box) -> tuple[np.ndarray, np.ndarray]:
    """Entry and exit ray parameters of every ray through an axis-aligned box (slab method)."""
    low = np.asarray(box.center) - np.asarray(box.size) / 2.0
    high = np.asarray(box.center) + np.asarray(box.size) / 2.0
    with np.errstate(divide="ignore", invalid="ignore"):
        t_low = (low - origin) / directions
        t_high = (high - origin) / directions
    return np.nanmax(np.minimum(t_low, t_high), axis=1), np.nanmin(
        np.maximum(t_low, t_high), axis=1
    )


def render(world: World, camera: CameraModel, pose: np.ndarray) -> Render:
    """Cast one ray per pixel center; a ray's direction has unit length along the optical axis,
    so the ray parameter of the first hit is its z-depth."""
    v, u = np.mgrid[0 : camera.height, 0 : camera.width]
    in_camera = np.stack(
        [(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones(u.shape)], axis=-1
    ).reshape(-1, 3)
    directions = in_camera @ np.asarray(pose)[:3, :3].T
    origin = np.asarray(pose)[:3, 3]
    sx, sy, height = world.room_size
    room = Box("room", "room", (sx / 2, sy / 2, height / 2), (sx, sy, height))
    nearest = _slabs(origin, directions, room)[1]  # from inside: where the ray leaves the room
    instance = np.full(nearest.shape, -1, dtype=np.int32)
    fixture_instance = np.full(nearest.shape, -1, dtype=np.int32)
    for group, boxes in ((fixture_instance, world.fixtures), (instance, world.objects)):
        for index, box in enumerate(boxes):
            enter, leave = _slabs(origin, directions, box)
            hit = (enter <= leave) & (enter > 0) & (enter < nearest)
            nearest = np.where(hit, enter, nearest)
            instance[hit] = -1
            fixture_instance[hit] = -1
            group[hit] = index
    depth = nearest.astype(np.float32)
    depth[~((depth >= camera.min_depth) & (depth <= camera.max_depth))] = 0.0
    shape = (camera.height, camera.width)
    return Render(depth.reshape(shape), instance.reshape(shape), fixture_instance.reshape(shape))


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
    embeddings: Mapping[str, np.ndarray] | None = None,
    t: float = 0.0,
) -> Frame:
    """A rendered frame at time `t` with fixture masks (class scores) and object masks (with
    the appearance `embeddings` gives an object by its id)."""
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
                embedding = None if embeddings is None else embeddings.get(box.id)
                detections.append(
                    Detection(box.label, 0.9, "object", Mask.from_array(mask), embedding)
                )
    return Frame(frame_id, t, INTRINSICS, pose, view.depth.astype(np.float32), tuple(detections))


def batches(
    world: World,
    views: Iterable[tuple[Vec3, Vec3]],
    prefix: str,
    scores: Mapping[str, Mapping[str, float]] = SCORES,
    objects: bool = True,
    embeddings: Mapping[str, np.ndarray] | None = None,
    t0: float | None = None,
) -> list[Batch]:
    """One single-frame batch per viewpoint: at time 0, or with `t0` a second apart from it."""
    return [
        Batch(
            f"{prefix}{i}",
            (
                frame(
                    world,
                    eye,
                    target,
                    f"{prefix}{i}",
                    scores,
                    objects,
                    embeddings,
                    0.0 if t0 is None else t0 + i,
                ),
            ),
        )
        for i, (eye, target) in enumerate(views)
    ]
