"""`pbdag ingest rosbag` on ROS 2 bags written from 20 real kitchen frames, into a real
`pbdag serve`; and the bag source's poses, sync and skips."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ingest.detectors import load_detector
from ingest.frames import IngestError
from ingest.rosbag import OdomPose, RosbagSource, TfPose
from ingest.transforms import invert
from service.cli import main
from tests.ingest.cli_runs import ingest_bag, ingest_folder
from tests.ingest.conftest import FRAMES, Recordings
from tests.ingest.recordings import BASE_TO_CAMERA, MAP_TO_ODOM, frame_stamp
from tests.ingest.service_checks import batch_status, events, nodes, scene_id

# The kitchen's pose files drift from orthonormal by about 1e-4; a bag's quaternions are
# orthonormal, so the poses read back agree to that drift (a wrong chain is off by decimetres).
POSE_ATOL = 2e-4


def bag_source(bag: Path, pose: TfPose | OdomPose, stride: int = 1) -> RosbagSource:
    """The bag's depth frames with their camera info."""
    return RosbagSource(
        bag,
        depth_topic="/camera/depth",
        camera_info_topic="/camera/camera_info",
        pose=pose,
        stride=stride,
    )


def pose_file(kitchen: Path, index: int) -> np.ndarray:
    return np.loadtxt(kitchen / f"frame-{index:06d}.pose.txt")


def test_tf_poses_compose_map_odom_base_camera_to_the_pose_files(
    recordings: Recordings, real_kitchen: Path
) -> None:
    source = bag_source(recordings.bag, TfPose("map"))
    frames = list(source.frames())
    assert [f.index for f in frames] == list(range(FRAMES)) and source.counts.skipped == {}
    for frame in frames:
        assert frame.stamp_ns == frame_stamp(frame.index)
        np.testing.assert_allclose(frame.pose, pose_file(real_kitchen, frame.index), atol=POSE_ATOL)
        with Image16(real_kitchen, frame.index) as depth:
            np.testing.assert_array_equal(frame.depth, depth)
        assert (frame.intrinsics.fx, frame.intrinsics.cy, frame.intrinsics.width) == (585, 240, 640)
    # Naming the camera frame explicitly gives the same; the odom frame gives the pose in odom.
    named = next(iter(bag_source(recordings.bag, TfPose("map", "camera_optical")).frames()))
    np.testing.assert_allclose(named.pose, frames[0].pose, atol=1e-12)
    in_odom = next(iter(bag_source(recordings.bag, TfPose("odom")).frames()))
    np.testing.assert_allclose(in_odom.pose, invert(MAP_TO_ODOM) @ frames[0].pose, atol=1e-9)


class Image16:
    """The real depth PNG of a frame, as a context manager."""

    def __init__(self, kitchen: Path, index: int) -> None:
        from PIL import Image

        self.image = Image.open(kitchen / f"frame-{index:06d}.depth.png")

    def __enter__(self) -> np.ndarray:
        return np.asarray(self.image)

    def __exit__(self, *_: object) -> None:
        self.image.close()


def test_odometry_poses_with_the_extrinsic_from_tf_static_or_given(
    recordings: Recordings, real_kitchen: Path
) -> None:
    from_static = bag_source(recordings.bag, OdomPose("/odom"), stride=4)
    given = bag_source(recordings.bag, OdomPose("/odom", camera_in_base=BASE_TO_CAMERA), stride=4)
    wrong = bag_source(recordings.bag, OdomPose("/odom", np.eye(4)), stride=4)
    for a, b, c in zip(from_static.frames(), given.frames(), wrong.frames(), strict=True):
        expected = invert(MAP_TO_ODOM) @ pose_file(real_kitchen, a.index)  # odometry is in odom
        np.testing.assert_allclose(a.pose, expected, atol=POSE_ATOL)
        np.testing.assert_allclose(b.pose, a.pose, atol=1e-9)
        assert np.abs(c.pose[:3, 3] - a.pose[:3, 3]).max() > 0.05  # the test can tell
    assert from_static.counts.read == 5


def test_float_depth_is_read_as_metres(recordings: Recordings, real_kitchen: Path) -> None:
    frames = list(bag_source(recordings.float_bag, TfPose("map")).frames())
    assert len(frames) == 5
    with Image16(real_kitchen, 3) as depth:
        metres = frames[3].depth_metres()
        assert frames[3].depth.dtype == np.float32
        np.testing.assert_allclose(metres, depth / 1000.0, atol=1e-6)  # NaN read as 0


def test_mcap_bags_read_the_same_as_sqlite_ones(recordings: Recordings) -> None:
    detector = load_detector(
        "label-image", {"label-topic": "/camera/instances", "labels": str(recordings.labels)}
    )
    sqlite3 = bag_source(recordings.bag, TfPose("map"))
    mcap = bag_source(recordings.mcap_bag, TfPose("map"))
    pairs = list(zip(sqlite3.frames(detector.topics), mcap.frames(detector.topics), strict=False))
    assert len(pairs) == 5 and mcap.counts.read == 5
    for a, b in pairs:
        assert a.stamp_ns == b.stamp_ns
        np.testing.assert_array_equal(a.pose, b.pose)
        np.testing.assert_array_equal(a.depth, b.depth)
        found_a, found_b = detector.detect(a, sqlite3), detector.detect(b, mcap)
        assert [d.label for d in found_b] == ["mug", "bowl", "book", "table"]
        for x, y in zip(found_a, found_b, strict=True):
            np.testing.assert_array_equal(x.mask, y.mask)


def test_frames_without_a_pose_or_label_image_are_skipped_and_counted(
    recordings: Recordings, service_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code = ingest_bag(
        recordings.gappy_bag,
        service_url,
        "bag-gappy",
        "--tf",
        "--map-frame",
        "map",
        "--pose-tolerance",
        "0.01",  # frame 7's neighbours' transforms are 29 ms and 37 ms away
        "--detector",
        "label-image",
        "--label-topic",
        "/camera/instances",
        "--labels",
        str(recordings.labels),
        "--no-progress",
    )
    assert code == 0
    out = capsys.readouterr().out
    assert f"frames read: {FRAMES}, sent: {FRAMES - 2}" in out
    assert "skipped 1: no pose: no transform 'odom' -> 'base_link' within 0.01 s" in out
    assert "skipped 1: no /camera/instances message near the depth stamp" in out


def test_a_bag_becomes_the_same_scene_as_the_folder(
    recordings: Recordings, service_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code = ingest_bag(
        recordings.bag,
        service_url,
        "bag-kitchen",
        "--tf",
        "--map-frame",
        "map",
        "--detector",
        "label-image",
        "--label-topic",
        "/camera/instances",
        "--labels",
        str(recordings.labels),
        "--wait",
    )
    assert code == 0
    captured = capsys.readouterr()
    assert f"{FRAMES}/{FRAMES}" in captured.err  # the progress bar
    assert f"frames read: {FRAMES}, sent: {FRAMES} (with 80 detections), skipped: 0" in captured.out
    assert "batch statuses: 3 done" in captured.out
    scene = scene_id(service_url, "bag-kitchen")
    assert [
        batch_status(service_url, scene, f"kitchen_bag-{n:06d}")["status"] for n in range(3)
    ] == ["done"] * 3
    log = events(service_url, scene)
    assert {e["details"]["kind"] for e in log if e["type"] == "add"} == {"object", "fixture"}
    from_bag = nodes(service_url, scene)
    # The folder of the same frames, whose poses are the pose files: the map is the same map.
    assert ingest_folder(recordings, service_url, "folder-twin", "--no-progress", "--wait") == 0
    from_folder = nodes(service_url, scene_id(service_url, "folder-twin"))
    assert set(from_bag) == set(from_folder) == {"mug", "bowl", "book", "table"}
    for label, node in from_bag.items():
        assert node["kind"] == from_folder[label]["kind"]
        distance = np.linalg.norm(np.subtract(node["center"], from_folder[label]["center"]))
        assert distance < 0.01, (label, distance)


def test_odometry_poses_through_the_command(
    recordings: Recordings, service_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    extrinsic = ["0.1", "0", "0.3", "-0.5", "0.5", "-0.5", "0.5"]  # BASE_TO_CAMERA
    arguments = ["--odom-topic", "/odom", "--camera-in-base", *extrinsic, "--limit", "4"]
    assert ingest_bag(recordings.bag, service_url, "bag-odom", *arguments, "--no-progress") == 0
    assert "frames read: 4, sent: 4 (with 0 detections)" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (
            ("--depth-topic", "/nope", "--tf", "--map-frame", "map"),
            "depth topic '/nope' is not in bag",
        ),
        (
            ("--camera-info-topic", "/camera/depth", "--tf", "--map-frame", "map"),
            "camera info topic '/camera/depth' has type sensor_msgs/msg/Image, expected sensor_msgs/msg/CameraInfo",
        ),
        (
            ("--tf", "--map-frame", "world"),
            "frame 'world' is not in the bag's transforms; frames: base_link, camera_optical, map, odom",
        ),
        (("--tf",), "--tf needs --map-frame"),
        (("--odom-topic", "/odom", "--map-frame", "map"), "--map-frame goes with --tf"),
        (
            ("--odom-topic", "/odom", "--camera-in-base", "0", "0", "0", "0", "0", "0", "0"),
            "a zero quaternion is not a rotation",
        ),
        (("--odom-topic", "/wheel_odom"), "odometry topic '/wheel_odom' is not in bag"),
        (
            (
                "--tf",
                "--map-frame",
                "map",
                "--detector",
                "label-image",
                "--label-topic",
                "/masks",
                "--labels",
                "{labels}",
            ),
            "detector topic '/masks' is not in bag",
        ),
        (
            ("--tf", "--map-frame", "map", "--detector", "label-image", "--labels", "{labels}"),
            "'label-image' needs --label-topic",
        ),
        (("--tf", "--map-frame", "map", "--detector", "sam"), "unknown detector 'sam'"),
    ],
)
def test_bad_input_names_the_topic_frame_or_option(
    recordings: Recordings,
    capsys: pytest.CaptureFixture[str],
    arguments: tuple[str, ...],
    message: str,
) -> None:
    filled = [a.format(labels=recordings.labels) for a in arguments]
    base = ["ingest", "rosbag", str(recordings.bag), "--scene", "bad", "--no-progress"]
    defaults = ["--depth-topic", "/camera/depth", "--camera-info-topic", "/camera/camera_info"]
    code = main([*base, *defaults, *filled])  # a later flag wins over the default
    assert code == 2
    error = capsys.readouterr().err
    assert message in error
    if "is not in bag" in message:
        assert (
            "/camera/camera_info (sensor_msgs/msg/CameraInfo)" in error or "/camera/depth" in error
        )


def test_a_missing_bag_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(IngestError, match="does not exist"):
        bag_source(tmp_path / "nope", TfPose("map"))
