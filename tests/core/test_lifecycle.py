"""The lifecycle rules of core/lifecycle.py (section 3.3) against hand-computed values:
confirmation at p_exist >= 0.72 after 2 batches (objects) or 3 (fixtures), demotion below 0.30,
removal at <= 0.12 after 3 visible misses, move at 0.35 m; and the one rule for every source of
a publication (batch, verdict, inspection capture)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from core.existence import miss, object_sighting, verdict_update
from core.geometry import Proposal
from core.lifecycle import (
    miss_decision,
    moved_distance,
    should_confirm,
    should_demote,
    should_move,
    should_remove,
    sighting_decision,
    verdict_decision,
)
from core.params import Params
from core.state import Track
from core.values import LifecycleState, TrackKind
from core.visibility import Sighting

PARAMS = Params()
# Equation (3) as the paper writes it: every visible miss counts eta_m once.
UNWEIGHTED = Params.from_dict({"existence": {"clear_view_miss_weight": 1.0}})
P_ONE_SIGHTING = 0.7310585786300049  # logistic(0 + 1.0): the prior and one observation


def track(
    lifecycle: LifecycleState,
    logodds: float,
    *,
    kind: TrackKind = "object",
    batches: int = 2,
    misses: int = 0,
    pinned: bool = False,
    published: tuple[float, float, float] | None = (0.0, 0.0, 1.0),
) -> Track:
    return Track(
        track_id="trk-000001",
        kind=kind,
        lifecycle=lifecycle,
        class_evidence={"mug": 2.0},
        existence_logodds=logodds,
        center=(0.0, 0.0, 1.0),
        extent=(0.1, 0.1, 0.1),
        recent_centers=((0.0, 0.0, 1.0),),
        parent_evidence={"trk-000009": 2.0},
        parent="trk-000009",
        batches_observed=batches,
        visible_misses=misses,
        published_center=published,
        pinned=pinned,
    )


def proposal(x: float = 0.0) -> Proposal:
    return Proposal(
        label="mug",
        score=0.9,
        kind="object",
        center=np.array([x, 0.0, 1.0]),
        extent=np.array([0.1, 0.1, 0.1]),
        embedding=None,
        valid_pixels=400,
        frame_id="f1",
        timestamp=1.0,
        bottom_z=0.95,
    )


def test_confirmation_needs_two_batches_and_p_exist_0_72() -> None:
    # One sighting: p = 0.7311 >= 0.72 but 1 batch < 2; a second batch publishes.
    assert not should_confirm("object", "tentative", P_ONE_SIGHTING, 1, PARAMS)
    assert should_confirm("object", "tentative", P_ONE_SIGHTING, 2, PARAMS)
    # Many batches, p = 0.7199 < 0.72: not yet; exactly 0.72: published.
    assert not should_confirm("object", "tentative", 0.7199, 9, PARAMS)
    assert should_confirm("object", "tentative", 0.72, 2, PARAMS)
    # A demoted node may come back; a published one is not published twice.
    assert should_confirm("object", "demoted", 0.8, 2, PARAMS)
    assert not should_confirm("object", "confirmed", 0.8, 2, PARAMS)


def test_fixtures_need_three_batches() -> None:
    assert not should_confirm("fixture", "tentative", 0.8, 2, PARAMS)
    assert should_confirm("fixture", "tentative", 0.8, 3, PARAMS)


def test_a_verified_capture_stands_in_for_batches_not_for_the_existence_belief() -> None:
    # One batch, p = 0.7311: a capture publishes. p = 0.5 (a demoted node seen again): it does not.
    assert should_confirm("object", "tentative", P_ONE_SIGHTING, 1, PARAMS, verified_capture=True)
    assert not should_confirm("object", "demoted", 0.5, 1, PARAMS, verified_capture=True)


def test_demotion_is_strictly_below_0_30_and_only_of_a_published_node() -> None:
    assert should_demote("confirmed", 0.2999, PARAMS.lifecycle)
    assert not should_demote("confirmed", 0.30, PARAMS.lifecycle)
    assert not should_demote("tentative", 0.1, PARAMS.lifecycle)


def test_removal_needs_p_0_12_and_three_misses_and_spares_pinned_fixtures() -> None:
    lifecycle = PARAMS.lifecycle
    assert should_remove("demoted", 0.12, 3, False, lifecycle)
    assert not should_remove("demoted", 0.12, 2, False, lifecycle)
    assert not should_remove("demoted", 0.1201, 5, False, lifecycle)
    assert not should_remove("demoted", 0.05, 5, True, lifecycle)
    assert not should_remove("removed", 0.05, 5, False, lifecycle)


def test_a_move_is_at_least_0_35_m_from_the_published_position() -> None:
    # |(0.35, 0, 0) - 0| = 0.35 >= 0.35; 0.3 is not; a node never published never moves.
    assert moved_distance((0.0, 0.0, 0.0), (0.35, 0.0, 0.0)) == 0.35
    assert should_move((0.0, 0.0, 0.0), (0.35, 0.0, 0.0), PARAMS.lifecycle)
    assert not should_move((0.0, 0.0, 0.0), (0.3, 0.0, 0.0), PARAMS.lifecycle)
    assert not should_move(None, (5.0, 0.0, 0.0), PARAMS.lifecycle)


def missed(subject: Track) -> Sighting:
    """A frame that showed `subject`'s place (20 of 125 samples passed)."""
    return Sighting(passed=20, expected_fraction=0.1, frame_id=f"f9-{subject.track_id}")


def test_a_visible_miss_demotes_below_0_30() -> None:
    # l = -0.6 (p 0.3543), 2 misses; one more: l = -0.6 - 0.7 = -1.3, p = 0.2142 < 0.30: demote;
    # 3 misses but p 0.2142 > 0.12: not removed.
    subject = track("confirmed", -0.6, misses=2)
    decision = miss_decision(subject, miss(subject, missed(subject), UNWEIGHTED), UNWEIGHTED)
    assert decision.demote is not None
    assert decision.demote.p_exist == pytest.approx(0.2141650169574414, abs=1e-12)
    assert decision.remove is None
    assert decision.frame_id == "f9-trk-000001"


def test_a_visible_miss_removes_at_0_12_after_three() -> None:
    # l = -1.3, 4 misses; one more: l = -2.0, p = 0.1192 <= 0.12, 5 misses >= 3: removed.
    subject = track("demoted", -1.3, misses=4)
    decision = miss_decision(subject, miss(subject, missed(subject), UNWEIGHTED), UNWEIGHTED)
    assert decision.demote is None  # demoted already
    assert decision.remove is not None
    assert decision.remove.p_exist == pytest.approx(0.11920292202211755, abs=1e-12)
    assert decision.remove.visible_misses == 5


def test_a_clear_view_of_an_empty_place_counts_twice_a_glimpse_once() -> None:
    # From l = 1.5: a clear view (the box covers 10% of the image) subtracts 2 x 0.7; a view
    # at the missed-detection floor (0.05%) 0.7; halfway between floor and clear (0.19%), 1.05.
    subject = track("confirmed", 1.5)
    for fraction, logodds in ((0.1, 0.1), (0.0005, 0.8), ((0.0005 + 0.0033) / 2, 0.45)):
        sighting = Sighting(passed=20, expected_fraction=fraction, frame_id="f")
        assert miss(subject, sighting, PARAMS).existence.logodds == pytest.approx(logodds)
    # Half the box outside the image halves what the view shows.
    cut = Sighting(passed=20, expected_fraction=0.0066, in_image_share=0.5, frame_id="f")
    assert miss(subject, cut, PARAMS).existence.logodds == pytest.approx(0.1)
    # A fixture's miss counts once, as does every miss with the weight at 1 (the paper's).
    fixture = track("confirmed", 1.5, kind="fixture")
    clear = Sighting(passed=20, expected_fraction=0.1, frame_id="f")
    assert miss(fixture, clear, PARAMS).existence.logodds == pytest.approx(0.8)
    assert miss(subject, clear, UNWEIGHTED).existence.logodds == pytest.approx(0.8)


def test_pinned_fixtures_and_append_only_memories_keep_their_nodes() -> None:
    pinned = track("confirmed", -1.3, kind="fixture", misses=4, pinned=True)
    decision = miss_decision(pinned, miss(pinned, missed(pinned), PARAMS), PARAMS)
    assert (decision.demote, decision.remove) == (None, None)
    kept = track("confirmed", -1.3, misses=4)
    decision = miss_decision(kept, miss(kept, missed(kept), PARAMS), PARAMS, removal=False)
    assert (decision.demote, decision.remove) == (None, None)
    assert decision.update is not None  # the miss itself is still recorded


def test_a_second_batch_publishes_and_a_relocation_moves_and_resets_support() -> None:
    # Tentative, l = 1.0, 1 batch, never published: + 1.0 -> clamped 1.5 (p 0.8176), 2 batches.
    subject = track("tentative", 1.0, batches=1, published=None)
    sighting = object_sighting(subject, "trk-000001", [proposal()], ["trk-000009"], PARAMS)
    decision = sighting_decision(subject, sighting, PARAMS)
    assert decision.publish is not None and decision.publish.reason is None
    assert decision.publish.p_exist == pytest.approx(0.8175744761936437, abs=1e-12)
    assert decision.publish.batches_observed == 2
    # Support evidence: 2.0 + 1.0 on the same parent, no reparent.
    assert decision.parent_evidence == {"trk-000009": 3.0} and decision.reparent is None
    # Seen 0.5 m away: outside its box grown by 0.10 m (0.05 + 0.10 = 0.15), no appearance to
    # vouch for it: an uncorroborated match moves, publishes and reparents nothing.
    far = object_sighting(
        track("confirmed", 1.5), "trk-000001", [proposal(0.5)], ["trk-000008"], PARAMS
    )
    assert not far.corroborated
    decision = sighting_decision(track("confirmed", 1.5), far, PARAMS)
    assert (decision.publish, decision.move, decision.reparent) == (None, None, None)
    # Published at x = -0.4 and seen in its box at x = 0: moved 0.4 m, the old support's
    # evidence is dropped and the new parent takes over.
    moved = replace(track("confirmed", 1.5), published_center=(-0.4, 0.0, 1.0))
    sighting = object_sighting(moved, "trk-000001", [proposal()], ["trk-000008"], PARAMS)
    decision = sighting_decision(moved, sighting, PARAMS)
    assert decision.move is not None and decision.move.distance == pytest.approx(0.4, abs=1e-12)
    assert decision.parent_evidence == {"trk-000008": 1.0}
    assert decision.reparent is not None
    assert (decision.reparent.old_parent, decision.reparent.new_parent) == (
        "trk-000009",
        "trk-000008",
    )


def test_a_capture_publishes_a_new_child_but_not_a_node_below_the_threshold() -> None:
    # A new child: p = 0.7311, 1 batch: batches alone would not publish, the capture does.
    child = object_sighting(None, "trk-000005", [proposal()], ["trk-000009"], PARAMS)
    assert sighting_decision(None, child, PARAMS).publish is None
    published = sighting_decision(None, child, PARAMS, verified_capture=True).publish
    assert published is not None and published.reason == "inspection"
    assert published.p_exist == pytest.approx(P_ONE_SIGHTING, abs=1e-15)
    # A demoted child seen again: l = -1.3 + 1.0 = -0.3, p = 0.4256 < 0.72: still demoted.
    demoted = track("demoted", -1.3, misses=4)
    sighting = object_sighting(demoted, "trk-000001", [proposal()], ["trk-000009"], PARAMS)
    assert sighting.existence.p_exist == pytest.approx(0.425557483188341, abs=1e-12)
    assert sighting_decision(demoted, sighting, PARAMS, verified_capture=True).publish is None


def test_a_verdict_publishes_through_the_same_rule_or_removes() -> None:
    # A pending fixture hypothesis, l = 0.0, 3 batches: confirm -> 0 + 1.8 = 1.8, clamped 1.5,
    # p = 0.8176 >= 0.72 with 3 batches: published for the verification.
    pending = replace(track("tentative", 0.0, kind="fixture", batches=3), verification="pending")
    update = verdict_update(pending, True, "table", "vlm", "f3", PARAMS)
    decision = verdict_decision(pending, update, PARAMS)
    assert update.existence.logodds == 1.5
    assert decision.publish is not None and decision.publish.reason == "verification"
    # Two batches only: the verdict's eta_c does not stand in for the third batch.
    early = replace(pending, batches_observed=2)
    decision = verdict_decision(
        early, verdict_update(early, True, "table", "vlm", "f3", PARAMS), PARAMS
    )
    assert decision.publish is None
    # Rejected: 0 - 2.2 = -2.2 (p 0.0998), removed for the rejection.
    update = verdict_update(pending, False, "table", "vlm", "f3", PARAMS)
    decision = verdict_decision(pending, update, PARAMS)
    assert update.existence.logodds == pytest.approx(-2.2, abs=1e-12)
    assert decision.remove is not None and decision.remove.reason == "verification_rejected"
    assert decision.remove.p_exist == pytest.approx(0.09975048911968513, abs=1e-12)
