"""Scene pieces of a scenario file: camera, furniture, walls, objects and events."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

from sim.camera import CameraModel
from sim.scenario_fields import (
    ScenarioError,
    Section,
    boolean,
    count,
    number,
    positive,
    text,
    vector,
)
from sim.world import Box

Vec2 = tuple[float, float]
Vec3 = tuple[float, float, float]
EVENT_TYPES = ("appear", "move", "disappear", "transfer")


@dataclass(frozen=True)
class CameraSpec(CameraModel):
    """The renderer's camera plus the eye height synthetic trajectories walk at."""

    eye_height: float = 1.2

    def model(self) -> CameraModel:
        """The renderer's camera model alone (what frames carry and runs save)."""
        return CameraModel(**{f.name: getattr(self, f.name) for f in fields(CameraModel)})


def parse_camera(value: Any, where: str) -> CameraSpec:
    """The `camera` section."""
    section, default = Section(value, where), CameraSpec()
    side = lambda item, at: int(positive(item, at, integer=True))  # noqa: E731
    spec = CameraSpec(
        width=section.get("width", side, default.width),
        height=section.get("height", side, default.height),
        fx=section.get("fx", positive, default.fx),
        fy=section.get("fy", positive, default.fy),
        cx=section.get("cx", number, default.cx),
        cy=section.get("cy", number, default.cy),
        eye_height=section.get("eye_height", positive, default.eye_height),
        min_depth=section.get("min_depth", positive, default.min_depth),
        max_depth=section.get("max_depth", positive, default.max_depth),
    )
    section.finish()
    if spec.min_depth >= spec.max_depth:
        raise ScenarioError(f"{where}.max_depth: must exceed min_depth")
    return spec


@dataclass(frozen=True)
class FixtureSpec:
    """Furniture standing on the floor; objects rest on its top."""

    id: str
    label: str
    center: Vec2
    size: Vec3
    yaw: float = 0.0

    def box(self) -> Box:
        """The fixture's world box."""
        center = (self.center[0], self.center[1], self.size[2] / 2.0)
        return Box(self.id, self.label, center, self.size, self.yaw, kind="fixture")


@dataclass(frozen=True)
class OccluderSpec:
    """A floor-standing box that hides things but is never detected (chairs, pillars)."""

    id: str
    label: str
    center: Vec2
    size: Vec3
    yaw: float = 0.0

    def box(self) -> Box:
        """The occluder's world box."""
        center = (self.center[0], self.center[1], self.size[2] / 2.0)
        return Box(self.id, self.label, center, self.size, self.yaw, kind="occluder")


def _floor_box_fields(section: Section) -> tuple[str, Vec2, Vec3, float]:
    """id, center, size and yaw shared by fixtures and occluders."""
    return (
        section.get("id", text),
        section.get("center", lambda item, at: vector(item, at, 2)),
        section.get("size", lambda item, at: vector(item, at, 3, positive_only=True)),
        section.get("yaw", number, 0.0),
    )


def parse_fixture(value: Any, where: str) -> FixtureSpec:
    """One entry of `fixtures`."""
    section = Section(value, where)
    box_id, center, size, yaw = _floor_box_fields(section)
    spec = FixtureSpec(box_id, section.get("label", text), center, size, yaw)
    section.finish()
    return spec


def parse_occluder(value: Any, where: str) -> OccluderSpec:
    """One entry of `occluders`."""
    section = Section(value, where)
    box_id, center, size, yaw = _floor_box_fields(section)
    spec = OccluderSpec(box_id, section.get("label", text, "occluder"), center, size, yaw)
    section.finish()
    return spec


@dataclass(frozen=True)
class WallSpec:
    """An interior wall segment from floor to `height`: an occluder, never detected."""

    start: Vec2
    end: Vec2
    height: float
    thickness: float = 0.1

    def box(self, index: int) -> Box:
        """The wall as a thin turned box."""
        (x0, y0), (x1, y1) = self.start, self.end
        length = math.hypot(x1 - x0, y1 - y0)
        center = ((x0 + x1) / 2.0, (y0 + y1) / 2.0, self.height / 2.0)
        size = (length, self.thickness, self.height)
        yaw = math.atan2(y1 - y0, x1 - x0)
        return Box(f"wall_{index}", "wall", center, size, yaw, kind="occluder")


def parse_wall(value: Any, where: str) -> WallSpec:
    """One entry of `walls`."""
    section = Section(value, where)
    spec = WallSpec(
        start=section.get("from", lambda item, at: vector(item, at, 2)),
        end=section.get("to", lambda item, at: vector(item, at, 2)),
        height=section.get("height", positive),
        thickness=section.get("thickness", positive, 0.1),
    )
    section.finish()
    if spec.start == spec.end:
        raise ScenarioError(f"{where}.to: the wall has zero length")
    return spec


@dataclass(frozen=True)
class ObjectSpec:
    """A small movable object resting on a fixture's top at offset `at` (fixture axes)."""

    id: str
    label: str
    size: Vec3
    on: str
    at: Vec2 = (0.0, 0.0)
    yaw: float = 0.0
    absent: bool = False  # not in the scene until an appear event


def _offset(value: Any, where: str) -> Vec2:
    """An [dx, dy] offset on a support's top."""
    return vector(value, where, 2)  # type: ignore[no-any-return]


def parse_object(value: Any, where: str) -> ObjectSpec:
    """One entry of `objects`."""
    section = Section(value, where)
    spec = ObjectSpec(
        id=section.get("id", text),
        label=section.get("label", text),
        size=section.get("size", lambda item, at: vector(item, at, 3, positive_only=True)),
        on=section.get("on", text),
        at=section.get("at", _offset, (0.0, 0.0)),
        yaw=section.get("yaw", number, 0.0),
        absent=section.get("absent", boolean, False),
    )
    section.finish()
    return spec


@dataclass(frozen=True)
class EventSpec:
    """A scripted change from `frame` on; `on`/`at`/`yaw` say where the object ends up."""

    frame: int
    type: str
    object: str
    on: str | None = None
    at: Vec2 | None = None
    yaw: float | None = None


# Which optional fields each event type accepts (label and size only define an appearing object).
_EVENT_FIELDS = {
    "appear": {"on", "at", "yaw", "label", "size"},
    "move": {"at", "yaw"},
    "disappear": set(),
    "transfer": {"on", "at", "yaw"},
}


def parse_event(value: Any, where: str) -> tuple[EventSpec, ObjectSpec | None]:
    """One entry of `events`, plus the object it defines when an appear event gives label/size."""
    section = Section(value, where)
    kind = section.get("type", text)
    if kind not in EVENT_TYPES:
        raise ScenarioError(f"{where}.type: {kind!r} is not one of {', '.join(EVENT_TYPES)}")
    for key in map(str, section.data):
        if key in {"on", "at", "yaw", "label", "size"} and key not in _EVENT_FIELDS[kind]:
            raise ScenarioError(f"{where}.{key}: not allowed for a {kind} event")
    event = EventSpec(
        frame=section.get("frame", count),
        type=kind,
        object=section.get("object", text),
        on=section.get("on", text, None),
        at=section.get("at", _offset, None),
        yaw=section.get("yaw", number, None),
    )
    if kind == "move" and event.at is None:
        raise ScenarioError(f"{where}.at: required for a move event")
    if kind == "transfer" and event.on is None:
        raise ScenarioError(f"{where}.on: required for a transfer event")
    label = section.get("label", text, None)
    size = section.get("size", lambda item, at: vector(item, at, 3, positive_only=True), None)
    section.finish()
    if (label is None) != (size is None):
        raise ScenarioError(f"{where}.{'size' if size is None else 'label'}: give label and size")
    defined = None
    if label is not None:
        if event.on is None:
            raise ScenarioError(f"{where}.on: required when the event defines the object")
        defined = ObjectSpec(
            event.object, label, size, event.on, event.at or (0.0, 0.0), event.yaw or 0.0, True
        )
    return event, defined
