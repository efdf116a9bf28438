"""Render checks against analytic geometry: z-depth, pixel convention, instances, occlusion."""

from __future__ import annotations

from typing import Any

import numpy as np

from sim.camera import CameraModel, look_at
from sim.render import add_kinect_noise, render
from sim.world import Box, World

CAMERA = CameraModel()
EYE = (1.0, 4.0, 1.5)
# Looking along +x: image right is world -y, image down is world -z.
POSE = look_at(EYE, (2.0, 4.0, 1.5))
TARGET = Box("target", "crate", center=(4.0, 4.0, 1.5), size=(0.4, 0.6, 0.5))
ROOM = (6.0, 8.0, 3.0)
FRONT_FACE_DEPTH = TARGET.center[0] - TARGET.size[0] / 2 - EYE[0]  # 2.8 m


def lone_box_world(**changes: tuple[Box, ...]) -> World:
    """A room holding only the target box (as an object unless overridden)."""
    fields: dict[str, Any] = {"room_size": ROOM, "fixtures": (), "objects": (TARGET,), **changes}
    return World(**fields)


def projected_columns_and_rows() -> tuple[range, range]:
    """Integer pixel centres (OpenCV convention) that fall inside the box's front face."""
    half_y, half_z = TARGET.size[1] / 2, TARGET.size[2] / 2
    u_low = CAMERA.cx + CAMERA.fx * (-half_y) / FRONT_FACE_DEPTH
    u_high = CAMERA.cx + CAMERA.fx * half_y / FRONT_FACE_DEPTH
    v_low = CAMERA.cy + CAMERA.fy * (-half_z) / FRONT_FACE_DEPTH
    v_high = CAMERA.cy + CAMERA.fy * half_z / FRONT_FACE_DEPTH
    return (
        range(int(np.ceil(u_low)), int(np.floor(u_high)) + 1),
        range(int(np.ceil(v_low)), int(np.floor(v_high)) + 1),
    )


def test_centre_pixel_depth_is_front_face_distance() -> None:
    view = render(lone_box_world(), CAMERA, POSE)
    assert view.depth.dtype == np.float32 and view.depth.shape == (CAMERA.height, CAMERA.width)
    assert abs(view.depth[240, 320] - FRONT_FACE_DEPTH) < 1e-3


def test_off_centre_pixel_on_same_face_has_same_z_depth() -> None:
    view = render(lone_box_world(), CAMERA, POSE)
    row, col = 200, 370
    ray_length = FRONT_FACE_DEPTH * np.linalg.norm(
        [(col - CAMERA.cx) / CAMERA.fx, (row - CAMERA.cy) / CAMERA.fy, 1.0]
    )
    assert view.instance[row, col] == 0
    assert abs(view.depth[row, col] - FRONT_FACE_DEPTH) < 1e-3
    assert ray_length - FRONT_FACE_DEPTH > 0.01  # the check above could tell the two apart


def test_pixel_missing_the_box_sees_far_wall() -> None:
    view = render(lone_box_world(), CAMERA, POSE)
    assert view.instance[240, 100] == -1
    assert abs(view.depth[240, 100] - (ROOM[0] - EYE[0])) < 1e-3


def test_instance_map_is_exactly_the_projected_rectangle() -> None:
    view = render(lone_box_world(), CAMERA, POSE)
    columns, rows = projected_columns_and_rows()
    expected = np.zeros((CAMERA.height, CAMERA.width), dtype=bool)
    expected[rows.start : rows.stop, columns.start : columns.stop] = True
    # The face edges sit at least 0.25 px from any pixel centre, so this is exact only if the
    # renderer samples pixel centres the OpenCV way (u, v integers), not at u + 0.5.
    assert view.instance.dtype == np.int32
    assert np.array_equal(view.instance == 0, expected)
    assert set(np.unique(view.instance)) == {-1, 0}


def test_fixture_gets_its_own_map_and_no_object_instance() -> None:
    fixture = Box("shelf", "shelf", TARGET.center, TARGET.size, kind="fixture")
    view = render(lone_box_world(fixtures=(fixture,), objects=()), CAMERA, POSE)
    columns, rows = projected_columns_and_rows()
    assert (view.instance == -1).all()
    assert (view.fixture_instance == 0).sum() == len(columns) * len(rows)


def test_occluder_in_front_hides_the_object() -> None:
    screen = Box("screen", "screen", (2.5, 4.0, 1.5), (0.05, 0.3, 0.3), kind="occluder")
    plain = render(lone_box_world(), CAMERA, POSE)
    occluded = render(lone_box_world().with_occluder(screen), CAMERA, POSE)
    assert occluded.instance[240, 320] == -1
    assert abs(occluded.depth[240, 320] - (2.5 - 0.025 - EYE[0])) < 1e-3
    visible_before, visible_after = (plain.instance == 0).sum(), (occluded.instance == 0).sum()
    assert 0 < visible_after < visible_before


def test_depth_outside_sensor_range_is_zero() -> None:
    near_camera = CameraModel(min_depth=3.0)
    view = render(lone_box_world(), near_camera, POSE)
    assert view.depth[240, 320] == 0.0  # the box at 2.8 m is too close for this sensor
    assert view.instance[240, 320] == 0  # the detector still sees it in colour
    assert abs(view.depth[240, 100] - 5.0) < 1e-3


def test_yawed_box_shows_its_long_side() -> None:
    turned = Box("target", "crate", TARGET.center, size=(0.6, 0.4, 0.5), yaw=np.pi / 2)
    view = render(lone_box_world(objects=(turned,)), CAMERA, POSE)
    assert abs(view.depth[240, 320] - FRONT_FACE_DEPTH) < 1e-3
    assert (view.instance == 0).sum() == (
        render(lone_box_world(), CAMERA, POSE).instance == 0
    ).sum()


def test_kinect_noise_grows_with_square_of_depth_and_keeps_holes() -> None:
    depth = np.full((200, 200), 2.0, dtype=np.float32)
    depth[:, :20] = 0.0
    noisy = add_kinect_noise(depth, np.random.default_rng(3))
    assert noisy.dtype == np.float32
    assert (noisy[:, :20] == 0).all()
    observed_sigma = float(np.std(noisy[:, 20:] - 2.0))
    assert abs(observed_sigma - 0.0012 * 4.0) < 0.0003
    assert np.array_equal(depth[:, 20:], np.full((200, 180), 2.0, dtype=np.float32))
