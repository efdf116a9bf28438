"""Two mugs confirmed, one carried elsewhere: the appearances and the run of the deferred
fallback's tests."""

from __future__ import annotations

import numpy as np

from core.events import Event
from core.params import Params
from core.state import SceneState
from tests.core.scenes import look_pose, run_log, scene_batch, track_events

RNG = np.random.default_rng(17)
A, B, C = (RNG.normal(size=32) for _ in range(3))
SAME_AS_A = A + 0.3 * RNG.normal(size=32)  # mug_1 from another side
TWO_MUGS = {"mug_1": ((0.2, 0.1, 2.0), 0.1), "mug_2": ((-0.3, 0.1, 2.0), 0.1)}
MUG_2_ALONE = {"mug_2": TWO_MUGS["mug_2"]}  # mug_1's place in view, empty
TURNED = look_pose(90.0)

ELSEWHERE = ((0.0, 0.1, 2.0), 0.1)  # in the turned view: about 2.8 m from mug_1's place


run = run_log


def carried(seen_there: np.ndarray, params: Params | None = None) -> tuple[SceneState, list[Event]]:
    """Two mugs confirmed; mug_1 is seen once elsewhere (appearance `seen_there`), then its
    place is seen empty twice while mug_2 stays. Returns the state and the whole log."""
    state = SceneState() if params is None else SceneState(params=params)
    both = {"mug_1": A, "mug_2": B}
    seen = {"mug_1": seen_there}
    state, log = run(
        state, [scene_batch(f"b{i}", TWO_MUGS, embeddings=both, t=float(i)) for i in range(3)]
    )
    assert [t.lifecycle for t in state.tracks.values()] == ["confirmed", "confirmed"]
    state, there = run(
        state, [scene_batch("there", {"mug_1": ELSEWHERE}, pose=TURNED, embeddings=seen, t=3.0)]
    )
    assert [e.type for e in track_events(there)] == ["add"]  # absence not established yet
    state, empty = run(
        state,
        [scene_batch(f"e{i}", MUG_2_ALONE, embeddings={"mug_2": B}, t=4.0 + i) for i in range(2)],
    )
    return state, log + there + empty
