"""What the route shows: a quick low-resolution render of every frame, per object and fixture.

The generator times its events from it (an object carried away while out of view, a place seen
before another), and the tests measure occlusion with the same definition on the full render.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sim.camera import CameraModel
from sim.render import render
from sim.scenario_spec import Scenario
from sim.stream import frame_source
from sim.timeline import Timeline

PLAN_SCALE = 4  # the planning render is this many times coarser along each image axis
SEEN_PIXELS = 150  # what the detector needs at 640 x 480 (the realistic detector's default)
# An object counts as hidden in a frame when its centre is in the camera's view, the camera
# stands in the object's room, and fewer than this many of its pixels show (at 640 x 480).
HIDDEN_PIXELS = 40
Rect = tuple[float, float, float, float]


@dataclass(frozen=True)
class Sightings:
    """Per object: visible pixels per frame (at full resolution), and whether it is in view."""

    pixels: dict[str, np.ndarray]
    in_view: dict[str, np.ndarray]  # centre in the frustum and camera in the object's room

    def seen(self, object_id: str) -> np.ndarray:
        """Frames where the detector could report the object."""
        seen: np.ndarray = self.pixels[object_id] >= SEEN_PIXELS
        return seen


def in_view(camera: CameraModel, pose: np.ndarray, point: Sequence[float]) -> bool:
    """Whether a world point projects into the image within the depth range."""
    world_to_camera = np.linalg.inv(pose)
    x, y, z = world_to_camera[:3, :3] @ np.asarray(point, dtype=np.float64) + world_to_camera[:3, 3]
    if not camera.min_depth <= z <= camera.max_depth:
        return False
    u, v = camera.fx * x / z + camera.cx, camera.fy * y / z + camera.cy
    return bool(0 <= u < camera.width and 0 <= v < camera.height)


def room_of(rooms: Sequence[Rect], x: float, y: float) -> int:
    """Index of the room holding a point (-1 outside every room)."""
    for index, (x0, y0, x1, y1) in enumerate(rooms):
        if x0 <= x <= x1 and y0 <= y <= y1:
            return index
    return -1


def hidden_fraction(pixels: Sequence[int], in_view_frames: Sequence[bool]) -> float | None:
    """Share of an object's in-view frames it is hidden (None when it is never in view)."""
    frames = [count for count, shown in zip(pixels, in_view_frames, strict=True) if shown]
    if not frames:
        return None
    return sum(count < HIDDEN_PIXELS for count in frames) / len(frames)


def sightings(scenario: Scenario, rooms: Sequence[Rect], scale: int = PLAN_SCALE) -> Sightings:
    """Render every frame at 1/scale resolution; pixel counts scaled back to full resolution."""
    timeline, source = Timeline(scenario), frame_source(scenario)
    camera = source.camera
    coarse = dataclasses.replace(
        camera,
        width=camera.width // scale,
        height=camera.height // scale,
        fx=camera.fx / scale,
        fy=camera.fy / scale,
        cx=(camera.cx + 0.5) / scale - 0.5,
        cy=(camera.cy + 0.5) / scale - 0.5,
    )
    pixels = {spec.id: np.zeros(scenario.frames, dtype=np.int64) for spec in scenario.objects}
    shown = {spec.id: np.zeros(scenario.frames, dtype=bool) for spec in scenario.objects}
    for frame_index, pose in enumerate(source.poses):
        world = timeline.world(frame_index)
        view = render(world, coarse, pose)
        counts = np.bincount(view.instance.ravel() + 1, minlength=len(world.objects) + 1)[1:]
        camera_room = room_of(rooms, float(pose[0, 3]), float(pose[1, 3]))
        for box, count in zip(world.objects, counts, strict=True):
            pixels[box.id][frame_index] = int(count) * scale * scale
            shown[box.id][frame_index] = camera_room == room_of(
                rooms, box.center[0], box.center[1]
            ) and in_view(camera, pose, box.center)
    return Sightings(pixels, shown)
