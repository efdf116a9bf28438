"""`pbdag ingest rosbag` on hostile bags: corrupt storage or metadata, broken poses and camera
infos, undecodable messages, links out of the bag's folder. Each is one line naming the bag (and
the frame, when one is at fault) and the fix, status 2, before any scene or batch exists."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from ingest.checks import MAX_IMAGE_SIDE
from ingest.frames import IngestError
from ingest.messages import image_array
from tests.ingest.cli_runs import error_line, ingest_bag
from tests.ingest.conftest import Recordings
from tests.ingest.recordings import frame_stamp, write_bag
from tests.ingest.service_checks import scene_names

FRAMES = 12  # frames 0-7 make two batches of 4 before frame 9


def refused_bag(bag: Path, url: str, capsys: pytest.CaptureFixture[str], scene: str) -> str:
    """Ingest `bag` (pose from /tf) into a new scene `scene`, 4 frames a batch: the one error
    line, after checking the run ended with status 2, printed no summary and left no scene."""
    arguments = ("--tf", "--map-frame", "map", "--frames-per-batch", "4", "--no-progress")
    code = ingest_bag(bag, url, scene, *arguments)
    captured = capsys.readouterr()
    assert code == 2
    assert captured.out == ""
    assert "SECRET" not in captured.err  # no file's content is quoted
    assert scene not in scene_names(url)
    return error_line(captured.err)


def storage_file(bag: Path) -> Path:
    """The bag's one storage file (.db3 or .mcap)."""
    (found,) = [path for path in bag.iterdir() if path.name != "metadata.yaml"]
    return found


def cut_short(bag: Path, outside: Path) -> None:
    """Keep the first half of the storage file (a copy interrupted)."""
    path = storage_file(bag)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def scribbled(bag: Path, outside: Path) -> None:
    """Overwrite 5000 bytes a fifth into the storage file (in a chunk that is checksummed)."""
    path = storage_file(bag)
    raw = path.read_bytes()
    middle = len(raw) // 5
    path.write_bytes(raw[:middle] + b"\xff" * 5000 + raw[middle + 5000 :])


def broken_metadata(bag: Path, outside: Path) -> None:
    """A metadata.yaml that is no YAML (its parser's message quotes the line)."""
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: [SECRET-TOKEN\n")


def linked_metadata(bag: Path, outside: Path) -> None:
    """metadata.yaml a link to a file outside the bag's folder."""
    secret = outside / "secret.yaml"
    secret.write_text("SECRET-TOKEN: 1\n")
    (bag / "metadata.yaml").unlink()
    (bag / "metadata.yaml").symlink_to(secret)


@pytest.mark.parametrize(
    ("source", "spoil", "problem"),
    [
        ("bag", cut_short, "it cannot be opened (AnyReaderError: Cannot open database"),
        ("mcap_bag", cut_short, "it cannot be opened (AnyReaderError: File end magic is invalid"),
        ("mcap_bag", scribbled, "topic /camera/camera_info cannot be read ("),
        ("bag", broken_metadata, "it cannot be opened (AnyReaderError: Could not load YAML from"),
        ("bag", linked_metadata, "metadata.yaml resolves outside the folder"),
    ],
)
def test_a_corrupt_bag_is_one_line_and_nothing_is_sent(
    recordings: Recordings,
    service_url: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    source: str,
    spoil: Callable[[Path, Path], None],
    problem: str,
) -> None:
    bag = Path(shutil.copytree(getattr(recordings, source), tmp_path / "bag"))
    outside = tmp_path / "outside"
    outside.mkdir()
    spoil(bag, outside)
    line = refused_bag(bag, service_url, capsys, f"hostile-{source}-{spoil.__name__}")
    assert f"error: bag {bag}: " in line and problem in line
    assert "; fix: " in line


def test_a_nan_pose_at_frame_9_is_refused_before_anything_is_sent(
    real_kitchen: Path, service_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = write_bag(real_kitchen, tmp_path / "nan_tf", FRAMES, bad_tf={9: "nan"})
    line = refused_bag(bag, service_url, capsys, "hostile-bag-pose")
    at = f"t = {frame_stamp(9) / 1e9:.3f} s"
    assert f"error: frame 9 ({at}): bag {bag}, the pose from /tf and /tf_static: " in line
    assert "the pose holds NaN or infinite values" in line
    assert f"; fix: correct the pose messages of /tf and /tf_static near {at}" in line


def test_a_zero_quaternion_is_refused_before_anything_is_sent(
    real_kitchen: Path, service_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = write_bag(real_kitchen, tmp_path / "zero_q", FRAMES, bad_tf={5: "zero-quaternion"})
    line = refused_bag(bag, service_url, capsys, "hostile-bag-quaternion")
    at = f"t = {(frame_stamp(5) + 4_000_000) / 1e9:.3f} s"  # /tf is 4 ms after the depth
    assert f"error: bag {bag}, topic /tf: transform 'odom' -> 'base_link' at {at}: " in line
    assert "a zero quaternion is not a rotation; fix: " in line


def test_bad_camera_info_is_refused_before_anything_is_sent(
    real_kitchen: Path, service_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = write_bag(real_kitchen, tmp_path / "fx0", 3, fx=0.0)
    line = refused_bag(bag, service_url, capsys, "hostile-bag-intrinsics")
    at = f"t = {frame_stamp(0) / 1e9:.3f} s"
    assert f"error: frame 0 ({at}): bag {bag}, topic /camera/camera_info at {at}: " in line
    assert "fx is outside the service's bounds: input should be greater than or equal to 1" in line
    assert "; fix: record the depth camera's calibration" in line


def test_an_undecodable_depth_message_at_frame_9_is_refused_before_anything_is_sent(
    real_kitchen: Path, service_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = write_bag(real_kitchen, tmp_path / "garbage", FRAMES, garbage_depth=frozenset({9}))
    line = refused_bag(bag, service_url, capsys, "hostile-bag-message")
    assert f"error: frame 9: bag {bag}: a message of topic /camera/depth cannot be" in line
    assert "; fix: " in line


def test_an_image_message_over_the_size_limit_is_refused_before_its_pixels_are_read() -> None:
    side = MAX_IMAGE_SIDE + 1
    message = SimpleNamespace(
        encoding="16UC1",
        is_bigendian=0,
        height=side,
        width=side,
        step=2 * side,
        data=np.zeros(0, np.uint8),
    )
    with pytest.raises(IngestError, match=f"^topic /d: the image is {side} x {side} pixels, over"):
        image_array(message, "/d")
    message.height = message.width = 4
    with pytest.raises(IngestError, match=r"^topic /d: image data of 0 bytes does not hold 4 rows"):
        image_array(message, "/d")
