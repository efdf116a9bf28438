"""Verdicts, baselines and inspections at the core level (sections 3.1, 3.2, 3.4)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import pytest

from core.baseline import decide_freeze, decide_load, package_sha256
from core.decide import decide
from core.errors import InvalidCommand, StateConflict, UnknownTrack
from core.evolve import fold
from core.inspection import decide_inspection
from core.observation import Detection, Frame
from core.params import Params
from core.state import SceneState, Track
from core.values import Vec3
from core.verification import decide_verdict
from tests.core.rendered import COUNTER_VIEWS, ROOM, TABLE, TABLE_VIEWS, batches, frame, object_on

AMBIGUOUS = {"table": {"table": 0.50, "desk": 0.48}, "counter": {"counter": 0.6, "table": 0.3}}


def discover(
    scores: Mapping[str, Mapping[str, float]] | None = None,
    views: Sequence[tuple[Vec3, Vec3]] | None = None,
) -> SceneState:
    state = SceneState()
    kwargs: dict[str, Any] = {} if scores is None else {"scores": scores}
    for batch in batches(ROOM, views or (TABLE_VIEWS + COUNTER_VIEWS) * 2, "b", **kwargs):
        state = fold(state, decide(state, batch))
    return state


def fixture(state: SceneState, label: str) -> Track:
    return next(t for t in state.tracks.values() if t.kind == "fixture" and t.label == label)


def test_confirm_verdict_weighs_three_and_publishes() -> None:
    state = discover(AMBIGUOUS, TABLE_VIEWS * 3)
    table = fixture(state, "table")
    assert table.verification == "pending"
    events = decide_verdict(state, table.track_id, "confirm", None, "vlm", "b2")
    assert [e.type for e in events] == ["verify", "confirm"]
    after = fold(state, events).tracks[table.track_id]
    assert after.class_evidence["table"] == table.class_evidence["table"] + 3.0
    clamp = state.params.existence.logodds_max
    assert after.existence_logodds == min(clamp, table.existence_logodds + 1.8)
    assert after.lifecycle == "confirmed" and after.verification == "confirmed"


def test_reject_verdict_retires_for_good_and_a_second_verdict_needs_a_new_frame() -> None:
    state = discover(AMBIGUOUS, TABLE_VIEWS * 3)
    table_id = fixture(state, "table").track_id
    state = fold(state, decide_verdict(state, table_id, "reject", None, "vlm", "b2"))
    assert state.tracks[table_id].lifecycle == "removed"
    with pytest.raises(StateConflict):
        decide_verdict(state, table_id, "confirm", None, "vlm", "b2")
    # later batches keep seeing the cluster: the retired hypothesis absorbs it silently
    for batch in batches(ROOM, TABLE_VIEWS, "later", scores=AMBIGUOUS):
        state = fold(state, decide(state, batch))
    assert state.tracks[table_id].lifecycle == "removed"
    assert sum(t.kind == "fixture" and t.label == "table" for t in state.tracks.values()) == 1


def test_verdict_errors_name_the_field() -> None:
    state = discover()
    with pytest.raises(UnknownTrack):
        decide_verdict(state, "trk-999999", "confirm", None, "vlm", None)
    with pytest.raises(InvalidCommand, match="taxonomy"):
        decide_verdict(state, fixture(state, "table").track_id, "confirm", "spaceship", "vlm", None)


def test_freeze_pins_and_a_new_session_keeps_the_identities() -> None:
    state = discover()
    events, package = decide_freeze(state, "scn-a")
    assert events[0].details()["sha256"] == package_sha256(package)
    frozen = fold(state, events)
    ids = sorted(f["track_id"] for f in package["fixtures"])
    assert all(frozen.tracks[i].pinned for i in ids)
    assert decide_freeze(frozen, "scn-a")[1]["version"] == 2
    later = fold(SceneState(), decide_load(package))
    assert sorted(later.tracks) == ids and all(
        t.pinned and t.lifecycle == "confirmed" for t in later.tracks.values()
    )
    assert later.next_track_number > max(int(i.split("-")[1]) for i in ids)
    with pytest.raises(StateConflict):
        decide_freeze(SceneState(), "scn-empty")


def test_inspection_grounds_children_on_the_fixture_only() -> None:
    state = discover()
    table = fixture(state, "table")
    world = ROOM.with_object(object_on(TABLE, "book", "book", (0.2, 0.15, 0.05), at=(-0.3, 0.1)))
    view = frame(world, (2.0, 1.2, 1.5), (2.0, 2.0, 0.75), "insp")
    events = decide_inspection(state, "cap-1", table.track_id, [view], True)
    record = events[-1]
    assert record.type == "inspection" and record.details()["outcome"] == "completed"
    after = fold(state, events)
    labels = sorted(after.tracks[c].label for c in record.details()["children"])
    assert labels == ["book", "mug"]
    assert all(after.tracks[c].parent == table.track_id for c in record.details()["children"])
    assert after.tracks[table.track_id].inspection_status == "completed"
    # Each event states its track's lifecycle after it: a child the capture publishes is
    # confirmed by the time its support edge is recorded.
    assert any(e.type == "reparent" for e in events)
    for count, event in enumerate(events, start=1):
        assert event.track_id is not None
        assert fold(state, events[:count]).tracks[event.track_id].lifecycle == event.state


def test_the_primary_view_is_the_valid_view_that_grounds_the_most() -> None:
    state = discover()
    table = fixture(state, "table")
    world = ROOM.with_object(object_on(TABLE, "book", "book", (0.2, 0.15, 0.05), at=(-0.3, 0.1)))
    eye, target = (2.0, 1.2, 1.5), (2.0, 2.0, 0.75)
    away = frame(world, eye, (2.0, -2.0, 0.75), "away")  # the table's top out of view
    missed = frame(world, eye, target, "missed", objects=False)  # the detector saw nothing
    both = frame(world, eye, target, "both")
    mug_only = replace(both, frame_id="mug", detections=_without(both, "book"))
    sweep = [away, missed, mug_only, both]
    extended = decide_inspection(state, "cap-1", table.track_id, sweep, True)[-1].details()
    assert extended["primary_frame"] == "both" and len(extended["children"]) == 2
    # Ties go to the first: a view as good as a later one is not passed over.
    twin = replace(both, frame_id="twin")
    tied = decide_inspection(state, "cap-1", table.track_id, [missed, twin, both], True)
    assert tied[-1].details()["primary_frame"] == "twin"
    # The paper's reading: the first view that shows the support region, whatever it grounds.
    paper = replace(state, params=Params.from_dict({"inspection": {"primary_view": "first"}}))
    first = decide_inspection(paper, "cap-1", table.track_id, sweep, True)[-1].details()
    assert first["primary_frame"] == "missed" and first["children"] == []


def _without(view: Frame, label: str) -> tuple[Detection, ...]:
    return tuple(d for d in view.detections if d.label != label)


def test_inspection_refuses_what_is_not_a_confirmed_fixture() -> None:
    state = discover(views=TABLE_VIEWS[:1])
    view = frame(ROOM, (2.0, 1.2, 1.5), (2.0, 2.0, 0.75), "insp")
    young = next(t for t in state.tracks.values() if t.kind == "fixture")
    with pytest.raises(StateConflict):
        decide_inspection(state, "c", young.track_id, [view], None)
    mug = next(t for t in state.tracks.values() if t.kind == "object")
    with pytest.raises(InvalidCommand):
        decide_inspection(state, "c", mug.track_id, [view], None)
    with pytest.raises(UnknownTrack):
        decide_inspection(state, "c", "trk-999999", [view], None)
