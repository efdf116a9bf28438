"""Scenario files load, reject bad fields by name, replay deterministically and script events."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sim import DEMO_SCENARIO
from sim.camera import CameraModel
from sim.coverage import coverage
from sim.recorded import composite, load_recorded
from sim.render import render
from sim.scenario import REPO_ROOT, ScenarioError, load_scenario
from sim.stream import SimRun, simulate
from sim.trajectory import trajectory_poses
from sim.world import Box, World

SCENARIOS = REPO_ROOT / "sim" / "scenarios"
HOTEL = SCENARIOS / "hotel-suite.yaml"
KITCHEN = SCENARIOS / "kitchen-real.yaml"
SHORT_FRAMES = 20


@pytest.fixture(scope="module")
def short_hotel_run() -> SimRun:
    """The hotel suite squeezed into 20 frames (events at frames 3, 6, 9 and 12)."""
    return simulate(load_scenario(HOTEL, frames=SHORT_FRAMES), seed=0)


@pytest.mark.parametrize(
    "name", ["hotel-suite", "bedroom", "office", "kitchen-real", "busy-living-room"]
)
def test_every_shipped_scenario_loads_with_the_four_event_types(
    name: str, request: pytest.FixtureRequest
) -> None:
    if name == "kitchen-real":
        request.getfixturevalue("real_kitchen")  # skips, with the reason, without the data
    scenario = load_scenario(SCENARIOS / f"{name}.yaml")
    assert scenario.name == name
    assert [event.type for event in scenario.events] == ["appear", "move", "disappear", "transfer"]
    assert scenario.frames == (334 if name == "kitchen-real" else 300)
    move = next(event for event in scenario.events if event.type == "move")
    assert move.at is not None
    before = scenario.object(move.object).at
    # A move must be a real move, not jitter a method could average away.
    assert math.dist(before, move.at) >= 0.4


def test_hotel_suite_matches_the_protocol() -> None:
    scenario = load_scenario(HOTEL)
    assert {spec.label for spec in scenario.fixtures} >= {"bed", "desk", "counter", "table"}
    assert len(scenario.objects) >= 8 and len(scenario.walls) == 1
    transfer = scenario.events[-1]
    assert transfer.on != scenario.object(transfer.object).on


def _load_with(tmp_path: Path, text: str) -> Any:
    """Load a scenario written from YAML text."""
    path = tmp_path / "scenario.yaml"
    path.write_text(text, encoding="utf-8")
    return load_scenario(path)


@pytest.mark.parametrize(
    ("overrides", "field"),
    [
        ({"detector": {"recall": 1.5}}, r"detector\.recall"),
        ({"detecter": {}}, r"detecter: unknown field"),
        ({"camera": {"fx": "525"}}, r"camera\.fx"),
        ({"frames": 0}, r"frames"),
        ({"trajectory": {"type": "spiral"}}, r"trajectory\.type"),
        ({"detector": {"depth_noise": "gaussian"}}, r"detector\.depth_noise"),
        (
            {"detector": {"fixtures": {"ambiguity": {"desk_9": {"desk": 0.5}}}}},
            r"ambiguity\.desk_9",
        ),
        ({"evaluation": {"event_latency_batches": 0}}, r"evaluation\.event_latency_batches"),
        (
            {"people": [{"id": "p", "keyframes": [{"frame": 5, "at": [1, 1]}]}]},
            r"people\[0\]\.keyframes",
        ),
        (
            {
                "people": [
                    {
                        "id": "p",
                        "keyframes": [{"frame": 5, "at": [1, 1]}, {"frame": 2, "at": [1, 2]}],
                    }
                ]
            },
            r"people\[0\]\.keyframes\[1\]\.frame",
        ),
        (
            {
                "people": [
                    {
                        "id": "mug_1",
                        "keyframes": [{"frame": 1, "at": [1, 1]}, {"frame": 2, "at": [1, 2]}],
                    }
                ]
            },
            r"people\[0\]\.id",
        ),
        (
            {
                "people": [
                    {
                        "id": "p",
                        "keyframes": [{"frame": 1, "at": [9, 1]}, {"frame": 2, "at": [1, 2]}],
                    }
                ]
            },
            r"people\[0\]\.keyframes\[0\]\.at",
        ),
    ],
)
def test_a_bad_field_gives_an_error_naming_it(overrides: dict[str, Any], field: str) -> None:
    with pytest.raises(ScenarioError, match=field):
        load_scenario(HOTEL, overrides)


def test_bad_list_entries_and_events_are_named_by_index(tmp_path: Path) -> None:
    base = HOTEL.read_text(encoding="utf-8")
    with pytest.raises(ScenarioError, match=r"objects\[0\]\.on: unknown fixture 'sofa_9'"):
        _load_with(tmp_path, base.replace("on: desk_1, at: [-0.45, 0.1]", "on: sofa_9, at: [0, 0]"))
    with pytest.raises(ScenarioError, match=r"objects\[0\]\.at: .*hangs over the edge"):
        _load_with(tmp_path, base.replace("at: [-0.45, 0.1]}", "at: [-0.69, 0.1]}"))
    # remote_1 vanishes at frame 2, so the file's own disappear at frame 135 (events[3]) is stale.
    early = "- {frame: 45, type: appear, object: book_1}\n  - {frame: 2, type: disappear, object: remote_1}"
    with pytest.raises(ScenarioError, match=r"events\[3\]\.type: 'remote_1' is not present"):
        _load_with(tmp_path, base.replace("- {frame: 45, type: appear, object: book_1}", early))
    with pytest.raises(ScenarioError, match=r"line \d+: duplicate key 'height'"):
        _load_with(tmp_path, base.replace("eye_height: 1.3", "height: 1.3"))


def test_a_waypoint_inside_a_fixture_is_rejected() -> None:
    points = [
        {"at": [1.2, 5.4], "look_at": [1.5, 1.2, 0.55]},  # desk_1's center
        {"at": [2.6, 4.0], "look_at": [1.2, 5.4, 0.75]},
    ]
    with pytest.raises(
        ScenarioError, match=r"trajectory\.points\[0\]\.at: .*inside fixture 'desk_1'"
    ):
        load_scenario(HOTEL, {"trajectory": {"points": points}})


def test_a_path_through_a_wall_is_rejected() -> None:
    points = [
        {"at": [3.0, 2.0], "look_at": [1.5, 1.2, 0.55]},
        {"at": [5.0, 2.0], "look_at": [5.8, 1.2, 0.72]},
    ]
    with pytest.raises(ScenarioError, match=r"segment from points\[0\] to points\[1\].*walls\[0\]"):
        load_scenario(HOTEL, {"trajectory": {"points": points}})


def test_a_waypoint_pause_holds_the_camera_for_its_share_of_each_lap() -> None:
    from sim.scenario_settings import TrajectorySpec, Waypoint

    target = (2.0, 3.0, 0.7)
    spec = TrajectorySpec(
        "waypoints",
        loops=2,
        points=(
            Waypoint((1.0, 1.0, None), target, pause=0.25),
            Waypoint((3.0, 1.0, None), target),
        ),
    )
    poses = trajectory_poses(spec, 80, 1.2)  # 40 frames per lap
    eyes = np.array([pose[:3, 3] for pose in poses])
    parked = np.all(np.isclose(eyes[:, :2], (1.0, 1.0)), axis=1)
    # A quarter of each 40-frame lap (frames 0-9, and frame 10 where walking starts) at the first
    # waypoint, then walking there and back.
    assert parked[:11].all() and parked[40:51].all() and parked.sum() == 22
    steps = np.linalg.norm(np.diff(eyes[10:41], axis=0), axis=1)
    assert steps.max() < 1.5 * steps.mean()  # constant speed while walking


def test_orbit_poses_circle_the_center_and_look_at_the_target() -> None:
    scenario = load_scenario(
        HOTEL,
        {
            "trajectory": {
                "type": "orbit",
                "center": [6.0, 3.0],
                "radius": 1.0,
                "look_at": [5.8, 1.2, 0.72],
                "points": None,
            }
        },
        frames=SHORT_FRAMES,
    )
    assert scenario.trajectory is not None
    poses = trajectory_poses(scenario.trajectory, 8, scenario.camera.eye_height)
    for pose in poses:
        assert math.dist(pose[:2, 3], (6.0, 3.0)) == pytest.approx(1.0)
        toward = np.array([5.8, 1.2, 0.72]) - pose[:3, 3]
        assert pose[:3, 2] @ toward / np.linalg.norm(toward) == pytest.approx(1.0)


def test_an_elliptic_orbit_bobs_and_looks_at_its_targets_in_blocks() -> None:
    scenario = load_scenario(DEMO_SCENARIO)
    assert scenario.trajectory is not None
    poses = trajectory_poses(scenario.trajectory, 20, scenario.camera.eye_height)
    eyes = np.array([pose[:3, 3] for pose in poses])
    # On the ellipse (x - 3.0)^2 / 2.2^2 + (y - 2.3)^2 / 1.5^2 = 1, starting due north.
    ellipse = ((eyes[:, 0] - 3.0) / 2.2) ** 2 + ((eyes[:, 1] - 2.3) / 1.5) ** 2
    assert ellipse == pytest.approx(np.ones(20))
    assert eyes[0, :2] == pytest.approx([3.0, 3.8])
    angles = np.pi / 2 + 2 * np.pi * np.arange(20) / 20
    assert eyes[:, 2] == pytest.approx(1.3 + 0.1 * np.sin(3 * angles))
    # Ten blocks of two frames each, alternating between the table top and the counter top.
    targets = [(3.0, 2.3, 0.75), (3.0, 4.6, 0.9)]
    for index, pose in enumerate(poses):
        toward = np.array(targets[index // 2 % 2]) - pose[:3, 3]
        assert pose[:3, 2] @ toward / np.linalg.norm(toward) == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("trajectory", "field"),
    [
        ({"radius": [2.2]}, r"trajectory\.radius: expected a list of 2"),
        ({"radius": [2.2, 0]}, r"trajectory\.radius\[1\]: must be > 0\.0, got 0"),
        ({"look_at": [[3.0, 2.3, 0.75], [3.0, 4.6]]}, r"trajectory\.look_at\[1\]"),
        ({"look_blocks": 0}, r"trajectory\.look_blocks"),
        ({"bob": {"cycles": None}}, r"trajectory\.bob\.cycles: required"),
        ({"bob": {"amplitude": 0.1, "cycles": 3, "phase": 0}}, r"trajectory\.bob\.phase: unknown"),
        ({"bob": {"amplitude": 1.5, "cycles": 3}}, r"camera height .* outside the room"),
    ],
)
def test_a_bad_orbit_field_gives_an_error_naming_it(trajectory: dict[str, Any], field: str) -> None:
    with pytest.raises(ScenarioError, match=field):
        load_scenario(DEMO_SCENARIO, {"trajectory": trajectory})


def test_orbit_only_fields_are_unknown_on_waypoints() -> None:
    with pytest.raises(ScenarioError, match=r"trajectory\.bob: unknown field"):
        load_scenario(HOTEL, {"trajectory": {"bob": {"amplitude": 0.1, "cycles": 3}}})


def test_shortening_keeps_the_event_order_and_relative_times() -> None:
    scenario = load_scenario(HOTEL, frames=SHORT_FRAMES)
    assert scenario.frames == SHORT_FRAMES
    assert [event.frame for event in scenario.events] == [3, 6, 9, 12]


def test_the_same_seed_replays_the_stream_and_another_seed_differs(
    short_hotel_run: SimRun,
) -> None:
    scenario = load_scenario(HOTEL, frames=SHORT_FRAMES)
    again, other = simulate(scenario, seed=0), simulate(scenario, seed=1)
    assert again.scenario_sha256 == short_hotel_run.scenario_sha256
    for first, second in zip(short_hotel_run.frames, again.frames, strict=True):
        assert np.array_equal(first.depth, second.depth)
        assert np.array_equal(first.pose, second.pose)
        assert [d.label for d in first.detections] == [d.label for d in second.detections]
        for left, right in zip(first.detections, second.detections, strict=True):
            assert np.array_equal(left.mask, right.mask)
    assert not np.array_equal(short_hotel_run.frames[0].depth, other.frames[0].depth)


def test_events_change_presence_and_positions_at_their_frames(short_hotel_run: SimRun) -> None:
    def truth(frame: int, object_id: str) -> Any:
        return next(
            o for o in short_hotel_run.frames[frame].truth.objects if o.object_id == object_id
        )

    events = {event.type: event for event in short_hotel_run.events}
    appear, move = events["appear"], events["move"]
    disappear, transfer = events["disappear"], events["transfer"]
    assert not truth(appear.frame - 1, appear.object_id).present
    assert truth(appear.frame, appear.object_id).present
    before = truth(move.frame - 1, move.object_id).center
    after = truth(move.frame, move.object_id).center
    assert math.dist(before, after) >= 0.4
    assert truth(move.frame, move.object_id).parent == move.parent == "desk_1"
    assert truth(disappear.frame - 1, disappear.object_id).present
    assert not truth(disappear.frame, disappear.object_id).present
    assert truth(disappear.frame, disappear.object_id).visible_pixels == 0
    assert truth(transfer.frame - 1, transfer.object_id).parent == "table_1"
    assert truth(transfer.frame, transfer.object_id).parent == transfer.parent == "counter_1"
    fixture_tops = {
        fixture.fixture_id: fixture.center[2] + fixture.size[2] / 2
        for fixture in short_hotel_run.fixtures
    }
    moved = truth(transfer.frame, transfer.object_id)
    assert moved.center[2] == pytest.approx(fixture_tops["counter_1"] + 0.11 / 2)


def test_compositing_keeps_the_nearer_surface_and_masks_only_winning_pixels() -> None:
    camera = CameraModel(width=40, height=30, fx=40.0, fy=40.0, cx=19.5, cy=14.5)
    pose = np.eye(4)  # at the origin looking along +z
    real_wall = np.full((30, 40), 2.0, dtype=np.float32)
    real_wall[0, :] = 0.0  # a row of missing real depth: a virtual box there must still show
    for box_depth, wins in ((1.5, True), (2.5, False)):
        box = Box("b", "table", (0.0, 0.0, box_depth), (0.6, 0.6, 0.2), kind="fixture")
        world = World((0.0, 0.0, 0.0), (box,), (), include_room=False)
        view = render(world, camera, pose)
        merged, won = composite(view, real_wall)
        center = (15, 20)
        assert bool(won[center]) is wins
        assert merged.depth[center] == pytest.approx(box_depth - 0.1 if wins else 2.0)
        assert bool(merged.fixture_instance[center] == 0) is wins
        assert np.array_equal(merged.fixture_instance >= 0, won & (view.fixture_instance >= 0))
        off_box = view.depth == 0
        assert np.array_equal(merged.depth[off_box], real_wall[off_box])


def test_recorded_poses_are_gravity_aligned_with_the_floor_at_zero(real_kitchen: Path) -> None:
    scenario = load_scenario(KITCHEN)
    assert scenario.background is not None
    recording = load_recorded(scenario.background.path, (0, 3, 1))  # reads three frames only
    rotation = recording.alignment[:3, :3]
    assert rotation @ recording.up == pytest.approx([0.0, 0.0, 1.0], abs=1e-9)
    assert rotation @ rotation.T == pytest.approx(np.eye(3), abs=1e-9)
    heights = recording.poses[:, 2, 3]
    assert np.all((heights > 1.0) & (heights < 1.8))  # a hand-held Kinect above the floor
    assert recording.poses[:, :2, 3].mean(axis=0) == pytest.approx([0.0, 0.0], abs=1e-9)
    # The camera looks down at the table: its optical axis points below the horizon.
    assert np.all(recording.poses[:, 2, 2] < -0.2)
    assert recording.camera.fx == 585.0 and recording.camera.cx == 320.0


def test_a_recorded_run_composites_virtual_objects_into_real_depth(real_kitchen: Path) -> None:
    scenario = load_scenario(KITCHEN, frames=3)
    run = simulate(scenario, seed=0)
    assert len(run.frames) == 3 and scenario.background is not None
    assert scenario.background.frames == (0, 9, 3)
    assert [event.frame for event in scenario.events] == [0, 1, 1, 2]
    first = run.frames[0]
    assert first.pose[2, 3] > 1.0 and first.camera.width == 640
    detected = {d.object_id for frame in run.frames for d in frame.detections if d.kind == "object"}
    assert {"mug_1", "bottle_1"} <= detected
    visible = [o for o in first.truth.objects if o.visible_pixels > 0]
    assert visible and all(o.present for o in visible)


def test_the_hotel_wall_hides_objects_and_the_vanished_place_is_seen_again() -> None:
    report = coverage(load_scenario(HOTEL, frames=30))
    # In view but behind the wall: a method without a visibility gate would remove them.
    assert report["occluded_frames"].get("lamp_1", 0) > 0
    vanished = next(event for event in report["events"] if event["type"] == "disappear")
    assert vanished["visible_before"] > 0 and vanished["visible_after"] == 0
    assert vanished["place_visible_after"] > 0
