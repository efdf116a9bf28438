"""Worlds for the questions asked in the robot's terms: the fixture room with a mug on the table
and a bowl on the counter, or with five mugs; batches stamped one second apart on the robot's
clock so that wall-clock time travel has batches to land between."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from fastapi.testclient import TestClient

from service.worker import Worker
from sim.world import World, object_on
from tests.e2e.fixture_api import feed
from tests.e2e.fixture_world import COUNTER, DISCOVERY, MUG, ROOM, TABLE, wire_batches

BOWL = object_on(COUNTER, "bowl", "bowl", (0.15, 0.15, 0.08), at=(0.4, 0.0))
KITCHEN = World(room_size=ROOM.room_size, fixtures=ROOM.fixtures, objects=(MUG, BOWL))
# Five mugs, each its own look (the simulator's appearance vector is seeded by the object id).
MUGS = (
    object_on(TABLE, "mug-a", "mug", (0.1, 0.1, 0.1), at=(-0.45, 0.0)),
    object_on(TABLE, "mug-b", "mug", (0.1, 0.1, 0.1), at=(0.0, 0.0)),
    object_on(TABLE, "mug-c", "mug", (0.1, 0.1, 0.1), at=(0.45, 0.0)),
    object_on(COUNTER, "mug-d", "mug", (0.1, 0.1, 0.1), at=(-0.5, 0.0)),
    object_on(COUNTER, "mug-e", "mug", (0.1, 0.1, 0.1), at=(0.5, 0.0)),
)
FIVE_MUGS = World(room_size=ROOM.room_size, fixtures=ROOM.fixtures, objects=MUGS)
# The robot's clock at the discovery's first batch; batch i is stamped START + i.
START = 100.0


def timed(bodies: Sequence[dict[str, Any]], start: float) -> list[dict[str, Any]]:
    """The batches with their frames stamped `start`, `start + 1`, ... (one second a batch)."""
    for index, body in enumerate(bodies):
        for frame in body["frames"]:
            frame["timestamp"] = start + index
    return list(bodies)


def discovered_at(
    client: TestClient, worker: Worker, world: World
) -> tuple[str, list[dict[str, Any]]]:
    """A new scene fed the discovery tour of `world` from START on; its id and the batches."""
    scene_id: str = client.post("/v1/scenes", json={"name": "kitchen"}).json()["id"]
    bodies = timed(wire_batches(world, DISCOVERY, "d"), START)
    feed(client, worker, scene_id, bodies)
    return scene_id, bodies
