"""Evaluation metrics on hand-built frames whose expected scores are worked out by hand."""

from __future__ import annotations

import pytest

from core.events import ObjectAdded, TrackConfirmed, TrackMoved, TrackRemoved, TrackReparented
from evaluation.change_metrics import (
    event_recall,
    identity_before,
    latency_summary,
    lenient_event_recall,
)
from evaluation.metrics import (
    global_assignment,
    identity_metrics,
    presence_f1,
)
from evaluation.predictions import MethodEvent
from sim.truth import FrameTruth, ScheduledEvent, Vec3
from tests.evaluation.metric_cases import (
    FAR,
    node,
    prediction_frames,
    truth_frames,
    truth_object,
)


def test_perfect_tracker_scores_one_and_tolerates_an_empty_frame() -> None:
    # a at the origin and b at 3 m, each followed within 0.1 m by its own track; frame 2 is
    # empty on both sides. IDTP = 6, IDFP = IDFN = 0 -> idf1 = 1, no switch, 4 frames.
    truth = truth_frames(
        [truth_object("a"), truth_object("b", FAR)],
        [truth_object("a"), truth_object("b", FAR)],
        [],
        [truth_object("a"), truth_object("b", FAR)],
    )
    near_a, near_b = (0.1, 0.0, 0.0), (3.0, 0.1, 0.0)
    predictions = prediction_frames(
        [node("t1", near_a), node("t2", near_b)],
        [node("t1", near_a), node("t2", near_b)],
        [],
        [node("t1", near_a), node("t2", near_b)],
    )
    scores = identity_metrics(truth, predictions)
    assert (scores.idf1, scores.idp, scores.idr) == (1.0, 1.0, 1.0)
    assert scores.id_switches == 0
    assert scores.num_frames == 4
    assert global_assignment(truth, predictions) == {"a": "t1", "b": "t2"}


def test_identity_change_midway_is_one_switch() -> None:
    # a is present in 5 frames; track t1 follows it in frames 0-2, then t2 takes over in
    # frames 3-4 (one switch). A ghost g, 3 m away, is published in frame 0 only.
    # Global matching a -> t1: IDTP = 3, IDFN = 5 - 3 = 2, IDFP = 6 published - 3 = 3.
    # idp = 3/6, idr = 3/5, idf1 = 2*3 / (5 + 6) = 6/11.
    truth = truth_frames(*([truth_object("a")] for _ in range(5)))
    predictions = prediction_frames(
        [node("t1"), node("g", FAR)],
        [node("t1")],
        [node("t1")],
        [node("t2")],
        [node("t2")],
    )
    scores = identity_metrics(truth, predictions)
    assert scores.id_switches == 1
    assert scores.idp == pytest.approx(0.5)
    assert scores.idr == pytest.approx(0.6)
    assert scores.idf1 == pytest.approx(6 / 11)
    assert global_assignment(truth, predictions) == {"a": "t1"}


def test_track_beyond_half_a_metre_never_matches_but_one_at_half_a_metre_does() -> None:
    # 0.6 m is outside the 0.5 m gate in every frame: no identity true positive at all.
    truth = truth_frames([truth_object("a")], [truth_object("a")])
    away = prediction_frames([node("t1", (0.6, 0.0, 0.0))], [node("t1", (0.6, 0.0, 0.0))])
    scores = identity_metrics(truth, away)
    assert (scores.idf1, scores.idp, scores.idr, scores.id_switches) == (0.0, 0.0, 0.0, 0)
    assert global_assignment(truth, away) == {}
    # Exactly 0.5 m (squared 0.25, exact in binary) is inside: the gate is inclusive.
    at_gate = prediction_frames([node("t1", (0.5, 0.0, 0.0))], [node("t1", (0.5, 0.0, 0.0))])
    assert identity_metrics(truth, at_gate).idf1 == 1.0
    assert global_assignment(truth, at_gate) == {"a": "t1"}


def test_no_ground_truth_scores_zero() -> None:
    # Nothing is present (b is listed but absent), yet a track is published.
    truth = truth_frames([], [truth_object("b", present=False)])
    predictions = prediction_frames([node("t1")], [node("t1")])
    scores = identity_metrics(truth, predictions)
    assert (scores.idf1, scores.id_switches, scores.num_frames) == (0.0, 0, 2)


def test_nothing_published_scores_zero_not_nan() -> None:
    # a present in 2 frames, no track: IDTP = 0, IDFN = 2, IDFP = 0; idp is 0/0 in motmetrics.
    truth = truth_frames([truth_object("a")], [truth_object("a")])
    scores = identity_metrics(truth, prediction_frames([], []))
    assert (scores.idf1, scores.idp, scores.idr, scores.id_switches) == (0.0, 0.0, 0.0, 0)


def test_global_assignment_maximizes_total_co_occurrence_not_greedy() -> None:
    # a at the origin, b at 3 m. Co-occurrences: a-t1 = 3 (frames 0-2), a-t2 = 2 (frames
    # 0-1), b-t1 = 2 (frames 3-4), b-t2 = 0; the ghost g (1 m from b) never co-occurs.
    # Greedy a -> t1 totals 3; Hungarian a -> t2, b -> t1 totals 4.
    truth = truth_frames(*([truth_object("a"), truth_object("b", FAR)] for _ in range(5)))
    predictions = prediction_frames(
        [node("t1"), node("t2"), node("g", (4.0, 0.0, 0.0))],
        [node("t1"), node("t2")],
        [node("t1")],
        [node("t1", FAR)],
        [node("t1", FAR)],
    )
    assert global_assignment(truth, predictions) == {"a": "t2", "b": "t1"}


def test_a_node_stands_only_for_an_object_of_its_label() -> None:
    # A cluttered table: a remote 0.3 m from a mug. The mug is carried 3 m away at frame 2; its
    # track m stays at the old place until frame 4, when the memory moves it; the remote's own
    # track r is published at frame 4. Class-agnostic, the remote takes the stale m at frames
    # 2-3 and passes to r at frame 4: a switch that is no one's error. Class-aware, m is never
    # the remote's, so there is no switch: IDTP = 4 (mug: frames 0, 1, 4, 5) + 2 (remote:
    # frames 4-5), IDFN = 12 - 6, IDFP = 8 published - 6 -> idf1 = 12 / 20.
    remote_at: Vec3 = (0.3, 0.0, 0.0)
    remote = truth_object("remote", remote_at, label="remote")
    truth = truth_frames(
        *([truth_object("mug"), remote] for _ in range(2)),
        *([truth_object("mug", FAR), remote] for _ in range(4)),
    )
    predictions = prediction_frames(
        *([node("m")] for _ in range(4)),
        *([node("m", FAR), node("r", remote_at, label="remote")] for _ in range(2)),
    )
    agnostic = identity_metrics(truth, predictions, class_aware=False)
    assert agnostic.id_switches == 1
    aware = identity_metrics(truth, predictions)
    assert aware.id_switches == 0
    assert aware.idf1 == pytest.approx(12 / 20)
    assert global_assignment(truth, predictions) == {"mug": "m", "remote": "r"}
    # A node of another label within the gate covers nothing class-aware; class-agnostic, a
    # cup's node at the mug's old place "tracks" the remote for 6 frames.
    cup_only = prediction_frames(*([node("c", label="cup")] for _ in range(6)))
    assert identity_metrics(truth, cup_only).idf1 == 0.0
    assert global_assignment(truth, cup_only) == {}
    assert global_assignment(truth, cup_only, class_aware=False) == {"remote": "c"}


def test_presence_counts_ghosts_missing_tracks_far_tracks_and_unassigned_objects() -> None:
    # frame 0: a, b present; t1 (3 m from a: outside the 0.5 m gate), t2 on b, ghost g, and a
    #          fixture node that object metrics ignore      -> TP 1 (b), FN 1 (a), FP 1 (g);
    #          t1 is a's own track, published away from it: a miss, not also a ghost
    # frame 1: a, b present; t1 on a, t2 on b, g published     -> TP 2, FP 1 (g)
    # frame 2: a, b, c present (c unassigned); only t1         -> TP 1, FN 2 (b's t2, c)
    # frame 3: a present, b listed absent; t1, t2 published     -> TP 1, FP 1 (t2)
    # TP 5, FP 3, FN 3: precision 5/8, recall 5/8, f1 = 10 / (10 + 3 + 3) = 5/8.
    a, b, c = truth_object("a"), truth_object("b", FAR), truth_object("c")
    truth = truth_frames([a, b], [a, b], [a, b, c], [a, truth_object("b", FAR, present=False)])
    predictions = prediction_frames(
        [node("t1", FAR), node("t2", FAR), node("g"), node("f1", kind="fixture")],
        [node("t1"), node("t2", FAR), node("g")],
        [node("t1")],
        [node("t1"), node("t2", FAR)],
    )
    scores = presence_f1(truth, predictions, {"a": "t1", "b": "t2"})
    assert (scores.tp, scores.fp, scores.fn) == (5, 3, 3)
    assert scores.precision == pytest.approx(5 / 8)
    assert scores.recall == pytest.approx(5 / 8)
    assert scores.f1 == pytest.approx(5 / 8)
    # Without a gate (a huge radius) t1 in frame 0 counts for a: the earlier, distance-blind figure.
    loose = presence_f1(truth, predictions, {"a": "t1", "b": "t2"}, max_distance=100.0)
    assert (loose.tp, loose.fp, loose.fn) == (6, 3, 2)


def test_lenient_event_recall_per_event_type() -> None:
    assignment = {"mug": "t1", "book": "t2", "bowl": "t3", "cup": "t4"}
    fixture_map = {"table": "F1", "counter": "F2"}
    scheduled = [
        ScheduledEvent(2, "appear", "mug", parent="table"),  # confirm t1 at 3: recalled
        ScheduledEvent(4, "move", "book"),  # only t2's move at 3 (early), t1's at 5: not
        ScheduledEvent(5, "disappear", "bowl"),  # remove t3 at 5, the same frame: recalled
        ScheduledEvent(6, "transfer", "book", parent="counter"),  # reparent to F1: wrong
        ScheduledEvent(6, "transfer", "mug", parent="counter"),  # reparent to F2 at 8: recalled
        ScheduledEvent(6, "transfer", "cup", parent="shelf"),  # shelf unmatched: never
        ScheduledEvent(1, "appear", "cup", parent="table"),  # add at 1, confirm at 10 >= n_frames
        ScheduledEvent(3, "disappear", "vase"),  # vase has no track: never
    ]
    method_events = [
        MethodEvent(1, "t4", ObjectAdded),
        MethodEvent(2, "t1", ObjectAdded),
        MethodEvent(3, "t1", TrackConfirmed),
        MethodEvent(3, "t2", TrackMoved),
        MethodEvent(5, "t1", TrackMoved),
        MethodEvent(5, "t3", TrackRemoved),
        MethodEvent(7, "t2", TrackReparented, new_parent="F1"),
        MethodEvent(7, "t4", TrackReparented),
        MethodEvent(8, "t1", TrackReparented, new_parent="F2"),
        MethodEvent(10, "t4", TrackConfirmed),
    ]
    result = lenient_event_recall(scheduled, method_events, assignment, fixture_map, n_frames=10)
    assert [outcome.recalled for outcome in result.per_event] == [
        True,
        False,
        True,
        False,
        True,
        False,
        False,
        False,
    ]
    assert [outcome.event for outcome in result.per_event] == scheduled
    assert (result.recalled, result.total, result.recalled_any) == (3, 8, 3)


def test_event_latency_counts_batches_from_the_first_observable_frame() -> None:
    # Two frames per batch; bound 10 batches.
    # mug appears at 2, first seen at 6 (batch 3), confirmed at 9 (batch 4): latency 1.
    # bowl disappears at 4, never observable: removed at 30 (batch 15), latency counted from the
    #   scheduled frame (batch 2): 13 > 10 -> reflected, but not recalled within the bound.
    # book moves at 4, observable at 8 (batch 4), its move at 5 (batch 2): floored to 0.
    # cup transfers at 6: no reparent at all -> missed.
    assignment = {"mug": "t1", "bowl": "t2", "book": "t3", "cup": "t4"}
    scheduled = [
        ScheduledEvent(2, "appear", "mug", parent="table"),
        ScheduledEvent(4, "disappear", "bowl"),
        ScheduledEvent(4, "move", "book"),
        ScheduledEvent(6, "transfer", "cup", parent="table"),
    ]
    method_events = [
        MethodEvent(9, "t1", TrackConfirmed),
        MethodEvent(30, "t2", TrackRemoved),
        MethodEvent(5, "t3", TrackMoved),
        MethodEvent(12, "t3", TrackMoved),
    ]
    result = lenient_event_recall(
        scheduled,
        method_events,
        assignment,
        {"table": "F1"},
        n_frames=40,
        observable_frames=[6, None, 8, 7],
        frames_per_batch=2,
        latency_bound_batches=10,
    )
    assert [o.latency_batches for o in result.per_event] == [1, 13, 0, None]
    assert [o.recalled_frame for o in result.per_event] == [9, 30, 5, None]
    assert [o.within_bound for o in result.per_event] == [True, False, True, False]
    assert (result.recalled, result.recalled_any, result.unobservable, result.total) == (2, 3, 1, 4)
    assert latency_summary([1, 13, 0]) == (1.0, 13)
    assert latency_summary([1, 4]) == (2.5, 4) and latency_summary([]) is None


TABLE_TO_COUNTER = {"table": "F1", "counter": "F2"}


def transfer_world() -> list[FrameTruth]:
    """A cup on the table at the origin (frames 0-3), carried to the counter 3 m away at frame 4
    (frames 4-9)."""
    return truth_frames(
        *([truth_object("cup")] for _ in range(4)),
        *([truth_object("cup", FAR)] for _ in range(6)),
    )


def test_a_new_track_at_the_new_place_is_not_the_transfer() -> None:
    # t1 stands for the cup on the table (frames 0-3) and stays there, stale, until frame 5; a
    # new track t2 is published on the counter from frame 5 (5 frames against t1's 4, so the
    # run's assignment gives the cup t2), its first parent event (from none) at frame 5. The
    # lenient reading takes that for the transfer; the identity the cup had before it is t1,
    # which never reaches the counter, so the strict reading finds no transfer.
    truth = transfer_world()
    predictions = prediction_frames(
        *([node("t1")] for _ in range(5)),
        *([node("t2", FAR)] for _ in range(5)),
    )
    assignment = global_assignment(truth, predictions)
    assert assignment == {"cup": "t2"}
    transfer = [ScheduledEvent(4, "transfer", "cup", parent="counter")]
    first_parent = [MethodEvent(5, "t2", TrackReparented, new_parent="F2", old_parent=None)]
    lenient = lenient_event_recall(transfer, first_parent, assignment, TABLE_TO_COUNTER, len(truth))
    assert (lenient.recalled, lenient.per_event[0].recalled_frame) == (1, 5)
    assert identity_before(transfer[0], assignment, truth, predictions) is None
    strict = event_recall(transfer, first_parent, assignment, TABLE_TO_COUNTER, truth, predictions)
    assert (strict.recalled, strict.recalled_any, strict.total) == (0, 0, 1)
    assert strict.per_event[0].recalled_frame is None


def test_the_old_identity_reparented_at_the_new_place_counts_in_both_readings() -> None:
    # t1 stands for the cup on the table, then on the counter from frame 6, reparented from the
    # table's node F1 to F2 at frame 6: the same identity at the new place, in both readings.
    truth = transfer_world()
    predictions = prediction_frames(
        *([node("t1")] for _ in range(6)),
        *([node("t1", FAR)] for _ in range(4)),
    )
    assignment = global_assignment(truth, predictions)
    assert assignment == {"cup": "t1"}
    transfer = [ScheduledEvent(4, "transfer", "cup", parent="counter")]
    reparented = [MethodEvent(6, "t1", TrackReparented, new_parent="F2", old_parent="F1")]
    assert identity_before(transfer[0], assignment, truth, predictions) == "t1"
    strict = event_recall(transfer, reparented, assignment, TABLE_TO_COUNTER, truth, predictions)
    lenient = lenient_event_recall(transfer, reparented, assignment, TABLE_TO_COUNTER, len(truth))
    assert strict.per_event[0].recalled_frame == lenient.per_event[0].recalled_frame == 6
    assert strict.recalled == lenient.recalled == 1
    # The same track's first parent (it had none on the table) is not a change of parent: only
    # the lenient reading counts it.
    first_parent = [MethodEvent(6, "t1", TrackReparented, new_parent="F2", old_parent=None)]
    assert (
        event_recall(
            transfer, first_parent, assignment, TABLE_TO_COUNTER, truth, predictions
        ).recalled
        == 0
    )
    assert (
        lenient_event_recall(
            transfer, first_parent, assignment, TABLE_TO_COUNTER, len(truth)
        ).recalled
        == 1
    )


def test_a_strict_move_waits_for_the_old_identity_to_stand_at_the_new_place() -> None:
    # The cup moves 3 m at frame 4. t1 stands for it before; its TrackMoved at frame 4 leaves it
    # 1 m short of the cup (frames 4-6) and it reaches the cup at frame 7. Lenient: reflected at
    # the move event (frame 4); strict: at frame 7, when the old identity stands where the cup
    # now is. Two frames a batch, bound 1 batch from the observable frame 4: the strict latency
    # (batch 3 - batch 2 = 1) is within it, so both count; with a bound of 0 only the lenient one.
    truth = transfer_world()
    short_of_it: Vec3 = (2.0, 0.0, 0.0)
    predictions = prediction_frames(
        *([node("t1")] for _ in range(4)),
        *([node("t1", short_of_it)] for _ in range(3)),
        *([node("t1", FAR)] for _ in range(3)),
    )
    assignment = global_assignment(truth, predictions)
    move = [ScheduledEvent(4, "move", "cup")]
    moved = [MethodEvent(4, "t1", TrackMoved)]
    strict = event_recall(move, moved, assignment, {}, truth, predictions)
    lenient = lenient_event_recall(move, moved, assignment, {}, len(truth))
    assert (strict.per_event[0].recalled_frame, lenient.per_event[0].recalled_frame) == (7, 4)
    strict_tight = event_recall(move, moved, assignment, {}, truth, predictions, None, 2, 0)
    lenient_tight = lenient_event_recall(move, moved, assignment, {}, len(truth), None, 2, 0)
    assert (strict_tight.recalled, lenient_tight.recalled) == (0, 1)
    # A track that never stood for the cup before the move is not its identity, whatever the
    # run's assignment: t9 appears on the new place at frame 4 and outlasts t1 there.
    replaced = prediction_frames(
        *([node("t1")] for _ in range(3)),
        *([node("t9", FAR)] for _ in range(7)),
    )
    assignment = global_assignment(truth, replaced)
    assert assignment == {"cup": "t9"}
    late = [MethodEvent(6, "t9", TrackMoved)]
    assert lenient_event_recall(move, late, assignment, {}, len(truth)).recalled == 1
    assert event_recall(move, late, assignment, {}, truth, replaced).recalled == 0


def test_appear_and_disappear_read_the_same_in_both_readings() -> None:
    # The mug appears at frame 2 (t1 confirmed at 3) and disappears at frame 6 (t1 removed at 7).
    mug = truth_object("mug")
    gone = truth_object("mug", present=False)
    truth = truth_frames([gone], [gone], *([mug] for _ in range(4)), [gone], [gone])
    predictions = prediction_frames([], [], [], *([node("t1")] for _ in range(4)), [])
    scheduled = [
        ScheduledEvent(2, "appear", "mug", parent="table"),
        ScheduledEvent(6, "disappear", "mug"),
    ]
    events = [MethodEvent(3, "t1", TrackConfirmed), MethodEvent(7, "t1", TrackRemoved)]
    assignment = global_assignment(truth, predictions)
    strict = event_recall(scheduled, events, assignment, {"table": "F1"}, truth, predictions)
    lenient = lenient_event_recall(scheduled, events, assignment, {"table": "F1"}, len(truth))
    assert [o.recalled_frame for o in strict.per_event] == [3, 7]
    assert [o.recalled_frame for o in lenient.per_event] == [3, 7]
