"""`explain` of a track that handed its identity over: the answer names the older identity."""

from __future__ import annotations

from core.events import Event
from core.state import SceneState
from service.explain import explain
from service.store.event_log import StoredEvent
from tests.core.scenes import scene_batch
from tests.core.test_lifecycle_rules import FAR, MUG, run, timed


def stored(events: list[Event]) -> list[StoredEvent]:
    return [
        StoredEvent("s", seq, e.type, e.track_id, e.state, "b", e.frame_id, 0.0, dict(e.details()))
        for seq, e in enumerate(events, start=1)
    ]


def test_a_handed_over_track_is_explained_by_the_identity_it_was() -> None:
    state, first = run(SceneState(), timed([scene_batch(f"b{i}", MUG) for i in range(3)], 0))
    hide = [((0.2, 0.1, 1.2), 0.5)]
    state, second = run(
        state, timed([scene_batch(f"f{i}", FAR, occluders=hide) for i in range(2)], 3)
    )
    state, third = run(state, timed([scene_batch(f"g{i}", FAR) for i in range(2)], 5))
    young = [e for events in first + second + third for e in events if e.track_id == "trk-000002"]
    answer = explain("trk-000002", stored(young))
    assert answer.state == "retired"
    assert "trk-000001 seen at its new place" in answer.summary
    assert [e.type for e in answer.events][-2:] == ["remove", "retire"]
