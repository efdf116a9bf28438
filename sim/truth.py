"""Ground truth per frame: the records the simulator produces and the evaluation judges against."""

from __future__ import annotations

from dataclasses import dataclass

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class TruthObject:
    """One movable object as the simulator knows it at one frame."""

    object_id: str
    label: str
    center: Vec3
    present: bool  # False once the object has disappeared (or before it appears)
    parent: str | None  # id of the supporting fixture, None when on the floor or absent
    visible_pixels: int


@dataclass(frozen=True)
class TruthFixture:
    """One static fixture (table, counter, shelf) of the simulated world."""

    fixture_id: str
    label: str
    center: Vec3
    size: Vec3


@dataclass(frozen=True)
class FrameTruth:
    """The ground-truth objects of one frame."""

    frame_index: int
    objects: tuple[TruthObject, ...]


@dataclass(frozen=True)
class ScheduledEvent:
    """A change the scenario script applies to the world at a given frame."""

    frame: int
    type: str  # "appear", "move", "disappear" or "transfer"
    object_id: str
    parent: str | None = None  # the new supporting fixture for "appear" and "transfer"
