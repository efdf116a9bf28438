"""A few batches of a small scene decided and folded as the worker does, their events in the
stored form, for a test that compares the log decided in another process (another string
hashing, another global random state)."""

from __future__ import annotations

import orjson

from core.decide import decide
from core.event_records import event_to_record
from core.evolve import fold
from core.state import SceneState
from tests.core.scenes import scene_batch

MUG, BOOK, CUP = (0.2, 0.1, 2.0), (-0.3, 0.0, 2.2), (0.5, -0.2, 1.9)


def decided_log(mug_at: tuple[float, float, float] = MUG) -> bytes:
    """The events of five batches, in the stored form: a mug, a book and a cup seen, the book
    hidden behind an occluder, the mug moved to `mug_at`, the cup gone."""
    sizes = {"mug_1": 0.1, "book_1": 0.2, "cup_1": 0.08}
    at = {"mug_1": MUG, "book_1": BOOK, "cup_1": CUP}
    steps = [
        (at, set(at), ()),
        (at, set(at), ()),
        (at, {"mug_1", "cup_1"}, [(BOOK, 0.3)]),
        ({**at, "mug_1": mug_at}, {"mug_1", "book_1", "cup_1"}, ()),
        ({"mug_1": mug_at, "book_1": BOOK}, {"mug_1", "book_1"}, ()),
    ]
    state, records = SceneState(), []
    for index, (where, seen, occluders) in enumerate(steps):
        objects = {name: (center, sizes[name]) for name, center in where.items()}
        batch = scene_batch(f"b{index}", objects, detect=seen, occluders=occluders, t=index)
        events = decide(state, batch)
        state = fold(state, events)
        records += [event_to_record(event) for event in events]
    return orjson.dumps(records)
