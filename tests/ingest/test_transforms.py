"""tf chains and time sync on hand-built transforms."""

from __future__ import annotations

import numpy as np
import pytest

from ingest.transforms import (
    DisconnectedFrames,
    TransformLookupError,
    TransformTree,
    invert,
    nearest,
    quaternion_matrix,
    quaternion_of,
    rigid,
)

MS = 1_000_000  # nanoseconds
MAP_TO_ODOM = rigid((1.0, 2.0, 0.0), (0.0, 0.0, np.sin(0.4), np.cos(0.4)))
BASE_TO_CAMERA = rigid((0.2, 0.0, 0.5), (-0.5, 0.5, -0.5, 0.5))
BASE_TO_LIDAR = rigid((0.0, 0.1, 0.8), (0.0, 0.0, 0.0, 1.0))


def odom_to_base(x: float) -> np.ndarray:
    """The robot at (x, 0), turned by x/10 rad."""
    return rigid((x, 0.0, 0.0), (0.0, 0.0, np.sin(x / 20), np.cos(x / 20)))


@pytest.fixture
def tree() -> TransformTree:
    """map -> odom (static), odom -> base_link at 0, 100 and 200 ms, base_link -> camera and
    -> lidar (static)."""
    built = TransformTree()
    built.add("map", "odom", 0, MAP_TO_ODOM, static=True)
    built.add("/base_link", "camera_optical", 0, BASE_TO_CAMERA, static=True)
    built.add("base_link", "lidar", 0, BASE_TO_LIDAR, static=True)
    for step in (2, 0, 1):  # out of order, as merged bags may be
        built.add("odom", "base_link", step * 100 * MS, odom_to_base(float(step)), static=False)
    return built


def test_the_chain_is_the_product_of_its_links_at_the_nearest_stamp(tree: TransformTree) -> None:
    at_90ms = tree.lookup("map", "camera_optical", 90 * MS, 50 * MS)
    np.testing.assert_allclose(
        at_90ms, MAP_TO_ODOM @ odom_to_base(1.0) @ BASE_TO_CAMERA, atol=1e-12
    )
    at_40ms = tree.lookup("map", "camera_optical", 40 * MS, 50 * MS)
    np.testing.assert_allclose(
        at_40ms, MAP_TO_ODOM @ odom_to_base(0.0) @ BASE_TO_CAMERA, atol=1e-12
    )
    # The product in the wrong order is a different pose: the test can tell.
    assert not np.allclose(at_90ms, BASE_TO_CAMERA @ odom_to_base(1.0) @ MAP_TO_ODOM, atol=1e-3)


def test_a_lookup_up_the_tree_is_the_inverse_and_siblings_go_through_their_parent(
    tree: TransformTree,
) -> None:
    down = tree.lookup("map", "camera_optical", 200 * MS, 0)
    up = tree.lookup("camera_optical", "map", 200 * MS, 0)
    np.testing.assert_allclose(up, invert(down), atol=1e-12)
    np.testing.assert_allclose(up @ down, np.eye(4), atol=1e-12)
    lidar_in_camera = tree.lookup("camera_optical", "lidar", 200 * MS, 0)
    np.testing.assert_allclose(lidar_in_camera, invert(BASE_TO_CAMERA) @ BASE_TO_LIDAR, atol=1e-12)
    np.testing.assert_allclose(tree.lookup("odom", "odom", 0, 0), np.eye(4))


def test_a_stamp_beyond_the_tolerance_names_the_missing_link(tree: TransformTree) -> None:
    with pytest.raises(
        TransformLookupError, match=r"no transform 'odom' -> 'base_link' within 0.05 s"
    ) as gap:
        tree.lookup("map", "camera_optical", 300 * MS, 50 * MS)
    assert gap.type is TransformLookupError  # a gap in time skips a frame, it is no naming error
    # Static links have no time: only the timed link matters.
    np.testing.assert_allclose(
        tree.lookup("base_link", "camera_optical", 10**12, 0), BASE_TO_CAMERA
    )


def test_unknown_disconnected_and_two_parent_frames_are_clear_errors(tree: TransformTree) -> None:
    with pytest.raises(
        DisconnectedFrames,
        match=r"'world' \(target\) is not in the transforms; frames seen: base_link, camera_optical, lidar, map, odom",
    ):
        tree.lookup("world", "camera_optical", 0, MS)
    tree.add("earth", "gps", 0, np.eye(4), static=True)
    with pytest.raises(
        DisconnectedFrames, match="not connected: their roots are 'map' and 'earth'"
    ):
        tree.lookup("map", "gps", 0, MS)
    with pytest.raises(TransformLookupError, match="two parents"):
        tree.add("map", "base_link", 0, np.eye(4), static=False)


def test_nearest_picks_the_closest_stamp_within_the_tolerance() -> None:
    stamps = [0, 100, 200, 350]
    assert nearest(stamps, 140, 60) == 1
    assert nearest(stamps, 160, 60) == 2
    assert nearest(stamps, 150, 60) == 1  # a tie goes to the earlier message
    assert nearest(stamps, 275, 74) is None  # 75 from both neighbours
    assert nearest(stamps, 275, 75) == 2
    assert nearest(stamps, -10, 10) == 0
    assert nearest(stamps, 400, 49) is None
    assert nearest([], 0, 10**9) is None


def test_quaternions_round_trip_through_matrices() -> None:
    rng = np.random.default_rng(7)
    for _ in range(200):
        quaternion = rng.normal(size=4)
        quaternion /= np.linalg.norm(quaternion)
        rotation = quaternion_matrix(*quaternion)
        np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)
        assert np.linalg.det(rotation) == pytest.approx(1.0)
        np.testing.assert_allclose(
            quaternion_matrix(*quaternion_of(rotation)), rotation, atol=1e-12
        )
    quarter_turn = quaternion_matrix(0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4))
    np.testing.assert_allclose(quarter_turn @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)
    with pytest.raises(ValueError, match="zero quaternion"):
        quaternion_matrix(0.0, 0.0, 0.0, 0.0)
