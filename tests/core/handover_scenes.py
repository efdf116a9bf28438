"""A mug carried from the table to the counter of the rendered room, seen in either order, and
two mugs of which one is taken away while the other is carried: the identity hand-over's and
the fallback's scenes (section 3.3, unique-class fallback)."""

from __future__ import annotations

import numpy as np

from core.events import Event
from core.params import Params
from core.state import SceneState, Track
from tests.core.rendered import (
    COUNTER,
    COUNTER_VIEWS,
    ROOM,
    TABLE,
    TABLE_VIEWS,
    World,
    batches,
    object_on,
)
from tests.core.scenes import run_log

DIM = 32


def unit(*weights: float) -> np.ndarray:
    """A unit vector along the first axes, with these weights."""
    vector = np.zeros(DIM)
    vector[: len(weights)] = weights
    return vector / np.linalg.norm(vector)


MUG_1 = unit(1.0)  # mug_1 as its first views show it
MUG_2 = unit(0.82, np.sqrt(1 - 0.82**2))  # another mug: cosine 0.82 with mug_1, past the gate
# mug_1 seen at the counter: 0.97 with its own first views, 0.795 with mug_2 (past the gate too).
MUG_1_THERE = unit(0.97, 0.0, np.sqrt(1 - 0.97**2))
ON_COUNTER = object_on(COUNTER, "mug", "mug", (0.1, 0.1, 0.1), at=(0.3, 0.0)).center


def settled(
    world: World, embeddings: dict[str, np.ndarray], params: Params
) -> tuple[SceneState, list[Event]]:
    """Both fixtures and the world's objects confirmed: two rounds of every view."""
    views = (TABLE_VIEWS + COUNTER_VIEWS) * 2
    return run_log(
        SceneState(params=params), batches(world, views, "b", embeddings=embeddings, t0=0.0)
    )


def mugs(state: SceneState) -> list[Track]:
    return [t for t in state.tracks.values() if t.label == "mug"]


def carried(
    params: Params, counter_first: bool, counter_views: int = 2
) -> tuple[SceneState, str, list[Event]]:
    """The only mug, confirmed on the table, carried to the counter. The robot views the counter
    twice (or `counter_views` times), then the table (the mug gone) twice, then the counter once
    more; or the table first, then the counter. Returns the state, the mug's first identity and
    the whole log."""
    embeddings = {"mug": MUG_1}
    state, log = settled(ROOM, embeddings, params)
    (mug,) = mugs(state)
    moved = ROOM.moved("mug", ON_COUNTER)
    views = (COUNTER_VIEWS[:2] * counter_views)[:counter_views]
    counter = batches(moved, views, "c", embeddings=embeddings, t0=20.0)
    table = batches(moved, TABLE_VIEWS[:2], "t", embeddings=embeddings, t0=40.0)
    again = batches(moved, COUNTER_VIEWS[2:], "k", embeddings=embeddings, t0=50.0)
    order = counter + table + again if counter_first else table + counter + again
    state, more = run_log(state, order)
    return state, mug.track_id, log + more


def two_mugs(params: Params) -> tuple[SceneState, dict[str, str]]:
    """Two mugs confirmed on the table. mug_2 is taken away and removed; then mug_1 is carried
    to the counter and seen there while its own track still stands on the table, unrefuted;
    then the table is seen empty twice and the counter once more. Returns the state and each
    mug's first identity."""
    world = ROOM.with_object(object_on(TABLE, "mug_2", "mug", (0.1, 0.1, 0.1), at=(-0.3, 0.0)))
    state, _ = settled(world, {"mug": MUG_1, "mug_2": MUG_2}, params)
    first = {"mug_1" if t.embedding() @ MUG_1 > 0.99 else "mug_2": t.track_id for t in mugs(state)}
    assert len(first) == 2
    alone = ROOM  # mug_2 taken away, mug_1 on the table
    state, _ = run_log(
        state, batches(alone, TABLE_VIEWS * 3, "a", embeddings={"mug": MUG_1}, t0=20.0)
    )
    assert state.tracks[first["mug_2"]].lifecycle == "removed"
    moved = ROOM.moved("mug", ON_COUNTER)
    there = {"mug": MUG_1_THERE}
    state, _ = run_log(state, batches(moved, COUNTER_VIEWS[:2], "c", embeddings=there, t0=40.0))
    state, _ = run_log(state, batches(moved, TABLE_VIEWS[:2], "t", embeddings=there, t0=50.0))
    state, _ = run_log(state, batches(moved, COUNTER_VIEWS[2:], "k", embeddings=there, t0=60.0))
    return state, first
