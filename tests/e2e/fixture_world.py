"""A room with a table and a counter, seen partially from several viewpoints, as wire batches."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from core.values import Vec3
from sim.camera import look_at
from sim.detector import detect, detect_fixtures
from sim.render import render
from sim.wire import make_batch, make_frame
from sim.world import Box, World, object_on
from tests.core import rendered
from tests.core.rendered import CAMERA, COUNTER_VIEWS, TABLE_VIEWS

# The fixtures of the core tests' room, as the simulator's boxes.
TABLE, COUNTER = (
    Box(box.id, box.label, box.center, box.size, kind="fixture")
    for box in (rendered.TABLE, rendered.COUNTER)
)
MUG = object_on(TABLE, "mug", "mug", (0.1, 0.1, 0.1), at=(0.3, 0.0))
ROOM = World(room_size=(6.0, 5.0, 2.6), fixtures=(TABLE, COUNTER), objects=(MUG,))
FINE = (
    object_on(TABLE, "book", "book", (0.2, 0.15, 0.05), at=(-0.35, -0.1)),
    object_on(TABLE, "bowl", "bowl", (0.15, 0.15, 0.08), at=(0.0, 0.15)),
    object_on(TABLE, "remote", "remote", (0.18, 0.06, 0.04), at=(-0.1, -0.2)),
)
CLOSE_VIEW = ((2.0, 1.2, 1.5), (2.0, 2.0, 0.75))  # fixture-centered, looking down at the table
AWAY_VIEW = ((2.0, 1.2, 1.5), (2.0, -3.0, 1.2))  # the wall behind the robot: no support visible
DISCOVERY = [*TABLE_VIEWS, *COUNTER_VIEWS] * 2


def wire_frame(
    world: World,
    view: tuple[Vec3, Vec3],
    frame_id: str,
    *,
    ambiguity: Mapping[str, Mapping[str, float]] | None = None,
    objects: bool = True,
    seed: int = 0,
) -> dict[str, Any]:
    """One rendered frame with fixture masks (class scores) and object masks, in the wire format."""
    eye, target = view
    pose = look_at(eye, target)
    rendered = render(world, CAMERA, pose)
    rng = np.random.default_rng(seed)
    detections = detect_fixtures(
        rendered, world, rng, min_visible_pixels=200, score_noise=0.0, ambiguity=ambiguity
    )
    if objects:
        detections += detect(rendered, world, rng, min_visible_pixels=30)
    return make_frame(frame_id, 0.0, CAMERA, pose, rendered.depth, detections)


def wire_batches(
    world: World, views: Iterable[tuple[Vec3, Vec3]], prefix: str, **kwargs: Any
) -> list[dict[str, Any]]:
    """One single-frame batch per viewpoint."""
    return [
        make_batch(f"{prefix}{i}", [wire_frame(world, view, f"{prefix}{i}", **kwargs)])
        for i, view in enumerate(views)
    ]
