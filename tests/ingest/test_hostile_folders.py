"""`pbdag ingest folder` on hostile recordings: bad poses, intrinsics and PNGs, decompression
bombs, links out of the folder. Each is one line naming the frame, the file and the fix, status
2, and nothing reaches the service: no scene is created, no batch is posted."""

from __future__ import annotations

import os
import resource
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageFile

from api_schema import requests
from ingest.checks import MAX_IMAGE_PIXELS, MAX_IMAGE_SIDE, BadFile, open_png
from ingest.detectors import InstancePngsDetector
from ingest.folder import FolderSource
from ingest.frames import IngestError
from service.cli import main
from tests.ingest.cli_runs import error_line, ingest_folder
from tests.ingest.conftest import Recordings
from tests.ingest.recordings import write_png_header, write_zero_png
from tests.ingest.service_checks import batch_exists, events, scene_id, scene_names

SCALED = "2 0 0 0\n0 2 0 0\n0 0 2 0\n0 0 0 1\n"
K = "585 0 320\n0 585 240\n0 0 1\n"


@pytest.fixture
def folder(recordings: Recordings, tmp_path: Path) -> Path:
    """A copy of the test folder (named `kitchen`, its batches `kitchen-NNNNNN`) to spoil."""
    return Path(shutil.copytree(recordings.folder, tmp_path / "kitchen"))


def refused(
    recordings: Recordings,
    url: str,
    folder: Path,
    capsys: pytest.CaptureFixture[str],
    scene: str,
    *extra: str,
) -> str:
    """Ingest `folder` into a new scene `scene`, 4 frames a batch: the one error line, after
    checking the run ended with status 2, printed no summary and left no scene behind."""
    arguments = ("--frames-per-batch", "4", "--no-progress", *extra)
    code = ingest_folder(recordings, url, scene, *arguments, folder=folder)
    captured = capsys.readouterr()
    assert code == 2
    assert captured.out == ""  # no summary: nothing was sent
    assert "SECRET" not in captured.err  # no file's content is quoted
    assert scene not in scene_names(url)
    return error_line(captured.err)


@pytest.mark.parametrize(
    ("number", "text", "problem"),
    [
        (9, SCALED, "the pose's rotation is not orthonormal (max |R^T R - I| = 3, tolerance"),
        (2, "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n", "the pose's last row is not 0 0 0 1"),
        (9, "1 0 0 0\n0 1 0 0\n0 0 -1 0\n0 0 0 1\n", "the pose's rotation is a reflection"),
        (5, "1 0 0 0\n0 1 0 0\n0 0 1 0\n", "expected 4 lines of 4 numbers, found 3 lines"),
        (
            9,
            "1 0 0 0\n0 1 SECRET-TOKEN 0\n0 0 1 0\n0 0 0 1\n",
            "line 2 holds something that is not a number",
        ),
        (9, b"\xff\xfeSECRET\x00", "is not text"),
    ],
)
def test_a_bad_pose_anywhere_is_refused_before_the_scene_is_created(
    recordings: Recordings,
    service_url: str,
    folder: Path,
    capsys: pytest.CaptureFixture[str],
    number: int,
    text: str | bytes,
    problem: str,
) -> None:
    pose_file = folder / f"frame-{number:06d}.pose.txt"
    if isinstance(text, bytes):
        pose_file.write_bytes(text)
    else:
        pose_file.write_text(text)
    line = refused(recordings, service_url, folder, capsys, "hostile-pose")
    assert f"error: frame {number}: {pose_file}: {problem}" in line
    assert "; fix: write the frame's 4x4 camera-to-world transform there" in line


def test_a_bad_frame_leaves_an_existing_scene_as_it_was(
    recordings: Recordings, service_url: str, folder: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    first = ("--limit", "2", "--batch-prefix", "first", "--no-progress", "--wait")
    assert ingest_folder(recordings, service_url, "hostile-existing", *first) == 0
    scene = scene_id(service_url, "hostile-existing")
    before = events(service_url, scene)
    (folder / "frame-000002.pose.txt").write_text(SCALED)
    arguments = ("--frames-per-batch", "1", "--no-progress")
    assert (
        ingest_folder(recordings, service_url, "hostile-existing", *arguments, folder=folder) == 2
    )
    assert "error: frame 2: " in error_line(capsys.readouterr().err)
    # One frame a batch: frames 0 and 1 would have been posted before frame 2 was read.
    assert not batch_exists(service_url, scene, "kitchen-000000")
    assert events(service_url, scene) == before


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("nan 0 320\n0 585 240\n0 0 1", "fx is outside the service's bounds: input should be a "),
        (
            "0 0 320\n0 585 240\n0 0 1",
            "fx is outside the service's bounds: input should be greater",
        ),
        ("-585 0 320\n0 585 240\n0 0 1", "fx is outside the service's bounds"),
        ("585 0 320\n0 inf 240\n0 0 1", "fy is outside the service's bounds"),
        (
            "585 0 700\n0 585 240\n0 0 1",
            "the principal point's cx lies outside the image (0 to 640",
        ),
        ("585 0 320\n0 585 -1\n0 0 1", "the principal point's cy lies outside the image (0 to 480"),
        ("585 0 320\n0 585 240", "expected 3 lines of 3 numbers, found 2 lines"),
        ("585 0 SECRET\n0 585 240\n0 0 1", "line 1 holds something that is not a number"),
    ],
)
def test_bad_intrinsics_are_refused_before_the_scene_is_created(
    recordings: Recordings,
    service_url: str,
    folder: Path,
    capsys: pytest.CaptureFixture[str],
    text: str,
    problem: str,
) -> None:
    path = folder / "camera-intrinsics.txt"
    path.write_text(text)
    line = refused(recordings, service_url, folder, capsys, "hostile-intrinsics")
    assert f"error: frame 0: {path}: {problem}" in line
    assert "; fix: write the depth camera's 3x3 K matrix there" in line


def truncated(path: Path) -> None:
    """Keep the first half of the file (a copy cut short)."""
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


@pytest.mark.parametrize(
    ("spoil", "problem"),
    [
        (truncated, "is truncated or corrupt (OSError)"),
        (
            lambda path: path.write_bytes(b"SECRET-TOKEN, no image"),
            "is not a PNG image (UnidentifiedImageError)",
        ),
        (
            lambda path: write_zero_png(path, 640, 480, bit_depth=8),
            "is not a 16-bit single-channel PNG (Pillow mode L)",
        ),
        (
            lambda path: write_png_header(path, 9000, 9000),
            f"the image is 9000 x 9000 pixels, over the limit of 8192 x 8192 ({8192**2} pixels)",
        ),
        (  # beyond Pillow's own threshold, which refuses it while opening
            lambda path: write_png_header(path, 30000, 30000),
            f"the image has more than {Image.MAX_IMAGE_PIXELS} pixels, over the limit",
        ),
    ],
)
def test_a_bad_depth_png_at_frame_9_is_refused_before_the_scene_is_created(
    recordings: Recordings,
    service_url: str,
    folder: Path,
    capsys: pytest.CaptureFixture[str],
    spoil: Callable[[Path], object],
    problem: str,
) -> None:
    path = folder / "frame-000009.depth.png"
    spoil(path)
    line = refused(recordings, service_url, folder, capsys, "hostile-png")
    assert f"error: frame 9: {path}: {problem}" in line
    assert "; fix: " in line


def test_a_decompression_bomb_is_refused_from_its_header_without_decoding(
    recordings: Recordings,
    service_url: str,
    folder: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    bomb = write_zero_png(folder / "frame-000009.depth.png", 13000, 13000)  # 338 MB of pixels
    assert bomb.stat().st_size < 400_000
    decoded: list[str] = []
    load = ImageFile.ImageFile.load

    def spy(image: ImageFile.ImageFile) -> object:
        decoded.append(str(image.filename))
        return load(image)

    monkeypatch.setattr(ImageFile.ImageFile, "load", spy)
    peak_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # KiB on Linux
    line = refused(recordings, service_url, folder, capsys, "hostile-bomb")
    peak_growth = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak_before
    assert f"error: frame 9: {bomb}: the image has more than" in line
    assert f"fix: downscale the recording to at most {MAX_IMAGE_SIDE} pixels a side" in line
    assert str(bomb) not in decoded
    assert peak_growth < 150 * 1024  # decoding it takes 338 MB at least
    # The spy sees decoding: reading a frame decodes its PNG.
    next(iter(FolderSource(folder).frames()))
    assert decoded == [str(folder / "frame-000000.depth.png")]


def test_the_size_limit_is_the_wires_and_read_from_the_header(tmp_path: Path) -> None:
    assert MAX_IMAGE_SIDE == requests.MAX_IMAGE_SIDE
    assert Image.MAX_IMAGE_PIXELS is not None
    assert MAX_IMAGE_PIXELS == MAX_IMAGE_SIDE**2 < Image.MAX_IMAGE_PIXELS  # Pillow never warns
    edge = write_png_header(tmp_path / "edge.png", MAX_IMAGE_SIDE, MAX_IMAGE_SIDE)
    with open_png(edge) as image:
        assert image.size == (MAX_IMAGE_SIDE, MAX_IMAGE_SIDE)
    for width, height in ((MAX_IMAGE_SIDE + 1, 1), (1, MAX_IMAGE_SIDE + 1)):
        wide = write_png_header(tmp_path / "over.png", width, height)
        with pytest.raises(BadFile, match="over the limit of 8192 x 8192"), open_png(wide):
            pass


@pytest.mark.parametrize(
    ("name", "frame"),
    [
        ("frame-000003.pose.txt", 3),
        ("frame-000003.depth.png", 3),
        ("frame-000003.color.jpg", 3),
        ("camera-intrinsics.txt", 0),
    ],
)
def test_a_link_out_of_the_folder_is_refused_without_reading_it(
    recordings: Recordings,
    service_url: str,
    folder: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    name: str,
    frame: int,
) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    secret = outside / "secret.txt"
    secret.write_text("SECRET-TOKEN 1 2 3\n")
    path = folder / name
    path.unlink(missing_ok=True)
    path.symlink_to(secret)
    line = refused(recordings, service_url, folder, capsys, "hostile-link")
    assert f"error: frame {frame}: {path}: resolves outside the folder" in line
    assert "; fix: copy the file into the folder instead of linking to it" in line
    assert str(secret) not in line


def test_links_inside_the_folder_are_followed_and_loops_refused(folder: Path) -> None:
    poses = folder / "poses"
    poses.mkdir()
    (folder / "frame-000001.pose.txt").rename(poses / "frame-000001.pose.txt")
    (folder / "frame-000001.pose.txt").symlink_to(Path("poses") / "frame-000001.pose.txt")
    source = FolderSource(folder, limit=3)
    source.check()
    frames = list(source.frames())
    assert [frame.index for frame in frames] == [0, 1, 2]
    np.testing.assert_array_equal(frames[1].pose, np.loadtxt(poses / "frame-000001.pose.txt"))
    loop = folder / "frame-000002.pose.txt"
    loop.unlink()
    os.symlink(loop.name, loop)
    with pytest.raises(IngestError, match=r"^frame 2: .*frame-000002.pose.txt: is a symbolic link"):
        FolderSource(folder, limit=3).check()


def test_corrupt_data_behind_valid_checksums_is_one_error_naming_the_file(folder: Path) -> None:
    """Only decoding finds it (the check reads headers and checksums), still as one line."""
    path = write_png_header(folder / "frame-000001.depth.png", 640, 480, bytes(range(256)) * 4)
    source = FolderSource(folder, limit=2)
    source.check()
    with pytest.raises(IngestError) as raised:
        list(source.frames())
    assert str(raised.value).startswith(f"frame 1: {path}: is truncated or corrupt (")
    assert source.counts.read == 1


def test_a_pose_that_is_not_finite_is_a_skipped_frame(
    recordings: Recordings, service_url: str, folder: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (folder / "frame-000003.pose.txt").write_text("-inf -inf -inf -inf\n" * 4)  # tracking lost
    arguments = ("--limit", "5", "--no-progress")
    assert ingest_folder(recordings, service_url, "hostile-lost", *arguments, folder=folder) == 0
    out = capsys.readouterr().out
    assert (
        "frames read: 5, sent: 4" in out and "skipped 1: pose is not finite (tracking lost)" in out
    )


def test_instance_pngs_are_read_as_carefully_as_depth(
    recordings: Recordings, tmp_path: Path
) -> None:
    masks = Path(shutil.copytree(recordings.folder / "masks", tmp_path / "masks"))
    detector = InstancePngsDetector({"masks": str(masks), "labels": str(recordings.labels)})
    source = FolderSource(recordings.folder, limit=1)
    frame = next(iter(source.frames()))
    path = masks / "frame-000000.png"
    assert len(detector.detect(frame, source)) == 4
    write_png_header(path, 9000, 9000)
    with pytest.raises(IngestError, match=r"^frame 0: .*: the image is 9000 x 9000 pixels, over"):
        detector.detect(frame, source)
    write_png_header(path, 640, 480, b"not zlib")
    with pytest.raises(IngestError, match=r"^frame 0: .*: is truncated or corrupt \(OSError\)"):
        detector.detect(frame, source)
    path.unlink()
    path.symlink_to(recordings.folder / "masks" / "frame-000000.png")
    with pytest.raises(IngestError, match=r"^frame 0: .*: resolves outside the folder"):
        detector.detect(frame, source)


def test_an_error_is_one_line_whatever_it_names(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "two\nlines"
    assert main(["ingest", "folder", str(folder), "--scene", "x", "--no-progress"]) == 2
    assert "two\\nlines does not exist" in error_line(capsys.readouterr().err)
