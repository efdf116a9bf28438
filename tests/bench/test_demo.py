"""The demo scenario shows every object from several views and applies its script on time."""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import pytest

from bench.sim.camera import CameraModel
from bench.sim.demo import COUNTER, TABLE, demo_script, demo_trajectory, demo_world, world_at
from bench.sim.render import render

N_FRAMES = 120
MIN_PIXELS = 150


@pytest.fixture(scope="module")
def sightings() -> dict[str, list[int]]:
    """For each object id, the frames in which at least MIN_PIXELS of it are visible."""
    base, script = demo_world(), demo_script(N_FRAMES)
    seen: dict[str, list[int]] = defaultdict(list)
    for frame_index, pose in enumerate(demo_trajectory(N_FRAMES)):
        world = world_at(frame_index, base, script)
        view = render(world, CameraModel(), pose)
        counts = np.bincount(view.instance.ravel() + 1, minlength=len(world.objects) + 1)[1:]
        for box, count in zip(world.objects, counts, strict=True):
            if count >= MIN_PIXELS:
                seen[box.id].append(frame_index)
    return dict(seen)


def test_every_object_is_seen_in_at_least_three_frames(sightings: dict[str, list[int]]) -> None:
    for object_id in ("mug", "book", "bowl", "bottle"):
        assert len(sightings.get(object_id, [])) >= 3, object_id


def test_changed_objects_are_seen_after_each_change(sightings: dict[str, list[int]]) -> None:
    bowl_gone, mug_moved, book_carried = (change.frame_index for change in demo_script(N_FRAMES))
    assert len([f for f in sightings["bowl"] if f < bowl_gone]) >= 3
    assert not [f for f in sightings["bowl"] if f >= bowl_gone]
    assert len([f for f in sightings["mug"] if f >= mug_moved]) >= 3
    assert len([f for f in sightings["book"] if f >= book_carried]) >= 3


def test_script_changes_happen_at_the_stated_frames() -> None:
    base, script = demo_world(), demo_script(N_FRAMES)
    assert [change.frame_index for change in script] == [48, 72, 96]

    def at(frame_index: int) -> dict[str, tuple[float, float, float]]:
        return {box.id: box.center for box in world_at(frame_index, base, script).objects}

    assert "bowl" in at(47) and "bowl" not in at(48)
    assert at(71)["mug"] == at(48)["mug"]
    assert np.linalg.norm(np.subtract(at(72)["mug"], at(71)["mug"])) == pytest.approx(0.5)
    assert at(95)["book"][2] == pytest.approx(TABLE.top_z + 0.02)
    assert at(96)["book"][2] == pytest.approx(COUNTER.top_z + 0.02)
    assert abs(at(96)["book"][1] - COUNTER.center[1]) < COUNTER.size[1] / 2


def test_trajectory_stays_in_the_room_at_head_height() -> None:
    room = demo_world().room_size
    poses = demo_trajectory(N_FRAMES)
    assert len(poses) == N_FRAMES
    eyes = np.array([pose[:3, 3] for pose in poses])
    assert (eyes[:, 2] >= 1.2 - 1e-9).all() and (eyes[:, 2] <= 1.4 + 1e-9).all()
    assert (eyes[:, :2] > 0.3).all() and (eyes[:, :2] < np.array(room[:2]) - 0.3).all()
    for pose in poses:
        rotation = pose[:3, :3]
        assert np.allclose(rotation.T @ rotation, np.eye(3)) and np.linalg.det(rotation) > 0
    # The gaze alternates: some frames look at the table, others at the counter.
    forward_y = np.array([pose[1, 2] for pose in poses])
    assert (forward_y > 0.5).any() and (forward_y < -0.5).any()
