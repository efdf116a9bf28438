"""The demo scenario: a kitchen-like room, a looping camera walk and a script of object changes."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from sim.camera import look_at
from sim.world import Box, World, object_on

TABLE = Box("table", "table", (3.0, 2.3, 0.375), (1.2, 0.8, 0.75), kind="fixture")
COUNTER = Box("counter", "counter", (3.0, 4.6, 0.45), (2.0, 0.6, 0.9), kind="fixture")
# Against the east wall's south end, 0.3 m clear of the camera loop; the table-facing views from
# the loop's north and west sides (frames 1-11 and 24-35 of 120) see it, the first few partly.
DESK = Box("desk", "desk", (5.65, 1.0, 0.375), (0.6, 1.2, 0.75), kind="fixture")

# Fixture id -> class scores replacing the detector's defaults: the desk reads almost as well as
# a table, so the demo shows a fixture waiting for verification; table and counter stay clear.
DEMO_AMBIGUITY: Mapping[str, Mapping[str, float]] = {DESK.id: {"desk": 0.50, "table": 0.47}}

MUG_SIZE = (0.08, 0.08, 0.10)
BOOK_SIZE = (0.20, 0.15, 0.04)
BOWL_SIZE = (0.15, 0.15, 0.07)
BOTTLE_SIZE = (0.07, 0.07, 0.25)

# Where the camera loop runs: an ellipse around the table that stays clear of the counter.
LOOP_CENTER = (3.0, 2.3)
LOOP_RADII = (2.2, 1.5)
LOOP_START_ANGLE = math.pi / 2.0  # start on the counter side so the run ends near it
TARGET_BLOCKS = 10  # the gaze alternates table/counter this many times per loop


def demo_world() -> World:
    """A 6 x 5 x 2.6 m room: a mug, book, bowl and bottle on a table and counter; a bare desk."""
    objects = (
        object_on(TABLE, "mug", "mug", MUG_SIZE, at=(-0.4, -0.2)),
        object_on(TABLE, "book", "book", BOOK_SIZE, at=(0.35, 0.15), yaw=0.3),
        object_on(TABLE, "bowl", "bowl", BOWL_SIZE, at=(-0.1, 0.2)),
        object_on(COUNTER, "bottle", "bottle", BOTTLE_SIZE, at=(-0.5, 0.05)),
    )
    return World(room_size=(6.0, 5.0, 2.6), fixtures=(TABLE, COUNTER, DESK), objects=objects)


def gaze_target(frame_index: int, n_frames: int) -> tuple[float, float, float]:
    """The fixture top the camera looks at: table and counter alternate in equal blocks."""
    block = frame_index * TARGET_BLOCKS // max(n_frames, 1)
    fixture = TABLE if block % 2 == 0 else COUNTER
    return (fixture.center[0], fixture.center[1], fixture.top_z)


def demo_trajectory(n_frames: int) -> list[np.ndarray]:
    """Camera-to-world poses walking one loop around the room at 1.2-1.4 m height."""
    poses = []
    for frame_index in range(n_frames):
        angle = LOOP_START_ANGLE + 2.0 * math.pi * frame_index / n_frames
        eye = (
            LOOP_CENTER[0] + LOOP_RADII[0] * math.cos(angle),
            LOOP_CENTER[1] + LOOP_RADII[1] * math.sin(angle),
            1.3 + 0.1 * math.sin(3.0 * angle),  # a gentle bob keeps heights varied
        )
        poses.append(look_at(eye, gaze_target(frame_index, n_frames)))
    return poses


@dataclass(frozen=True)
class ScheduledChange:
    """A change of the world that takes effect from `frame_index` on."""

    frame_index: int
    description: str
    apply: Callable[[World], World]


def _carry_book_to_counter(world: World) -> World:
    """Take the book off the table and put it on the counter."""
    book = object_on(COUNTER, "book", "book", BOOK_SIZE, at=(0.4, 0.0), yaw=-0.2)
    return world.without("book").with_object(book)


def _slide_mug(world: World) -> World:
    """Move the mug 0.5 m along the table's long side."""
    x, y, z = world.object_by_id("mug").center
    return world.moved("mug", (x + 0.5, y, z))


def demo_script(n_frames: int = 120) -> list[ScheduledChange]:
    """Bowl vanishes at 40 %, mug slides 0.5 m at 60 %, book goes to the counter at 80 %."""
    return [
        ScheduledChange(int(0.4 * n_frames), "bowl removed", lambda world: world.without("bowl")),
        ScheduledChange(int(0.6 * n_frames), "mug moved 0.5 m along the table", _slide_mug),
        ScheduledChange(int(0.8 * n_frames), "book carried to the counter", _carry_book_to_counter),
    ]


def world_at(frame_index: int, base: World, script: Sequence[ScheduledChange]) -> World:
    """The world as it is at `frame_index`: every change scheduled up to then, in order."""
    world = base
    for change in sorted(script, key=lambda scheduled: scheduled.frame_index):
        if change.frame_index <= frame_index:
            world = change.apply(world)
    return world
