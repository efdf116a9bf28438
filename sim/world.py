"""The simulated world: a box room with fixtures, objects and occluders, plus its raycast scene."""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np
import open3d as o3d

Vec3 = tuple[float, float, float]

# The 12 triangles of a unit box, indexing the 8 corners produced by `box_corners`.
BOX_TRIANGLES = np.array(
    [
        [0, 2, 1], [0, 3, 2],  # bottom (z-)
        [4, 5, 6], [4, 6, 7],  # top (z+)
        [0, 1, 5], [0, 5, 4],  # y- side
        [2, 3, 7], [2, 7, 6],  # y+ side
        [1, 2, 6], [1, 6, 5],  # x+ side
        [3, 0, 4], [3, 4, 7],  # x- side
    ],
    dtype=np.uint32,
)  # fmt: skip

# Open3D tensors live here. Its stubs make Tensor's dtype and device required, so callers spell
# out what Open3D would pick by itself: the array's own dtype, on this device.
CPU = o3d.core.Device("CPU:0")


@dataclass(frozen=True)
class Box:
    """An axis-aligned-in-z box, optionally turned about z: the only shape the world knows."""

    id: str
    label: str
    center: Vec3
    size: Vec3
    yaw: float = 0.0
    kind: str = "object"  # "object", "fixture" or "occluder"

    @property
    def top_z(self) -> float:
        """Height of the box's upper face."""
        return self.center[2] + self.size[2] / 2.0


@dataclass(frozen=True)
class World:
    """Everything the camera can see; frozen so it can key the raycast-scene cache."""

    room_size: Vec3
    fixtures: tuple[Box, ...]
    objects: tuple[Box, ...]
    occluders: tuple[Box, ...] = ()
    include_room: bool = True  # False for recorded backgrounds, whose real depth is the room

    def object_index(self, object_id: str) -> int:
        """Position of an object in `objects` (the value the instance map uses)."""
        for index, box in enumerate(self.objects):
            if box.id == object_id:
                return index
        raise KeyError(f"no object {object_id!r} in the world")

    def object_by_id(self, object_id: str) -> Box:
        """The object with this id."""
        return self.objects[self.object_index(object_id)]

    def without(self, object_id: str) -> World:
        """The world with one object removed."""
        index = self.object_index(object_id)
        return dataclasses.replace(self, objects=self.objects[:index] + self.objects[index + 1 :])

    def with_object(self, box: Box) -> World:
        """The world with one more object (appended, so existing instance indices stay put)."""
        if any(existing.id == box.id for existing in self.objects):
            raise ValueError(f"object {box.id!r} already in the world")
        return dataclasses.replace(self, objects=(*self.objects, box))

    def moved(self, object_id: str, new_center: Vec3) -> World:
        """The world with one object placed at a new center (same index, same size)."""
        index = self.object_index(object_id)
        relocated = dataclasses.replace(self.objects[index], center=_as_vec3(new_center))
        objects = (*self.objects[:index], relocated, *self.objects[index + 1 :])
        return dataclasses.replace(self, objects=objects)

    def with_occluder(self, box: Box) -> World:
        """The world with one more occluder (never detected, only hides things)."""
        occluder = dataclasses.replace(box, kind="occluder")
        return dataclasses.replace(self, occluders=(*self.occluders, occluder))

    def with_people(self, people: tuple[Box, ...]) -> World:
        """The world with people walking in it: occluders of kind "person" (appended)."""
        if not people:
            return self
        walkers = tuple(dataclasses.replace(box, kind="person") for box in people)
        return dataclasses.replace(self, occluders=(*self.occluders, *walkers))


def _as_vec3(values: tuple[float, ...] | list[float] | np.ndarray) -> Vec3:
    """Plain float triple, so boxes stay hashable whatever the caller passed."""
    x, y, z = (float(value) for value in values)
    return (x, y, z)


def object_on(
    fixture: Box,
    object_id: str,
    label: str,
    size: Vec3,
    at: tuple[float, float] = (0.0, 0.0),
    yaw: float = 0.0,
) -> Box:
    """An object resting on the fixture's top, offset by `at` (in the fixture's own x/y axes)."""
    cos_yaw, sin_yaw = math.cos(fixture.yaw), math.sin(fixture.yaw)
    dx, dy = at
    center = (
        fixture.center[0] + cos_yaw * dx - sin_yaw * dy,
        fixture.center[1] + sin_yaw * dx + cos_yaw * dy,
        fixture.top_z + size[2] / 2.0,
    )
    return Box(object_id, label, _as_vec3(center), _as_vec3(size), yaw=fixture.yaw + yaw)


def box_corners(box: Box) -> np.ndarray:
    """The 8 world-frame corners (bottom four counter-clockwise, then the top four)."""
    half = np.asarray(box.size, dtype=np.float64) / 2.0
    signs = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)
    local_xy = signs * half[:2]
    cos_yaw, sin_yaw = math.cos(box.yaw), math.sin(box.yaw)
    rotation = np.array([[cos_yaw, -sin_yaw], [sin_yaw, cos_yaw]])
    world_xy = local_xy @ rotation.T + np.asarray(box.center[:2])
    bottom = np.column_stack([world_xy, np.full(4, box.center[2] - half[2])])
    top = np.column_stack([world_xy, np.full(4, box.center[2] + half[2])])
    return np.vstack([bottom, top])


@dataclass(frozen=True, eq=False)
class SceneGeometry:
    """A built raycast scene and what each of its geometry ids stands for."""

    scene: o3d.t.geometry.RaycastingScene
    box_by_geometry: dict[int, Box | None]  # None marks the room's own surfaces
    object_lookup: np.ndarray  # geometry id -> index into world.objects, -1 for the rest
    fixture_lookup: np.ndarray  # geometry id -> index into world.fixtures, -1 for the rest
    occluder_lookup: np.ndarray  # geometry id -> index into world.occluders, -1 for the rest


def _add_box(scene: o3d.t.geometry.RaycastingScene, corners: np.ndarray) -> int:
    """Add one box's triangles to the scene and return its geometry id."""
    vertices = o3d.core.Tensor(corners.astype(np.float32), o3d.core.float32, CPU)
    triangles = o3d.core.Tensor(BOX_TRIANGLES, o3d.core.uint32, CPU)
    return int(scene.add_triangles(vertices, triangles))


def _room_box(world: World) -> Box:
    """The room as one box whose inner faces are floor, ceiling and walls."""
    sx, sy, height = world.room_size
    return Box("room", "room", (sx / 2.0, sy / 2.0, height / 2.0), (sx, sy, height), kind="room")


@functools.lru_cache(maxsize=8)
def build_scene(world: World) -> SceneGeometry:
    """Raycast scene of the room and every box; cached because worlds repeat frame after frame."""
    scene = o3d.t.geometry.RaycastingScene()
    # Triangles are two-sided for the raycaster, so the room box needs no inward-facing winding.
    placed: list[tuple[int, Box | None, str, int]] = []
    if world.include_room:
        placed.append((_add_box(scene, box_corners(_room_box(world))), None, "room", -1))
    for group, boxes in (
        ("fixture", world.fixtures),
        ("object", world.objects),
        ("occluder", world.occluders),
    ):
        placed.extend(
            (_add_box(scene, box_corners(box)), box, group, index)
            for index, box in enumerate(boxes)
        )
    # At least one slot: render gathers misses through slot 0 even when the scene is empty.
    lookup_size = max((geometry_id for geometry_id, *_ in placed), default=0) + 1
    object_lookup = np.full(lookup_size, -1, dtype=np.int32)
    fixture_lookup = np.full(lookup_size, -1, dtype=np.int32)
    occluder_lookup = np.full(lookup_size, -1, dtype=np.int32)
    lookups = {"object": object_lookup, "fixture": fixture_lookup, "occluder": occluder_lookup}
    for geometry_id, _, group, index in placed:
        if group in lookups:
            lookups[group][geometry_id] = index
    box_by_geometry = {geometry_id: box for geometry_id, box, *_ in placed}
    return SceneGeometry(scene, box_by_geometry, object_lookup, fixture_lookup, occluder_lookup)
