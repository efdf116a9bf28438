"""Consistency checks of a parsed scenario: ids, supports, event order and a walkable camera path."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from sim.scenario_fields import ScenarioError, Vec2
from sim.scenario_parts import EventSpec, FixtureSpec, ObjectSpec, OccluderSpec, WallSpec
from sim.scenario_spec import Scenario
from sim.trajectory import path_samples, trajectory_poses
from sim.world import Box

CAMERA_CLEARANCE_M = 0.1  # the camera keeps this far from furniture footprints and walls


def _inside_footprint(point: np.ndarray, box: Box, margin: float) -> bool:
    """Whether a point's x, y lies in the box's footprint grown by `margin`."""
    dx, dy = point[0] - box.center[0], point[1] - box.center[1]
    cos_yaw, sin_yaw = math.cos(box.yaw), math.sin(box.yaw)
    local_x, local_y = cos_yaw * dx + sin_yaw * dy, -sin_yaw * dx + cos_yaw * dy
    return bool(
        abs(local_x) <= box.size[0] / 2 + margin and abs(local_y) <= box.size[1] / 2 + margin
    )


def _half_extents_on(obj_size: tuple[float, ...], relative_yaw: float) -> tuple[float, float]:
    """Half extents, along the support's axes, of an object turned by `relative_yaw`."""
    cos_yaw, sin_yaw = abs(math.cos(relative_yaw)), abs(math.sin(relative_yaw))
    half_x, half_y = obj_size[0] / 2, obj_size[1] / 2
    return cos_yaw * half_x + sin_yaw * half_y, sin_yaw * half_x + cos_yaw * half_y


def check_fits(
    where: str,
    object_id: str,
    size: tuple[float, ...],
    yaw: float,
    at: tuple[float, float],
    support: FixtureSpec,
) -> None:
    """Fail unless the object's footprint at offset `at` stays on the support's top."""
    half_x, half_y = _half_extents_on(size, yaw)
    if abs(at[0]) + half_x > support.size[0] / 2 or abs(at[1]) + half_y > support.size[1] / 2:
        raise ScenarioError(
            f"{where}: {object_id!r} at {list(at)} hangs over the edge of {support.id!r} "
            f"(top {support.size[0]} x {support.size[1]} m, offsets from its center)"
        )


def check_layout(
    room_size: tuple[float, float, float] | None,
    walls: Sequence[WallSpec],
    fixtures: Sequence[FixtureSpec],
    occluders: Sequence[OccluderSpec],
    objects: Sequence[ObjectSpec],
    listed_count: int,
) -> None:
    """Unique ids, fixtures inside the room, objects on known supports and on their tops."""
    seen: dict[str, str] = {}
    for section, specs in (("fixtures", fixtures), ("occluders", occluders), ("objects", objects)):
        for index, spec in enumerate[FixtureSpec | OccluderSpec | ObjectSpec](specs):
            if spec.id in seen:
                raise ScenarioError(
                    f"{section}[{index}].id: {spec.id!r} is also used by {seen[spec.id]}"
                )
            seen[spec.id] = f"{section}[{index}]"
    if room_size is not None:
        for section, specs in (("fixtures", fixtures), ("occluders", occluders)):
            for index, spec in enumerate[FixtureSpec | OccluderSpec](specs):
                corners = _footprint_corners(spec.box())
                if corners.min() < -1e-9 or (corners > np.array(room_size[:2]) + 1e-9).any():
                    raise ScenarioError(f"{section}[{index}].center: {spec.id!r} leaves the room")
        for index, wall in enumerate(walls):
            if wall.height > room_size[2]:
                raise ScenarioError(f"walls[{index}].height: taller than the room")
    by_id = {spec.id: spec for spec in fixtures}
    for index, obj in enumerate(objects):
        # Objects past `listed_count` come from appear events that define them.
        where = f"objects[{index}]" if index < listed_count else f"events (object {obj.id!r})"
        if obj.on not in by_id:
            raise ScenarioError(f"{where}.on: unknown fixture {obj.on!r}")
        check_fits(f"{where}.at", obj.id, obj.size, obj.yaw, obj.at, by_id[obj.on])


def _footprint_corners(box: Box) -> np.ndarray:
    """The four x, y corners of a box's footprint."""
    cos_yaw, sin_yaw = math.cos(box.yaw), math.sin(box.yaw)
    signs = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64)
    local = signs * np.array(box.size[:2]) / 2
    rotation = np.array([[cos_yaw, -sin_yaw], [sin_yaw, cos_yaw]])
    corners: np.ndarray = local @ rotation.T + np.array(box.center[:2])
    return corners


def check_events(
    events: Sequence[EventSpec],
    objects: Sequence[ObjectSpec],
    fixtures: Sequence[FixtureSpec],
    frames: int,
) -> None:
    """Replay the events in frame order and fail on any that does not fit the state then."""
    by_fixture = {spec.id: spec for spec in fixtures}
    by_object = {spec.id: spec for spec in objects}
    state: dict[str, tuple[bool, str, Vec2, float]] = {
        spec.id: (not spec.absent, spec.on, spec.at, spec.yaw) for spec in objects
    }
    appears = {event.object for event in events if event.type == "appear"}
    for index, spec in enumerate(objects):
        if spec.absent and spec.id not in appears:
            raise ScenarioError(f"objects[{index}].absent: no appear event brings {spec.id!r} in")
    last_frame: dict[str, int] = {}
    order = sorted(range(len(events)), key=lambda index: events[index].frame)
    for index in order:
        event, where = events[index], f"events[{index}]"
        if event.frame >= frames:
            raise ScenarioError(
                f"{where}.frame: {event.frame} is past the last frame ({frames - 1})"
            )
        if event.object not in by_object:
            raise ScenarioError(f"{where}.object: unknown object {event.object!r}")
        if last_frame.get(event.object) == event.frame:
            raise ScenarioError(f"{where}.frame: a second event for {event.object!r} in one frame")
        last_frame[event.object] = event.frame
        present, support, at, yaw = state[event.object]
        if (event.type == "appear") == present:
            status = "already present" if present else "not present"
            raise ScenarioError(
                f"{where}.type: {event.object!r} is {status} at frame {event.frame}"
            )
        if event.on is not None and event.on not in by_fixture:
            raise ScenarioError(f"{where}.on: unknown fixture {event.on!r}")
        if event.type == "transfer" and event.on == support:
            raise ScenarioError(f"{where}.on: already on {support!r}; use a move event")
        new_support = event.on or support
        new_at = event.at if event.at is not None else at
        new_yaw = event.yaw if event.yaw is not None else yaw
        if event.type != "disappear":
            size = by_object[event.object].size
            check_fits(f"{where}.at", event.object, size, new_yaw, new_at, by_fixture[new_support])
        state[event.object] = (event.type != "disappear", new_support, new_at, new_yaw)


def check_trajectory(scenario: Scenario) -> None:
    """Fail when a waypoint or the path between them enters furniture, a wall, or leaves the room."""
    spec = scenario.trajectory
    assert spec is not None  # only synthetic scenarios have one
    eye_height = scenario.camera.eye_height
    obstacles = [(f"fixture {f.id!r}", f.box()) for f in scenario.fixtures]
    obstacles += [(f"occluder {o.id!r}", o.box()) for o in scenario.occluders]
    obstacles += [(f"walls[{i}]", wall.box(i)) for i, wall in enumerate(scenario.walls)]
    sx, sy, height = scenario.room_size
    for index, point in enumerate(spec.points):
        z = eye_height if point.at[2] is None else point.at[2]
        _check_point(
            f"trajectory.points[{index}].at",
            np.array([point.at[0], point.at[1], z]),
            obstacles,
            (sx, sy, height),
        )
    for name, sample in path_samples(spec, eye_height):
        _check_point(f"trajectory: {name}", sample, obstacles, (sx, sy, height))
    try:
        trajectory_poses(spec, scenario.frames, eye_height)
    except ValueError as error:
        raise ScenarioError(f"trajectory: cannot aim the camera ({error})") from error


def _check_point(
    where: str,
    point: np.ndarray,
    obstacles: list[tuple[str, Box]],
    room: tuple[float, float, float],
) -> None:
    """Fail when a camera position is outside the room or too close to an obstacle."""
    margin = CAMERA_CLEARANCE_M
    if not (margin <= point[0] <= room[0] - margin and margin <= point[1] <= room[1] - margin):
        raise ScenarioError(
            f"{where}: camera position {np.round(point, 3).tolist()} leaves the room"
        )
    if not 0.0 < point[2] < room[2]:
        raise ScenarioError(f"{where}: camera height {point[2]:.2f} m is outside the room")
    for name, box in obstacles:
        if _inside_footprint(point, box, margin):
            raise ScenarioError(
                f"{where}: camera position {np.round(point[:2], 3).tolist()} is inside {name} "
                f"(keep {margin} m clear of its footprint)"
            )
