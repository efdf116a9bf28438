"""What a generated world may vary (`WorldKnobs`), the fixed seed splits, and what a world holds."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

# Disjoint seed ranges: development seeds for traces and tuning, test seeds for reporting only.
DEV_SEED_START = 1_000
TEST_SEED_START = 900_000
SPLIT_SIZE = 100_000  # each split holds this many seeds; dev stays far below the test range


@dataclass(frozen=True)
class WorldKnobs:
    """The dials of the world generator; the defaults make a dynamic world that runs fast."""

    area_m2: float = 60.0
    """Floor area of the house (a rectangle of aspect 1.2-1.6) in square metres."""
    rooms: int = 3
    """Rooms, made by splitting the house with interior walls (each wall has door gaps)."""
    doors_per_wall: int = 1
    """Door gaps (0.9-1.0 m wide) in each interior wall."""
    clutter: tuple[int, int] = (1, 3)
    """Objects per fixture, drawn uniformly from this inclusive range (plus event objects)."""
    people: int = 2
    """People who walk in and stand between the robot and a fixture it looks at."""
    revisit_frames: tuple[int, int] = (25, 110)
    """Target range of frames between two visits of one fixture; each gap is drawn from it."""
    frames: int = 240
    """Frames of the run (the route is walked once over them)."""
    fixtures: tuple[int, int] = (7, 11)
    """Inclusive range of fixtures; rooms get them in turn until the drawn count is placed."""
    objects: tuple[int, int] | None = None
    """Inclusive range of listed objects (None: whatever `clutter` gives)."""

    def __post_init__(self) -> None:
        if self.area_m2 < 12 or self.rooms < 1 or self.doors_per_wall < 1 or self.frames < 10:
            raise ValueError("knobs: area_m2 >= 12, rooms >= 1, doors_per_wall >= 1, frames >= 10")
        for name in ("clutter", "revisit_frames", "fixtures"):
            low, high = getattr(self, name)
            if low < 0 or high < low:
                raise ValueError(f"knobs.{name}: expected 0 <= low <= high, got {(low, high)}")
        if self.area_m2 / self.rooms < 9:
            raise ValueError("knobs: each room needs at least 9 m^2 (area_m2 / rooms)")


def active_knobs() -> WorldKnobs:
    """The defaults of active worlds: several rooms, 8-14 fixtures, 10-16 objects, a short walk."""
    return WorldKnobs(
        area_m2=80.0,
        rooms=4,
        clutter=(1, 2),
        people=0,
        frames=20,
        fixtures=(8, 14),
        objects=(10, 16),
    )


def split_seeds(split: Literal["dev", "test"], count: int) -> tuple[int, ...]:
    """The first `count` seeds of a split: dev 1000, 1001, ...; test 900000, 900001, ...

    The ranges never meet (each holds 100000 seeds). Development seeds are for traces and
    tuning; test seeds are for reporting only.
    """
    if split not in ("dev", "test"):
        raise ValueError(f"split: expected 'dev' or 'test', got {split!r}")
    if not 0 <= count <= SPLIT_SIZE:
        raise ValueError(f"count: expected 0..{SPLIT_SIZE}, got {count}")
    start = DEV_SEED_START if split == "dev" else TEST_SEED_START
    return tuple(range(start, start + count))


@dataclass(frozen=True)
class HardEvent:
    """One hard event the generator scripted: its kind, the objects and the event frames."""

    kind: str
    objects: tuple[str, ...]
    frames: tuple[int, ...]
    detail: str = ""


@dataclass(frozen=True)
class WorldNotes:
    """What the generator put into a world, for tests and reports (the YAML cannot hold it)."""

    seed: int
    attempt: int  # which deterministic resample passed the checks
    rooms: tuple[tuple[float, float, float, float], ...]  # x0, y0, x1, y1 of each room
    hard_events: tuple[HardEvent, ...]
    # Per fixture: the first frame of each visit of the route (its pause at the viewpoint).
    visits: dict[str, tuple[int, ...]] = field(default_factory=dict)
    revisit_intervals: tuple[int, ...] = ()  # frames between successive visits of a fixture
    # Objects put behind a taller object (as seen from their fixture's viewpoint): hidden id ->
    # the id in front of it.
    behind: dict[str, str] = field(default_factory=dict)
    # The planned share of in-room, in-frustum frames each `behind` object is hidden.
    planned_hidden_fraction: dict[str, float] = field(default_factory=dict)
