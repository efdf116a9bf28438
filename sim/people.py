"""People walking through a scenario: moving boxes that hide things and are never tracked objects.

A person is a box standing on the floor that walks from keyframe to keyframe; it is in the room
from its first keyframe's frame to its last one's. It shows in the depth image (so the memory's
visibility gate can see it standing in front of a table) and in the detector's output only when
`detected_as` names a class, as open-vocabulary detectors prompted with "person" report people.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Annotated

from pydantic import Field

from sim.scenario_fields import CHECKED, Count, ScenarioError, Size3, Text, Vec2, Vec3, field_error
from sim.world import Box

# An adult seen as one box: shoulder width, chest depth, height [m].
DEFAULT_PERSON_SIZE: Vec3 = (0.45, 0.30, 1.70)


@dataclass(frozen=True)
class Keyframe:
    """Where a person stands at a frame."""

    __pydantic_config__ = CHECKED
    frame: Count
    at: Vec2


@dataclass(frozen=True)
class PersonSpec:
    """One walker: a box moving linearly between keyframes, present from first to last."""

    __pydantic_config__ = CHECKED
    id: Text
    keyframes: Annotated[tuple[Keyframe, ...], Field(min_length=2)]  # in frame order
    size: Size3 = DEFAULT_PERSON_SIZE
    detected_as: Text | None = None  # the class a detector reports, None: never detected

    def __post_init__(self) -> None:
        for index in range(1, len(self.keyframes)):
            if self.keyframes[index].frame < self.keyframes[index - 1].frame:
                raise field_error(f"keyframes[{index}].frame", "earlier than the one before")

    def box_at(self, frame_index: int) -> Box | None:
        """The person's box at this frame, None while they are not in the room."""
        frames = [key.frame for key in self.keyframes]
        if frame_index < frames[0] or frame_index > frames[-1]:
            return None
        after = bisect.bisect_right(frames, frame_index)
        if after >= len(frames):
            position, yaw = self.keyframes[-1].at, self._heading(len(frames) - 1)
        else:
            start, end = self.keyframes[after - 1], self.keyframes[after]
            share = (frame_index - start.frame) / max(end.frame - start.frame, 1)
            position = (
                start.at[0] + share * (end.at[0] - start.at[0]),
                start.at[1] + share * (end.at[1] - start.at[1]),
            )
            yaw = self._heading(after)
        center = (position[0], position[1], self.size[2] / 2.0)
        return Box(self.id, "person", center, self.size, yaw, kind="person")

    def _heading(self, index: int) -> float:
        """Facing along the last segment that moved up to keyframe `index` (0 when none did)."""
        for later in range(min(index, len(self.keyframes) - 1), 0, -1):
            (x0, y0), (x1, y1) = self.keyframes[later - 1].at, self.keyframes[later].at
            if math.hypot(x1 - x0, y1 - y0) > 1e-9:
                return math.atan2(y1 - y0, x1 - x0)
        return 0.0


def check_people(
    people: tuple[PersonSpec, ...], room_size: Vec3 | None, frames: int, taken: set[str]
) -> None:
    """Unique ids, keyframes inside the run and (with a synthetic room) inside the room."""
    for index, person in enumerate(people):
        if person.id in taken:
            raise ScenarioError(f"people[{index}].id: {person.id!r} is already used")
        taken.add(person.id)
        for number, key in enumerate(person.keyframes):
            where = f"people[{index}].keyframes[{number}]"
            if key.frame >= frames:
                raise ScenarioError(f"{where}.frame: {key.frame} is past the last frame")
            if room_size is not None:
                half = max(person.size[0], person.size[1]) / 2
                inside = all(half <= key.at[axis] <= room_size[axis] - half for axis in (0, 1))
                if not inside:
                    raise ScenarioError(f"{where}.at: {list(key.at)} puts them outside the room")
