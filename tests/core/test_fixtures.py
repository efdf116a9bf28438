"""Fixture discovery, promotion, verification requests and support parents (sections 3.2, 3.3)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from core.decide import decide
from core.events import TrackReparented, TrackRetired
from core.evolve import fold
from core.fixture_association import FixtureTrackView, associate_fixtures
from core.fixtures import FixtureProposal, dbscan, kept_voxels
from core.params import FixtureParams
from core.state import SceneState
from tests.core.fixture_scenes import (
    fixtures_of,
    run,
    with_second_table,
    with_twin_of_another_class,
)
from tests.core.rendered import (
    COUNTER,
    COUNTER_VIEWS,
    ROOM,
    TABLE,
    TABLE_VIEWS,
    batches,
    object_on,
)


def test_dbscan_separates_blobs_and_drops_noise() -> None:
    rng = np.random.default_rng(0)
    blob_a = rng.normal([0, 0, 0], 0.02, size=(30, 3))
    blob_b = rng.normal([1, 0, 0], 0.02, size=(30, 3))
    noise = np.array([[5.0, 5.0, 5.0]])
    labels = dbscan(np.vstack([blob_a, blob_b, noise]), eps=0.1, min_points=4)
    assert len(set(labels[:30])) == 1 and len(set(labels[30:60])) == 1
    assert labels[0] != labels[30] and labels[60] == -1


def test_voxels_need_the_class_threshold_and_a_margin() -> None:
    params = FixtureParams(
        taxonomy=("table", "desk"), default_class_threshold=0.4, min_class_margin=0.05
    )
    counts = np.array([1, 2, 1])
    sums = np.array(
        [[0.6, 0.3], [0.9, 0.84], [0.3, 0.1]]
    )  # clear; too close (0.45 vs 0.42); too low
    kept, _, margins = kept_voxels(counts, sums, params)
    assert kept.tolist() == [0, -1, -1]
    assert math.isclose(margins[1], 0.03)


def test_residual_cluster_inside_a_matched_fixture_is_absorbed() -> None:
    params = FixtureParams()
    track = FixtureTrackView("trk-000001", "table", (2.0, 2.0, 0.375), (1.4, 0.8, 0.75))
    whole = FixtureProposal(
        "table", np.array([2.0, 2.0, 0.4]), np.array([1.3, 0.8, 0.75]), 200, 0.3, 0.6, 10, "f"
    )
    piece = FixtureProposal(
        "table", np.array([2.5, 2.1, 0.7]), np.array([0.3, 0.3, 0.1]), 20, 0.3, 0.6, 5, "f"
    )
    far = FixtureProposal(
        "table", np.array([4.5, 4.0, 0.4]), np.array([1.0, 0.6, 0.75]), 100, 0.3, 0.6, 5, "f"
    )
    matches, absorbed = associate_fixtures([whole, piece, far], [track], params)
    assert matches == {0: "trk-000001"} and absorbed == {1: "trk-000001"}


def test_partial_views_give_one_confirmed_fixture_each_with_right_label_and_center() -> None:
    views = [*TABLE_VIEWS, *COUNTER_VIEWS] * 2
    state, events = run(SceneState(), batches(ROOM, views, "b", objects=False))
    found = fixtures_of(state)
    assert sorted(t.label for t in found) == ["counter", "table"]
    assert all(t.lifecycle == "confirmed" for t in found)
    truth = {"table": TABLE.center, "counter": COUNTER.center}
    for track in found:
        assert math.dist(track.center, truth[track.label]) < 0.3, (track.label, track.center)
    confirms = [e for e in events if e.type == "confirm"]
    assert len(confirms) == 2 and len({e.track_id for e in confirms}) == 2


def test_conflicting_class_scores_wait_for_verification() -> None:
    scores = {"table": {"table": 0.50, "desk": 0.48}, "counter": {"counter": 0.6, "table": 0.3}}
    state, events = run(
        SceneState(), batches(ROOM, TABLE_VIEWS * 3, "b", scores=scores, objects=False)
    )
    requested = [e for e in events if e.type == "verification_requested"]
    assert len(requested) == 1
    assert requested[0].track_id is not None
    table = state.tracks[requested[0].track_id]
    assert table.lifecycle == "tentative" and table.verification == "pending"
    assert (
        "table" in requested[0].details()["candidates"]
        and "desk" in requested[0].details()["candidates"]
    )
    assert not any(e.type == "confirm" and e.track_id == table.track_id for e in events)
    assert (
        requested[0].details()["candidates"]["table"]
        > requested[0].details()["candidates"]["desk"]
        > 0.4
    )


def test_mug_on_the_table_gets_the_table_as_parent_and_carried_to_the_counter_reparents_once() -> (
    None
):
    state, events = run(SceneState(), batches(ROOM, TABLE_VIEWS * 3 + COUNTER_VIEWS * 3, "b"))
    table_id = next(t.track_id for t in fixtures_of(state) if t.label == "table")
    counter_id = next(t.track_id for t in fixtures_of(state) if t.label == "counter")
    mug = next(t for t in state.tracks.values() if t.label == "mug")
    assert mug.parent == table_id and mug.lifecycle == "confirmed"
    carried = ROOM.moved("mug", (COUNTER.center[0], COUNTER.center[1], COUNTER.top_z + 0.05))
    # Its place seen empty first (two batches): its absence is established, so the mug found on
    # the counter recovers its identity (the fallback never takes a track still in place).
    state, events = run(state, batches(carried, TABLE_VIEWS[1:3] + COUNTER_VIEWS * 2, "c"))
    reparents = [e for e in events if e.type == "reparent"]
    assert len(reparents) == 1
    assert reparents[0].track_id == mug.track_id
    assert reparents[0].details() == {"old_parent": table_id, "new_parent": counter_id}
    assert state.tracks[mug.track_id].parent == counter_id
    assert [t.track_id for t in state.tracks.values() if t.label == "mug"] == [mug.track_id]


def test_a_fixture_track_of_another_class_in_the_same_place_is_merged() -> None:
    state, events = run(SceneState(), batches(ROOM, TABLE_VIEWS * 2, "b"))
    (table,) = [t for t in fixtures_of(state) if t.label == "table"]
    twin = "trk-000099"
    same = with_twin_of_another_class(state, events, twin, "desk", shift=0.05)
    assert same.tracks[twin].lifecycle == "confirmed" and same.tracks[twin].label == "desk"
    batch = next(iter(batches(ROOM, TABLE_VIEWS[:1], "again")))
    (merge,) = [e for e in decide(same, batch) if isinstance(e, TrackRetired)]
    assert (merge.track_id, merge.merged_into) == (twin, table.track_id)
    # Switched off (IoU 1.0), the desk stays: the class rule alone does not take it.
    off = replace(same.params, fixtures=replace(same.params.fixtures, same_place_min_iou=1.0))
    assert not [e for e in decide(same, batch, off) if isinstance(e, TrackRetired)]
    # Beside the table (half its footprint shared) it is another fixture, and stays.
    beside = with_twin_of_another_class(state, events, twin, "desk", shift=TABLE.size[0] * 0.5)
    assert not [e for e in decide(beside, batch) if isinstance(e, TrackRetired)]


def test_a_second_track_inside_a_confirmed_fixture_is_merged_into_it() -> None:
    mug = object_on(TABLE, "mug_1", "mug", (0.08, 0.08, 0.1), at=(0.3, 0.0))
    state, events = run(SceneState(), batches(ROOM.with_object(mug), TABLE_VIEWS * 2, "b"))
    (table,) = [t for t in fixtures_of(state) if t.label == "table"]
    twin = "trk-000099"
    state = with_second_table(state, events, twin)
    assert state.tracks[twin].lifecycle == "confirmed"
    (mug_id,) = [t.track_id for t in state.tracks.values() if t.label == "mug"]
    state = fold(
        state,
        [
            TrackReparented(
                track_id=mug_id,
                state="confirmed",
                frame_id="x",
                old_parent=table.track_id,
                new_parent=twin,
            )
        ],
    )
    # The table seen again: its cluster matches the first track, whose footprint holds the
    # second; the second retires into it and its mug follows, in the log.
    after, seen = run(state, batches(ROOM, TABLE_VIEWS[:1], "again"))
    (merge,) = [e for e in seen if isinstance(e, TrackRetired)]
    assert (merge.track_id, merge.reason, merge.merged_into) == (twin, "merged", table.track_id)
    assert after.tracks[twin].lifecycle == "retired"
    assert after.tracks[mug_id].parent == table.track_id
    assert [t.track_id for t in fixtures_of(after) if t.lifecycle == "confirmed"] == [
        f.track_id for f in fixtures_of(state) if f.track_id != twin and f.lifecycle == "confirmed"
    ]
    # The paper's rule keeps both.
    paper = replace(
        state.params, fixtures=replace(state.params.fixtures, absorb_contained_tracks=False)
    )
    assert not [
        e
        for e in decide(state, next(iter(batches(ROOM, TABLE_VIEWS[:1], "p"))), paper)
        if isinstance(e, TrackRetired)
    ]


def test_a_pinned_fixture_is_never_merged_away() -> None:
    # Pinned fixtures (a frozen baseline's) are exempt from dynamic removal (section 3.3): the
    # same-place and contained-track merges retire other tracks, never them.
    state, events = run(SceneState(), batches(ROOM, TABLE_VIEWS * 2, "b"))
    again = next(iter(batches(ROOM, TABLE_VIEWS[:1], "again")))
    twin = "trk-000099"
    for second in (
        with_twin_of_another_class(state, events, twin, "desk", shift=0.05),
        with_second_table(state, events, twin),
    ):
        assert [e.track_id for e in decide(second, again) if isinstance(e, TrackRetired)] == [twin]
        pinned = second.tracks[twin].evolved(pinned=True)
        kept = replace(second, tracks={**second.tracks, twin: pinned})
        assert not [e for e in decide(kept, again) if isinstance(e, TrackRetired)]
