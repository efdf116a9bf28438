"""Evaluation metrics on hand-built frames, worked out by hand: false absence (identity- and
class-conditioned), fixture matching, the mean and deviation, and the change-kind counts."""

from __future__ import annotations

import math

import pytest

from evaluation.change_metrics import (
    class_false_absence,
    false_absence,
)
from evaluation.metrics import (
    fixture_scores,
    mean_std,
)
from evaluation.protocols import change_kinds
from sim.truth import TruthFixture, TruthObject, Vec3
from tests.evaluation.metric_cases import (
    FAR,
    ORIGIN,
    node,
    prediction_frames,
    truth_frames,
    truth_object,
)


def test_identity_conditioned_false_absence_is_not_covered_by_a_neighbour_of_the_class() -> None:
    # Two mugs 0.3 m apart, each with its own track, both published at frames 0-1. At frames 2-3
    # mug a's track ta is unpublished while b's tb, 0.3 m from a, stays. Identity-conditioned
    # (strict): a is eligible at 1-3 and absent at 2-3, b eligible at 1-3 -> 2/6. Identity-
    # agnostic (lenient): tb is a mug node within 0.5 m of a, so a is never absent -> 0/6.
    beside: Vec3 = (0.3, 0.0, 0.0)
    truth = truth_frames(*([truth_object("a"), truth_object("b", beside)] for _ in range(4)))
    predictions = prediction_frames(
        *([node("ta"), node("tb", beside)] for _ in range(2)),
        *([node("tb", beside)] for _ in range(2)),
    )
    strict = false_absence(truth, predictions, {"a": "ta", "b": "tb"})
    assert (strict.absent, strict.eligible, strict.by_object) == (2, 6, {"a": 2})
    lenient = class_false_absence(truth, predictions)
    assert (lenient.absent, lenient.eligible) == (0, 6)


def test_false_absence_counts_only_after_first_publication() -> None:
    # mug (t1): published at 1, 2, 4, missing at 3. Eligible at 2, 3, 4 (not at 1: acquisition
    #           must be EARLIER) -> 3 eligible, 1 absent.
    # book (t2): first published at 2, gone at 3, 4. Frames 0-2 not eligible -> 2 eligible,
    #           2 absent.
    # cup (t4): published at 0-2 while present at 0-2, absent from truth at 3-4 -> eligible at
    #           1 and 2, never absent; the missing track at 3-4 does not count.
    # bowl: no assigned track, never eligible although present throughout.
    # eligible 3 + 2 + 2 = 7, absent 1 + 2 = 3, rate 3/7.
    def objects(cup_present: bool) -> list[TruthObject]:
        """The four objects of one frame."""
        return [
            truth_object("mug"),
            truth_object("book", FAR),
            truth_object("bowl", (0.0, 3.0, 0.0)),
            truth_object("cup", (0.0, -3.0, 0.0), present=cup_present),
        ]

    truth = truth_frames(
        objects(True), objects(True), objects(True), objects(False), objects(False)
    )
    predictions = prediction_frames(
        [node("t4")],
        [node("t1"), node("t4")],
        [node("t1"), node("t2"), node("t4")],
        [],
        [node("t1")],
    )
    result = false_absence(truth, predictions, {"mug": "t1", "book": "t2", "cup": "t4"})
    assert (result.absent, result.eligible) == (3, 7)
    assert result.rate == pytest.approx(3 / 7)
    assert result.by_object == {"mug": 1, "book": 2}


def test_class_false_absence_asks_for_any_node_of_the_class_within_half_a_metre() -> None:
    # mug at the origin, cup at 3 m.
    # frame 0: a mug node 0.1 m away covers the mug (acquired from frame 1 on); no cup node.
    # frame 1: the node near the mug is now labelled cup -> mug eligible, absent.
    # frame 2: a mug node 0.6 m away (outside the gate) -> mug absent; a cup node 0.4 m from the
    #          cup covers it (cup acquired from frame 3 on).
    # frame 3: mug not present; no nodes -> cup eligible, absent.
    # frame 4: a mug node exactly 0.5 m away (inclusive) covers the mug; cup absent.
    # eligible: mug 1, 2, 4 and cup 3, 4 = 5; absent: mug 1, 2 and cup 3, 4 = 4 -> 4/5.
    def objects(mug_present: bool = True) -> list[TruthObject]:
        return [
            TruthObject("mug", "mug", ORIGIN, mug_present, None, 500),
            TruthObject("cup", "cup", FAR, True, None, 500),
        ]

    truth = truth_frames(objects(), objects(), objects(), objects(False), objects())
    predictions = prediction_frames(
        [node("n1", (0.1, 0.0, 0.0))],
        [node("n1", ORIGIN, label="cup")],
        [node("n2", (0.6, 0.0, 0.0)), node("n3", (3.4, 0.0, 0.0), label="cup")],
        [],
        [node("n4", (0.5, 0.0, 0.0))],
    )
    result = class_false_absence(truth, predictions)
    assert (result.absent, result.eligible) == (4, 5)
    assert result.rate == pytest.approx(4 / 5)
    assert result.by_object == {"mug": 2, "cup": 2}


def test_class_false_absence_acquires_a_moved_object_anew_at_its_new_place() -> None:
    # The mug stands at the origin (frames 0-1), then is carried 3 m away (frames 2-5).
    # A memory that never removes keeps its node at the origin throughout and adds one at the
    # new place at frame 4. Frames 2-4: not acquired where it stands (the move's latency, not a
    # loss) -> not eligible; frame 5: acquired at frame 4 and covered -> eligible, present.
    # A memory that drops the new node at frame 5 has that one checkpoint absent.
    mug, moved = truth_object("mug"), truth_object("mug", FAR)
    truth = truth_frames([mug], [mug], [moved], [moved], [moved], [moved])
    kept = [node("n1")]
    both = [node("n1"), node("n2", FAR)]
    never_removes = prediction_frames(kept, kept, kept, kept, both, both)
    result = class_false_absence(truth, never_removes)
    assert (result.absent, result.eligible) == (0, 2)  # frame 1 (at the origin) and frame 5
    drops = prediction_frames(kept, kept, kept, kept, both, kept)
    result = class_false_absence(truth, drops)
    assert (result.absent, result.eligible) == (1, 2)
    assert result.by_object == {"mug": 1}


def test_false_absence_with_nothing_eligible_is_zero() -> None:
    truth = truth_frames([truth_object("mug")], [truth_object("mug")])
    predictions = prediction_frames([], [node("t1")])
    result = false_absence(truth, predictions, {"mug": "t1"})
    assert (result.rate, result.absent, result.eligible) == (0.0, 0, 0)


def test_fixture_matching_by_class_and_distance() -> None:
    truth = [
        TruthFixture("T1", "table", (0.0, 0.0, 0.4), (1.0, 1.0, 0.8)),
        TruthFixture("T2", "table", (3.0, 0.0, 0.4), (1.0, 1.0, 0.8)),
        TruthFixture("C1", "counter", (0.0, 3.0, 0.45), (2.0, 0.6, 0.9)),
        TruthFixture("S1", "shelf", (5.0, 5.0, 1.0), (1.0, 0.4, 2.0)),
    ]
    predicted = [
        node("P1", (0.2, 0.0, 0.4), "fixture", "table"),  # T1 at 0.2 m: matched
        node("P2", (0.5, 0.0, 0.4), "fixture", "table"),  # duplicate of T1 (taken), T2 2.5 m
        node("P3", (0.0, 3.1, 0.45), "fixture", "table"),  # next to C1 but the wrong class
        node("P4", (0.0, 4.2, 0.45), "fixture", "counter"),  # C1 at 1.2 m: outside 1.0 m
        node("P5", (5.0, 5.6, 1.0), "fixture", "shelf"),  # S1 at 0.6 m: matched
        node("P6", (9.0, 9.0, 0.5), "fixture", "sofa"),  # no sofa in truth
        node("o1", (3.0, 0.0, 0.4), "object", "table"),  # an object node: ignored
    ]
    scores = fixture_scores(truth, predicted)
    # matched 2 of 6 predicted fixtures and 4 true ones: precision 1/3, recall 1/2,
    # f1 = 2 * (1/6) / (5/6) = 2/5; center error (0.2 + 0.6) / 2 = 0.4.
    # Counts per class (pred - truth): table 3-2, counter 1-1, shelf 1-1, sofa 1-0 -> MAE 2/4.
    assert scores.matched == 2
    assert scores.fixture_map == {"T1": "P1", "S1": "P5"}
    assert scores.precision == pytest.approx(1 / 3)
    assert scores.recall == pytest.approx(1 / 2)
    assert scores.f1 == pytest.approx(2 / 5)
    assert scores.center_error == pytest.approx(0.4)
    assert scores.count_mae == pytest.approx(0.5)


def test_fixture_greedy_takes_the_closest_pair_first() -> None:
    # P1 is 0.3 m from T1 and 0.1 m from T2; P2 is 0.5 m from T1 and 0.9 m from T2.
    # Ascending distance: (T2, P1) 0.1 first, then (T1, P2) 0.5; (T1, P1) is skipped.
    truth = [
        TruthFixture("T1", "table", (0.0, 0.0, 0.0), (1.0, 1.0, 1.0)),
        TruthFixture("T2", "table", (0.4, 0.0, 0.0), (1.0, 1.0, 1.0)),
    ]
    predicted = [
        node("P1", (0.3, 0.0, 0.0), "fixture", "table"),
        node("P2", (-0.5, 0.0, 0.0), "fixture", "table"),
    ]
    scores = fixture_scores(truth, predicted)
    assert scores.fixture_map == {"T2": "P1", "T1": "P2"}
    assert scores.center_error == pytest.approx(0.3)
    assert (scores.precision, scores.recall, scores.f1, scores.count_mae) == (1.0, 1.0, 1.0, 0.0)


def test_fixture_scores_with_nothing_on_either_side() -> None:
    scores = fixture_scores([], [])
    assert (scores.precision, scores.recall, scores.f1, scores.matched) == (0.0, 0.0, 0.0, 0)
    assert scores.center_error is None
    assert scores.count_mae == 0.0
    assert scores.fixture_map == {}


def test_mean_std_uses_the_sample_deviation() -> None:
    # mean 2.5; squared deviations 2.25 + 0.25 + 0.25 + 2.25 = 5, / (4 - 1) -> std sqrt(5/3).
    mean, std = mean_std([1.0, 2.0, 3.0, 4.0])
    assert mean == 2.5
    assert std == pytest.approx(math.sqrt(5 / 3))
    assert mean_std([0.7]) == (0.7, 0.0)


def test_carries_and_removals_seen_empty_are_counted_apart() -> None:
    def row(kind: str, observable: int | None, within: bool, **more: object) -> dict[str, object]:
        return {
            "type": kind,
            "observable_frame": observable,
            "identity_before": more.get("before", "trk-1"),
            "recalled_identity": within,
            "empty_place_batches": more.get("empty"),
        }

    trace = [
        row("move", 12, True),
        row("transfer", 12, False),
        row("move", None, False),  # never observable: not judged
        row("transfer", 12, False, before=None),  # not held before: no identity to carry
        row("disappear", 12, True, empty=3),
        row("disappear", 12, False, empty=2),  # its place seen empty in 2 batches: not judged
        row("disappear", 12, False, empty=4),  # removed late
        row("disappear", 12, False, empty=5, before=None),  # never held: nothing to remove
        row("appear", 12, True),
    ]
    assert change_kinds(trace) == {
        "carries_total": 2,
        "carries_recalled_identity": 1,
        "removals_seen_empty": 2,
        "removals_seen_empty_recalled": 1,
    }
