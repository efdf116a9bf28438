"""Section 3.4: u_i (equation (4)), Prox and target selection (equation (5)), views and J
(equation (6)), the lock, failed views and the retry cooldown, on hand-built maps."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Unpack

import numpy as np
import pytest

from core.errors import StateConflict
from core.events import InspectionRecorded, InspectionTargeted
from core.evolve import fold
from core.inspection import decide_inspection
from core.navigation import Navigation
from core.params import Params
from core.planner import (
    decide_plan,
    inspection_queue,
    plan,
    proximity,
    queue_status,
    unresolved_fixtures,
)
from core.state import SceneState, TrackChanges
from core.uncertainty import TERMS, fixture_uncertainty
from core.values import ViewPose
from core.views import best_view, feasible_views, view_cost
from tests.core.maps import GEOMETRY, grid_of, paint, room
from tests.core.planner_scenes import fixture, scene
from tests.core.scenes import frame as analytic_frame

PARAMS = Params()
ROBOT = ViewPose(x=1.02, y=1.02, yaw=0.0)  # inside the cell x, y in [1.00, 1.05)


# -- equation (4) ------------------------------------------------------------------------------


def test_fixture_uncertainty_equals_the_hand_computed_weighted_terms() -> None:
    track = fixture(
        "trk-000001",
        (3.0, 3.0, 0.375),
        (1.0, 1.0, 0.75),
        existence_logodds=0.0,  # below the clamp's top: equation (3) as it is, p = 0.5
        class_evidence={"table": 3.0, "desk": 1.0},  # p = (0.75, 0.25)
        batches_observed=3,
        margin_sum=0.24,  # mean margin 0.08
        recent_centers=((0.0, 0.0, 0.4), (0.3, 0.0, 0.4)),
        last_observed=100.0,
        pinned=False,
    )
    u = fixture_uncertainty(track, 400.0, PARAMS)
    # class: H = -(0.75 ln 0.75 + 0.25 ln 0.25) = 0.5623351446, over ln 7 = 1.9459101091
    # (seven taxonomy classes) = 0.2889830987; margin ambiguity 1 - 0.08 / 0.16 = 0.5;
    # 0.5 * 0.2889830987 + 0.5 * 0.5 = 0.3944915493.
    # position: var x = 0.045 (two centres 0.3 m apart), var y = 0: sqrt(0.045) / 0.30.
    # age: (400 - 100) / 600 = 0.5; confirmation: (12 - 3) / (12 - 3) = 1; parent: none = 0.
    # existence: 4 * 0.5 * 0.5 = 1 (the state's log-odds, not pinned by the clamp, is read).
    expected = {
        "existence": 1.0,
        "class": 0.3944915493,
        "parent": 0.0,
        "position": 0.7071067812,
        "age": 0.5,
        "confirmation": 1.0,
    }
    assert tuple(u.terms) == TERMS
    assert u.terms == pytest.approx(expected, abs=1e-9)
    # .20 * 1 + .30 * 0.3944915493 + .10 * 0 + .15 * 0.7071067812 + .10 * 0.5 + .15 * 1
    assert u.value == pytest.approx(0.6244134820, abs=1e-9)


def test_every_uncertainty_term_stays_in_0_1_and_a_settled_fixture_is_nearly_certain() -> None:
    settled = fixture("trk-000001", (3.0, 3.0, 0.375), (1.0, 1.0, 0.75))
    u = fixture_uncertainty(settled, 100.0, PARAMS)
    # Only existence is left: 12 batches, 4 p (1 - p) at p = logistic(12) is 2.4576547e-5.
    assert u.terms["existence"] == pytest.approx(2.4576547e-5, abs=1e-12)
    assert u.value == pytest.approx(0.2 * 2.4576547e-5, abs=1e-12)
    extreme = settled.evolved(
        existence_logodds=0.0,
        class_evidence={label: 1.0 for label in PARAMS.fixtures.taxonomy},
        parent_evidence={"a": 1.0, "b": 1.0},
        recent_centers=((0.0, 0.0, 0.0), (5.0, 5.0, 0.0)),
        batches_observed=0,
        margin_sum=0.0,
        last_observed=None,
        pinned=False,
    )
    worst = fixture_uncertainty(extreme, 1e6, PARAMS)
    assert all(0.0 <= value <= 1.0 for value in worst.terms.values())
    assert worst.value == pytest.approx(1.0)


def test_the_existence_term_reads_the_unclamped_evidence_not_the_clamped_log_odds() -> None:
    # Three fixtures at the clamp's top (1.5, p 0.82, 4 p (1 - p) = 0.5966 for all of them):
    # the term tells 3 supporting batches from 8, and a confirming verdict (eta_c) from none.
    at_clamp = fixture("f", (3.0, 3.0, 0.4), (1, 1, 0.8), existence_logodds=1.5, pinned=False)

    def existence(**changes: Unpack[TrackChanges]) -> float:
        return fixture_uncertainty(at_clamp.evolved(**changes), 100.0, PARAMS).terms["existence"]

    assert existence(batches_observed=3) == pytest.approx(0.1807066389, abs=1e-9)  # l = 3
    assert existence(batches_observed=8) == pytest.approx(0.0013409507, abs=1e-9)  # l = 8
    assert existence(batches_observed=3, verification="confirmed") == pytest.approx(
        0.0323837743, abs=1e-9
    )  # l = 3 + 1.8
    # Two visibility-admissible misses since the last positive batch: l = 3 - 2 * 0.7 = 1.6.
    assert existence(batches_observed=3, visible_misses=2) == pytest.approx(0.5590551677, abs=1e-9)
    # A fixture loaded from a baseline has no batches yet: its stored log-odds stands.
    assert existence(batches_observed=0, pinned=True) == pytest.approx(0.5965858083, abs=1e-9)
    # Below the clamp's top the state's log-odds is equation (3) exactly and is read as it is
    # (l = 1.0, p = 0.731, whatever the counters say); the paper's unclamped profile always is.
    assert existence(existence_logodds=1.0, batches_observed=3) == pytest.approx(
        4 * 0.7310585786 * (1 - 0.7310585786), abs=1e-9
    )


# -- equation (5) ------------------------------------------------------------------------------


def test_proximity_is_clipped_and_reaches_zero_at_8_m() -> None:
    def at(distance: float) -> float:
        return proximity(
            fixture("f", (distance, 0.0, 0.4), (1, 1, 0.8)), ViewPose(x=0, y=0, yaw=0), PARAMS
        )

    assert at(0.0) == 1.0
    assert at(2.0) == pytest.approx(0.75)  # 1 - 2 / 8
    assert at(6.0) == pytest.approx(0.25)
    assert at(8.0) == 0.0
    assert at(12.0) == 0.0


# A 7 m x 6 m room. Fixture A (uncertain) in the east, B (settled) near the robot in the west.
UNCERTAIN: TrackChanges = {
    "existence_logodds": 0.0,
    "class_evidence": {"table": 3.0, "desk": 1.0},
    "batches_observed": 3,
    "margin_sum": 0.24,
    "recent_centers": ((0.0, 0.0, 0.4), (0.3, 0.0, 0.4)),
    "pinned": False,
}
A = fixture("trk-00000a", (5.5, 4.0, 0.375), (1.0, 1.0, 0.75), **UNCERTAIN)
B = fixture("trk-00000b", (2.2, 2.2, 0.375), (0.8, 0.8, 0.75))


def two_fixture_room() -> list[str]:
    lines = room(7.0, 6.0)
    for track in (A, B):
        (x, y, _z), (dx, dy, _dz) = track.center, track.extent
        lines = paint(lines, x - dx / 2, y - dy / 2, x + dx / 2, y + dy / 2, "#")
    return lines


def test_target_is_the_argmax_of_equation_5_and_a_fixture_without_a_view_is_deferred() -> None:
    state = scene(grid_of(two_fixture_room()), A, B)
    # A: u = 0.6244134820 (the hand-computed fixture above); planar distance from the robot
    # sqrt(4.48^2 + 2.98^2) = 5.3806 m: Prox = 1 - 5.3806 / 8 = 0.3274; score 0.5650.
    # B: u = 0.2 * 2.4576547e-5 + 0.1 * 0.5 (unseen for 300 of 600 s) = 0.0500049; distance
    # 1.6688 m: Prox = 0.7914; score 0.1983.
    decided = plan(state, ROBOT)
    assert [c.fixture_id for c in decided.ranked] == [A.track_id, B.track_id]
    first, second = decided.ranked
    assert first.uncertainty.value == pytest.approx(0.6244134820, abs=1e-9)
    assert first.proximity == pytest.approx(1 - math.hypot(4.48, 2.98) / 8, abs=1e-12)
    assert first.score == pytest.approx(0.8 * 0.6244134820 + 0.2 * first.proximity, abs=1e-9)
    assert second.score == pytest.approx(
        0.8 * (0.2 * 2.4576547e-5 + 0.1 * 0.5) + 0.2 * (1 - math.hypot(1.18, 1.18) / 8), abs=1e-9
    )
    assert decided.decision == "inspect" and decided.lock == "new"
    assert decided.target is not None and decided.target.candidate.fixture_id == A.track_id
    # Walled in, A has no feasible view: it is deferred and B is the target.
    (x, y, _z) = A.center
    walled = paint(two_fixture_room(), x - 1.2, y - 1.2, x + 1.2, y + 1.2, "#")
    walled = paint(walled, x - 1.1, y - 1.1, x + 1.1, y + 1.1, ".")
    walled = paint(walled, x - 0.5, y - 0.5, x + 0.5, y + 0.5, "#")
    decided = plan(scene(grid_of(walled), A, B), ROBOT)
    assert decided.target is not None and decided.target.candidate.fixture_id == B.track_id
    assert [(d.fixture_id, d.reason) for d in decided.deferred] == [
        (A.track_id, "no_feasible_view")
    ]


# -- views and equation (6) --------------------------------------------------------------------


def test_view_cost_adds_the_five_terms_of_equation_6() -> None:
    # |1.2 - 0.9| + 0.08 * 5 - 0.20 * min(1.5, 1) + 4 * (1 - 0.75) + 0.3
    terms = view_cost(1.2, 5.0, 1.5, 0.75, 0.3, PARAMS.planner)
    assert {k: float(v) for k, v in terms.items()} == pytest.approx(
        {"standoff": 0.3, "travel": 0.4, "clearance": -0.2, "coverage": 1.0, "margin": 0.3}
    )
    assert sum(float(v) for v in terms.values()) == pytest.approx(1.8)
    # Clearance below the cap counts as it is: -0.20 * 0.4.
    assert float(view_cost(0.9, 0.0, 0.4, 1.0, 0.0, PARAMS.planner)["clearance"]) == pytest.approx(
        -0.08
    )


# A 6 m x 6 m room; a 1 m x 1 m table in the middle; a thin wall north of it (y 4.40-4.45,
# x 2-4) hiding it from the north; east of the table a free island (x 4.2-5.1, y 2.4-3.6)
# behind a moat of unknown cells: in sight of the table, out of the robot's reach.
TABLE = fixture("trk-000001", (3.0, 3.0, 0.375), (1.0, 1.0, 0.75))


def table_room() -> list[str]:
    lines = paint(room(6.0, 6.0), 2.5, 2.5, 3.5, 3.5, "#")
    lines = paint(lines, 2.0, 4.4, 4.0, 4.45, "#")
    lines = paint(lines, 4.1, 2.3, 5.2, 3.7, "?")
    return paint(lines, 4.2, 2.4, 5.1, 3.6, ".")


def navigation(lines: list[str], robot: ViewPose = ROBOT) -> Navigation:
    return Navigation(grid_of(lines), GEOMETRY, robot, PARAMS.planner)


def test_views_satisfy_standoff_reachability_line_of_sight_and_coverage() -> None:
    planner = replace(PARAMS.planner, max_candidate_views=100_000)
    nav = Navigation(grid_of(table_room()), GEOMETRY, ROBOT, planner)
    views = feasible_views(nav, TABLE, (), planner)
    assert len(views) > 50
    xs = np.array([v.pose.x for v in views])
    ys = np.array([v.pose.y for v in views])
    standoff = np.array([v.standoff_m for v in views])
    assert np.all((standoff >= 0.4) & (standoff <= 1.6))
    assert all(v.clearance_m >= 0.25 for v in views)  # the map inflated by the robot radius
    assert all(v.coverage >= 0.5 for v in views)
    # Nothing from the island, nothing behind the thin wall, some from the other sides.
    assert not np.any((xs > 4.1) & (ys > 2.3) & (ys < 3.7))
    assert not np.any((ys > 4.45) & (xs > 2.2) & (xs < 3.8))
    assert np.any(xs < 2.5) and np.any(ys < 2.5) and np.any((ys > 3.5) & (ys < 4.4))
    # Views are sorted by J, and J is the sum of its terms.
    assert [v.cost for v in views] == sorted(v.cost for v in views)
    for view in views:
        assert view.cost == pytest.approx(sum(view.cost_terms.values()))
    # Only reachability keeps views off the island: with the robot on it, they are there.
    island = ViewPose(x=4.62, y=3.02, yaw=0.0)
    inside = Navigation(grid_of(table_room()), GEOMETRY, island, planner)
    from_island = feasible_views(inside, TABLE, (), planner)
    assert from_island and all(v.pose.x > 4.1 for v in from_island)


def test_one_view_against_hand_computed_terms() -> None:
    nav = navigation(table_room())
    # West of the table at (1.65, 3.05), a travel cell's centre: d_foot = 2.5 - 1.65 = 0.85.
    [view] = feasible_views(nav, TABLE, (), PARAMS.planner, only=(1.65, 3.05))
    assert (view.pose.x, view.pose.y) == pytest.approx((1.65, 3.05))
    assert view.pose.yaw == pytest.approx(math.atan2(-0.05, 1.35))
    assert view.pitch == pytest.approx(math.atan2(0.75 - 1.3, math.hypot(1.35, 0.05)))
    # Travel: from the robot's travel cell (centre 1.05, 1.05), 6 cells east and 20 north on a
    # 10 cm grid: 6 diagonal steps and 14 straight ones.
    travel = 6 * math.sqrt(2) * 0.1 + 14 * 0.1
    # Clearance: the view's map cell (centre x 1.675) to the table's first cell (centre 2.525),
    # less half a cell.
    clearance = 2.525 - 1.675 - 0.025
    assert view.standoff_m == pytest.approx(0.85)
    assert view.travel_m == pytest.approx(travel)
    assert view.clearance_m == pytest.approx(clearance)
    # The whole top is in the image (its nearest corner at u = -0.82, inside the 0.95 margin).
    assert view.coverage == 1.0
    assert view.cost_terms == pytest.approx(
        {
            "standoff": 0.05,
            "travel": 0.08 * travel,
            "clearance": -0.20 * clearance,
            "coverage": 0.0,
            "margin": 0.0,
        }
    )
    assert view.cost == pytest.approx(0.05 + 0.08 * travel - 0.20 * clearance)


def test_failed_views_are_excluded_and_a_view_too_close_has_a_margin_penalty() -> None:
    nav = navigation(table_room())
    failed = ViewPose(x=1.65, y=3.05, yaw=0.0)
    assert feasible_views(nav, TABLE, (failed,), PARAMS.planner, only=(1.65, 3.05)) == []
    views = feasible_views(nav, TABLE, (failed,), PARAMS.planner)
    assert views and all(math.hypot(v.pose.x - 1.65, v.pose.y - 3.05) >= 0.3 for v in views)
    # At 0.45 m from the footprint the 1 m top spans more than the image: its near corners
    # project beyond the border (u = 1.27): the margin penalty is full.
    [close] = feasible_views(nav, TABLE, (), PARAMS.planner, only=(2.05, 3.05))
    [far] = feasible_views(nav, TABLE, (), PARAMS.planner, only=(1.65, 3.05))
    assert close.cost_terms["margin"] == 1.0 and far.cost_terms["margin"] == 0.0
    assert close.cost > far.cost


def test_coverage_counts_the_support_points_in_range() -> None:
    # With a 1.5 m camera range, from (1.65, 3.05) the two nearer columns of the 4 x 4 support
    # grid (x 2.625 and 2.875: at most 1.41 m away) are in range, the two farther ones (x 3.125
    # and 3.375: at least 1.57 m) are not: Cov = 8 / 16, just feasible, J's term 4 (1 - 0.5).
    short = replace(PARAMS.planner, max_view_range_m=1.5)
    nav = Navigation(grid_of(table_room()), GEOMETRY, ROBOT, short)
    [view] = feasible_views(nav, TABLE, (), short, only=(1.65, 3.05))
    assert view.coverage == 0.5 and view.cost_terms["coverage"] == 2.0
    stricter = replace(short, min_coverage=0.6)
    assert feasible_views(nav, TABLE, (), stricter, only=(1.65, 3.05)) == []


# -- the lock, failures and the cooldown -------------------------------------------------------


def failed_capture(state: SceneState, fixture_id: str, view: ViewPose | None) -> SceneState:
    record = InspectionRecorded(
        track_id=fixture_id,
        state="confirmed",
        capture_id="cap",
        fixture_id=fixture_id,
        frames=("x",),
        primary_frame=None,
        fixture_verified=None,
        outcome="support_not_visible",
        children=(),
        attempts=1,
        status=None,
        view=view,
    )
    return fold(state, [record])


def test_a_target_stays_locked_until_its_capture_then_cools_down() -> None:
    state = scene(grid_of(two_fixture_room()), A, B)
    decided, events = decide_plan(state, ROBOT)
    [event] = events
    assert decided.target is not None
    assert isinstance(event, InspectionTargeted) and event.track_id == A.track_id
    assert event.view == decided.target.view.pose and event.cost == decided.target.view.cost
    assert event.uncertainty_terms == decided.target.candidate.uncertainty.terms
    locked = fold(state, events)
    assert locked.plan.lock is not None and locked.plan.lock.seq == state.head_seq + 1
    assert queue_status(locked, A.track_id) == "in_progress"
    assert [t.track_id for t in inspection_queue(locked)] == [B.track_id]
    # From elsewhere, the lock holds: same fixture, same view, no new event.
    again, none = decide_plan(locked, ViewPose(x=3.0, y=1.0, yaw=1.0))
    assert none == [] and again.lock == "held" and again.target is not None
    assert again.target.view.pose == event.view
    # A capture that does not show the support fails; its view is the locked one.
    blind = analytic_frame("blind", np.zeros((120, 160), np.float32), t=500.0)
    *_children, record = decide_inspection(locked, "cap-1", A.track_id, [blind], None)
    assert isinstance(record, InspectionRecorded)
    assert record.outcome == "support_not_visible" and record.view == event.view
    failed = fold(locked, [record])
    assert failed.plan.lock is None
    assert failed.plan.failed_views == {A.track_id: (event.view,)}
    assert queue_status(failed, A.track_id) == "retry_cooldown"
    # Cooling down, A waits: B is the target.
    after, events = decide_plan(failed, ROBOT)
    assert after.target is not None and after.target.candidate.fixture_id == B.track_id
    cooled = fold(failed, events)
    assert queue_status(cooled, A.track_id) == "queued"  # one other lock later
    # B completed: its lock is void; A is the target again, never from near its failed view.
    b_done = B.evolved(inspection_status="completed")
    finished = replace(cooled, tracks={**cooled.tracks, B.track_id: b_done})
    retry, events = decide_plan(finished, ROBOT)
    assert retry.target is not None and retry.target.candidate.fixture_id == A.track_id
    assert retry.replaces == B.track_id and len(events) == 1
    view = retry.target.view.pose
    assert math.hypot(view.x - event.view.x, view.y - event.view.y) >= 0.3


def test_with_nothing_to_inspect_the_plan_explores_then_is_done() -> None:
    open_room = room(4.0, 3.0)
    open_room = [line[:-1] + ("?" if 20 <= i < 40 else "#") for i, line in enumerate(open_room)]
    decided = plan(scene(grid_of(open_room)), ROBOT)
    assert decided.decision == "explore" and decided.frontier is not None
    assert decided.frontier.goal is not None and decided.frontier.goal[0] > 3.4
    done = plan(scene(grid_of(room(4.0, 3.0))), ROBOT)
    assert done.decision == "done" and done.target is None and done.frontier is None
    empty = plan(SceneState(), ROBOT)
    assert empty.decision == "explore" and empty.frontier is None


def test_a_robot_outside_the_map_is_refused_naming_the_field() -> None:
    with pytest.raises(StateConflict) as error:
        plan(scene(grid_of(room(4.0, 3.0))), ViewPose(x=150.0, y=0.0, yaw=0.0))
    assert error.value.field == "robot_pose"


@pytest.mark.parametrize(
    ("robot", "failed"),
    [
        (ROBOT, ()),
        (ROBOT, (ViewPose(x=1.65, y=3.05, yaw=0.0),)),
        (ViewPose(x=5.0, y=1.0, yaw=0.0), ()),
        (ViewPose(x=1.0, y=5.5, yaw=0.0), (ViewPose(x=2.0, y=1.9, yaw=0.0),)),
    ],
)
def test_the_bounded_search_finds_the_cheapest_feasible_view(
    robot: ViewPose, failed: tuple[ViewPose, ...]
) -> None:
    nav = navigation(table_room(), robot)
    views = feasible_views(nav, TABLE, failed, PARAMS.planner)
    assert views
    assert best_view(nav, TABLE, failed, PARAMS.planner) == views[0]


def test_a_robot_far_from_the_known_map_is_told_to_look_around_without_planning() -> None:
    state = scene(grid_of(room(4.0, 3.0)))
    far = plan(state, ViewPose(x=90.0, y=-90.0, yaw=0.0))
    assert far.decision == "explore" and far.frontier is None and far.target is None
    assert "not in known free space" in far.reason
    inside = plan(state, ROBOT)
    assert inside.decision == "done"  # a closed, fully known room: nothing to do


def test_every_fixture_class_of_a_home_is_inspected_by_default_and_a_task_may_name_fewer() -> None:
    # A phone on a nightstand (a cabinet), glasses on a bed, a remote on a sofa.
    labels = ("table", "desk", "counter", "bed", "shelf", "cabinet", "sofa")
    tracks = {
        f"trk-{i:06d}": fixture(f"trk-{i:06d}", (i + 1.0, 1.0, 0.4), (1.0, 0.6, 0.8)).evolved(
            class_evidence={label: 12.0}
        )
        for i, label in enumerate(labels)
    }
    state = SceneState(tracks=tracks)
    assert [state.tracks[t.track_id].label for t in unresolved_fixtures(state)] == list(labels)
    kitchen = Params.from_dict({"fixtures": {"inspection_taxonomy": ["counter", "table"]}})
    assert [t.label for t in unresolved_fixtures(replace(state, params=kitchen))] == [
        "table",
        "counter",
    ]
