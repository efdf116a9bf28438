"""`pbdag ingest folder` on 20 real kitchen frames with instance PNGs, into a real `pbdag serve`."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import numpy as np
import pytest

from ingest.detectors import Detection
from ingest.folder import FolderSource
from ingest.frames import FrameSource, SkipFrame, SourceFrame
from ingest.pipeline import ingest
from service.cli import main
from tests.ingest.cli_runs import ingest_folder
from tests.ingest.conftest import FRAMES, REPO, Recordings, running_service
from tests.ingest.service_checks import batch_status, events, nodes, scene_id


def test_a_folder_becomes_objects_and_a_fixture_in_the_scene(
    recordings: Recordings, service_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert ingest_folder(recordings, service_url, "folder-kitchen", "--wait") == 0
    captured = capsys.readouterr()
    assert f"{FRAMES}/{FRAMES}" in captured.err  # the progress bar
    assert f"frames read: {FRAMES}, sent: {FRAMES}" in captured.out
    assert "batches posted 3" in captured.out and "batch statuses: 3 done" in captured.out
    scene = scene_id(service_url, "folder-kitchen")
    statuses = [batch_status(service_url, scene, f"kitchen-{n:06d}") for n in range(3)]
    assert [s["status"] for s in statuses] == ["done"] * 3
    assert [s["frame_count"] for s in statuses] == [8, 8, 4]  # --frames-per-batch 8
    log = events(service_url, scene)
    appended = sum(s["last_seq"] - s["first_seq"] + 1 for s in statuses)
    assert f"events appended: {appended}" in captured.out and appended == len(log) - 1
    added = {(e["details"]["kind"], e["track_id"]) for e in log if e["type"] == "add"}
    assert {kind for kind, _ in added} == {"object", "fixture"}
    graph = nodes(service_url, scene)
    assert {"mug", "bowl", "book", "table"} <= set(graph)
    assert graph["table"]["kind"] == "fixture" and graph["mug"]["kind"] == "object"
    assert {e["frame_id"] for e in log if e["frame_id"]} <= {f"frame-{i:06d}" for i in range(20)}


def test_ingesting_the_same_folder_again_adds_nothing(
    recordings: Recordings, service_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    arguments = ("--limit", "6", "--frames-per-batch", "3", "--batch-prefix", "again", "--wait")
    assert ingest_folder(recordings, service_url, "folder-again", *arguments) == 0
    first = capsys.readouterr().out
    scene = scene_id(service_url, "folder-again")
    before = len(events(service_url, scene))
    assert ingest_folder(recordings, service_url, "folder-again", *arguments) == 0
    second = capsys.readouterr().out
    assert "(created)" in first and "(existing)" in second
    assert "batches posted 2 (2 accepted before)" in second
    assert "events appended: 0" in second and "events appended: 0" not in first
    assert len(events(service_url, scene)) == before


def test_new_content_under_old_batch_ids_is_refused_with_the_reason(
    recordings: Recordings, service_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    arguments = ("--limit", "2", "--batch-prefix", "conflict", "--no-progress")
    assert ingest_folder(recordings, service_url, "folder-conflict", *arguments) == 0
    assert (
        ingest_folder(recordings, service_url, "folder-conflict", *arguments, "--stride", "2") == 2
    )
    error = capsys.readouterr().err
    assert "post batch conflict-000000: HTTP 409" in error
    assert "already posted with different content" in error
    assert "--batch-prefix" in error  # what to do about it


def test_a_full_scene_queue_is_waited_out(
    recordings: Recordings, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One unfinished batch per scene and no worker yet: the second post is a 429 (Retry-After
    1 s), repeated until a worker starts and catches up."""
    with running_service(
        tmp_path,
        "--no-worker",
        max_queued_batches_per_scene="1",
        queue_full_retry_after_seconds="1",
    ) as service:
        arguments = ("--limit", "8", "--frames-per-batch", "4", "--no-progress", "--wait")
        codes: list[int] = []
        sender = threading.Thread(
            target=lambda: codes.append(
                ingest_folder(recordings, service.url, "folder-full", *arguments)
            )
        )
        sender.start()
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not first_batch_queued(service.url):
            time.sleep(0.1)
        time.sleep(2.0)  # the second batch meets the full queue meanwhile
        service.start("worker")
        sender.join(timeout=120)
        assert codes == [0]
        out = capsys.readouterr().out
        assert re.search(r"batches posted 2, [1-9]\d* requests repeated after a busy reply", out)
        scene = scene_id(service.url, "folder-full")
        assert [
            batch_status(service.url, scene, f"kitchen-{n:06d}")["status"] for n in range(2)
        ] == ["done"] * 2


def first_batch_queued(url: str) -> bool:
    """Whether the scene `folder-full` exists and holds its first batch."""
    scenes = httpx.get(f"{url}/v1/scenes").json()["scenes"]
    found = [scene["id"] for scene in scenes if scene["name"] == "folder-full"]
    return bool(found) and (
        httpx.get(f"{url}/v1/scenes/{found[0]}/batches/kitchen-000000").status_code == 200
    )


def test_stride_and_limit_choose_the_frames(
    recordings: Recordings, service_url: str, capsys: pytest.CaptureFixture[str]
) -> None:
    arguments = ("--stride", "3", "--limit", "4", "--frames-per-batch", "1", "--no-progress")
    assert ingest_folder(recordings, service_url, "folder-stride", *arguments, "--wait") == 0
    assert "frames read: 4, sent: 4" in capsys.readouterr().out
    log = events(service_url, scene_id(service_url, "folder-stride"))
    # One frame per batch: each batch's occupancy evidence names its frame.
    assert [e["frame_id"] for e in log if e["type"] == "occupancy_evidence"] == [
        "frame-000000",
        "frame-000003",
        "frame-000006",
        "frame-000009",
    ]


def test_the_folder_frames_carry_the_pose_files_and_intrinsics(recordings: Recordings) -> None:
    source = FolderSource(recordings.folder, stride=5)
    frames = list(source.frames())
    assert [f.index for f in frames] == [0, 5, 10, 15] and source.counts.read == 4
    for frame in frames:
        pose = np.loadtxt(recordings.folder / f"frame-{frame.index:06d}.pose.txt")
        np.testing.assert_array_equal(frame.pose, pose)
        assert frame.depth.dtype == np.uint16 and frame.depth.shape == (480, 640)
        assert (frame.intrinsics.fx, frame.intrinsics.cx, frame.intrinsics.cy) == (585, 320, 240)
        assert frame.timestamp == pytest.approx(frame.index / 30)


def test_frames_without_a_pose_or_instance_png_are_skipped_and_counted(
    recordings: Recordings, service_url: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = tmp_path / "partial"
    shutil.copytree(recordings.folder, folder, symlinks=True)
    (folder / "frame-000002.pose.txt").unlink()
    (folder / "masks" / "frame-000004.png").unlink()
    masks = ("--masks", str(folder / "masks"), "--limit", "6", "--no-progress")
    assert ingest_folder(recordings, service_url, "folder-partial", *masks, folder=folder) == 0
    out = capsys.readouterr().out
    assert "frames read: 6, sent: 4 (with 16 detections), skipped: 2" in out
    assert "skipped 1: no pose file" in out and "skipped 1: no instance PNG" in out


@pytest.mark.parametrize(
    ("change", "arguments", "message"),
    [
        ("no intrinsics", (), "has no camera-intrinsics.txt"),
        ("", ("--detector", "yolo"), "unknown detector 'yolo'; installed detectors"),
        (
            "",
            ("--detector", "instance-pngs", "--masks", "{masks}"),
            "'instance-pngs' needs --labels",
        ),
        (
            "",
            ("--detector", "instance-pngs", "--labels", "{labels}"),
            "'instance-pngs' needs --masks",
        ),
        ("", ("--labels", "{labels}"), "--labels, --masks and --label-topic need a --detector"),
        ("", ("--stride", "0"), "--stride must be at least 1"),
        ("", ("--url", "http://127.0.0.1:9"), "list scenes: cannot reach http://127.0.0.1:9"),
    ],
)
def test_bad_input_is_a_clear_error(
    recordings: Recordings,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    change: str,
    arguments: tuple[str, ...],
    message: str,
) -> None:
    folder = tmp_path / "folder"
    shutil.copytree(recordings.folder, folder, symlinks=True)
    if change == "no intrinsics":
        (folder / "camera-intrinsics.txt").unlink()
    filled = [
        a.format(masks=recordings.folder / "masks", labels=recordings.labels) for a in arguments
    ]
    code = main(["ingest", "folder", str(folder), "--scene", "bad", "--no-progress", *filled])
    assert code == 2
    assert message in capsys.readouterr().err


class NearSurfaces:
    """A user's own detector (the `Detector` protocol, no entry point needed in process): the
    pixels nearer than 1.2 m are a "box"; every third frame it cannot judge."""

    topics: tuple[str, ...] = ()

    def detect(self, frame: SourceFrame, source: FrameSource) -> list[Detection]:
        if frame.index % 3 == 2:
            raise SkipFrame("model not sure")
        metres = frame.depth_metres()
        return [Detection("box", 0.8, (metres > 0) & (metres < 1.2), embedding=[1.0, 0.0])]


def test_a_detector_of_ones_own_runs_through_the_same_pipeline(
    recordings: Recordings, service_url: str
) -> None:
    source = FolderSource(recordings.folder, limit=9)
    summary = ingest(
        source, NearSurfaces(), url=service_url, scene="own-detector", wait=True, progress=False
    )
    assert (summary.frames_read, summary.frames_sent, summary.skipped) == (
        9,
        6,
        {"model not sure": 3},
    )
    assert summary.sink is not None and set(summary.sink.statuses.values()) == {"done"}
    log = events(service_url, summary.sink.scene_id)
    assert any(e["type"] == "add" and e["details"]["kind"] == "object" for e in log)
    assert "  skipped 3: model not sure" in summary.lines()


def test_a_service_that_needs_a_token_gets_it_from_the_flag(
    recordings: Recordings, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with running_service(tmp_path, allow_anonymous_local="false") as service:
        arguments = ("--limit", "2", "--no-progress")
        assert ingest_folder(recordings, service.url, "folder-token", *arguments) == 2
        assert "list scenes: HTTP 401" in capsys.readouterr().err
        create = ["token", "create", "--name", "ingest", "--scope", "write"]
        created = subprocess.run(
            [sys.executable, "-m", "service.cli", *create],
            env=service.env,
            cwd=REPO,
            capture_output=True,
            text=True,
            check=True,
        )
        token = created.stdout.strip()
        assert (
            ingest_folder(recordings, service.url, "folder-token", *arguments, "--token", token)
            == 0
        )
        assert "frames read: 2, sent: 2" in capsys.readouterr().out
