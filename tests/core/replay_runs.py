"""Random runs of a small scene decided and folded batch by batch, as the worker does (hypothesis
strategies and the run itself), for the properties of the fold and of snapshots.
"""

from __future__ import annotations

from typing import Any

from hypothesis import strategies as st

from core.decide import decide
from core.events import Event, SceneCreated
from core.evolve import evolve, fold
from core.params import Params
from core.state import SceneState
from tests.core.scenes import scene_batch

POSITIONS = [(-0.6, 0.1, 2.0), (-0.2, 0.1, 2.2), (0.3, 0.0, 1.8), (0.6, 0.2, 2.5), (0.0, -0.3, 2.0)]


step = st.fixed_dictionaries(
    {
        "mug_1": st.sampled_from([None, *range(len(POSITIONS))]),
        "book_1": st.sampled_from([None, *range(len(POSITIONS))]),
        "detect": st.sets(st.sampled_from(["mug_1", "book_1"])),
        "occlude": st.booleans(),
    }
)


def live_run(steps: list[dict[str, Any]]) -> tuple[list[Event], SceneState]:
    """Decide and fold batch by batch, as the worker does; return the log and the live state."""
    created = SceneCreated(name="prop", params=Params().to_dict())
    state = evolve(SceneState(), created)
    log: list[Event] = [created]
    for i, s in enumerate(steps):
        objects = {
            name: (POSITIONS[s[name]], 0.12 if name == "mug_1" else 0.2)
            for name in ("mug_1", "book_1")
            if s[name] is not None
        }
        occluders = [((0.0, 0.0, 1.0), 0.6)] if s["occlude"] else []
        events = decide(
            state,
            scene_batch(f"b{i}", objects, detect=s["detect"] & set(objects), occluders=occluders),
        )
        state = fold(state, events)
        log.extend(events)
    return log, state
