"""Scene pieces of a scenario file: camera, furniture, walls, objects and events."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Annotated, Literal, get_args

from pydantic import Field

from sim.camera import CameraModel
from sim.scenario_fields import (
    CHECKED,
    Count,
    Flag,
    Number,
    Positive,
    PositiveInt,
    Size3,
    Text,
    Vec2,
    field_error,
)
from sim.world import Box

EventType = Literal["appear", "move", "disappear", "transfer"]
EVENT_TYPES: tuple[str, ...] = get_args(EventType)


@dataclass(frozen=True)
class CameraSpec(CameraModel):
    """The renderer's camera plus the eye height synthetic trajectories walk at."""

    __pydantic_config__ = CHECKED
    width: PositiveInt = 640  # pixels
    height: PositiveInt = 480
    fx: Positive = 525.0  # focal lengths [px]
    fy: Positive = 525.0
    cx: Number = 319.5  # principal point [px]: may lie off the image (a cropped sensor)
    cy: Number = 239.5
    min_depth: Positive = 0.3  # the sensor's valid range [m]
    max_depth: Positive = 6.0
    eye_height: Positive = 1.2  # [m] above the floor

    def __post_init__(self) -> None:
        if self.min_depth >= self.max_depth:
            raise field_error("max_depth", "must exceed min_depth")

    def model(self) -> CameraModel:
        """The renderer's camera model alone (what frames carry and runs save)."""
        return CameraModel(**{f.name: getattr(self, f.name) for f in fields(CameraModel)})


@dataclass(frozen=True)
class FixtureSpec:
    """Furniture standing on the floor; objects rest on its top."""

    __pydantic_config__ = CHECKED
    id: Text
    label: Text
    center: Vec2  # of the footprint, room frame [m]
    size: Size3
    yaw: Number = 0.0

    def box(self) -> Box:
        """The fixture's world box."""
        center = (self.center[0], self.center[1], self.size[2] / 2.0)
        return Box(self.id, self.label, center, self.size, self.yaw, kind="fixture")


@dataclass(frozen=True)
class OccluderSpec:
    """A floor-standing box that hides things but is never detected (chairs, pillars)."""

    __pydantic_config__ = CHECKED
    id: Text
    center: Vec2
    size: Size3
    yaw: Number = 0.0
    label: Text = field(default="occluder", kw_only=True)

    def box(self) -> Box:
        """The occluder's world box."""
        center = (self.center[0], self.center[1], self.size[2] / 2.0)
        return Box(self.id, self.label, center, self.size, self.yaw, kind="occluder")


@dataclass(frozen=True)
class WallSpec:
    """An interior wall segment from floor to `height`: an occluder, never detected."""

    __pydantic_config__ = CHECKED
    start: Annotated[Vec2, Field(alias="from")]
    end: Annotated[Vec2, Field(alias="to")]
    height: Positive
    thickness: Positive = 0.1

    def __post_init__(self) -> None:
        if self.start == self.end:
            raise field_error("to", "the wall has zero length")

    def box(self, index: int) -> Box:
        """The wall as a thin turned box."""
        (x0, y0), (x1, y1) = self.start, self.end
        length = math.hypot(x1 - x0, y1 - y0)
        center = ((x0 + x1) / 2.0, (y0 + y1) / 2.0, self.height / 2.0)
        size = (length, self.thickness, self.height)
        yaw = math.atan2(y1 - y0, x1 - x0)
        return Box(f"wall_{index}", "wall", center, size, yaw, kind="occluder")


@dataclass(frozen=True)
class ObjectSpec:
    """A small movable object resting on a fixture's top at offset `at` (fixture axes)."""

    __pydantic_config__ = CHECKED
    id: Text
    label: Text
    size: Size3
    on: Text
    at: Vec2 = (0.0, 0.0)
    yaw: Number = 0.0
    absent: Flag = False  # not in the scene until an appear event


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


@dataclass(frozen=True)
class EventEntry:
    """One entry of `events`: the change, and the object it defines when it gives label and size."""

    __pydantic_config__ = CHECKED
    frame: Count
    type: EventType
    object: Text
    on: Text | None = None
    at: Vec2 | None = None
    yaw: Number | None = None
    label: Text | None = None
    size: Size3 | None = None

    def __post_init__(self) -> None:
        for key in ("on", "at", "yaw", "label", "size"):
            if getattr(self, key) is not None and key not in _EVENT_FIELDS[self.type]:
                raise field_error(key, f"not allowed for a {self.type} event")
        if self.type == "move" and self.at is None:
            raise field_error("at", "required for a move event")
        if self.type == "transfer" and self.on is None:
            raise field_error("on", "required for a transfer event")
        if (self.label is None) != (self.size is None):
            raise field_error("size" if self.size is None else "label", "give label and size")
        if self.label is not None and self.on is None:
            raise field_error("on", "required when the event defines the object")

    def spec(self) -> EventSpec:
        """The change alone."""
        return EventSpec(self.frame, self.type, self.object, self.on, self.at, self.yaw)

    def defined(self) -> ObjectSpec | None:
        """The object an appear event defines (absent until then), None when it names one."""
        if self.label is None or self.size is None or self.on is None:
            return None
        at, yaw = self.at or (0.0, 0.0), self.yaw or 0.0
        return ObjectSpec(self.object, self.label, self.size, self.on, at, yaw, True)
