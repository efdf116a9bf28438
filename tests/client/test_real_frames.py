"""20 real 7-Scenes kitchen frames posted through the client: depth PNGs in millimetres as they
are on disk, the recorded poses and intrinsics, and two object masks cut out of the depth (the
real surfaces inside two 20 cm cubes the first frame sees)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from api_schema import BatchIn, DetectionIn, FrameIn, Intrinsics
from pbdag_client import Client, build_batch, build_frame, detection
from tests.client.conftest import Service, open_settings, serving

FRAME_INDICES = range(0, 100, 5)  # 20 frames over the first 3.3 s of the walk
FRAMES_PER_BATCH = 2
ANCHORS = {"mug": (300, 250), "book": (220, 330)}  # pixels (u, v) of the first frame
HALF_M = 0.10
MIN_MASK_PIXELS = 150


def read_intrinsics(path: Path) -> Intrinsics:
    """The 3x3 K of camera-intrinsics.txt, for the 640x480 depth images."""
    k = np.loadtxt(path / "camera-intrinsics.txt")
    return Intrinsics(
        width=640,
        height=480,
        fx=float(k[0, 0]),
        fy=float(k[1, 1]),
        cx=float(k[0, 2]),
        cy=float(k[1, 2]),
    )


def world_points(depth_mm: np.ndarray, pose: np.ndarray, camera: Intrinsics) -> np.ndarray:
    """Every pixel back-projected to world coordinates (NaN where depth is missing)."""
    v, u = np.indices(depth_mm.shape)
    z = np.where(depth_mm > 0, depth_mm / 1000.0, np.nan)
    points = np.stack(
        [(u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z, np.ones_like(z)],
        axis=-1,
    )
    world: np.ndarray = (points @ pose.T)[..., :3]
    return world


def real_frames(path: Path) -> Iterator[FrameIn]:
    camera = read_intrinsics(path)
    centers: dict[str, np.ndarray] = {}
    for index in FRAME_INDICES:
        with Image.open(path / f"frame-{index:06d}.depth.png") as image:
            depth_mm = np.asarray(image).astype(np.uint16)
        pose = np.loadtxt(path / f"frame-{index:06d}.pose.txt")
        world = world_points(depth_mm, pose, camera)
        if not centers:
            centers = {label: world[v, u] for label, (u, v) in ANCHORS.items()}
            assert all(np.isfinite(c).all() for c in centers.values())
        detections: list[DetectionIn] = []
        for label, center in centers.items():
            with np.errstate(invalid="ignore"):
                mask = (np.abs(world - center) <= HALF_M).all(axis=-1)
            if mask.sum() >= MIN_MASK_PIXELS:
                detections.append(detection(label, 0.9, mask))
        yield build_frame(f"kitchen-{index:06d}", index / 30.0, depth_mm, camera, pose, detections)


def batches(path: Path) -> list[BatchIn]:
    frames = list(real_frames(path))
    return [
        build_batch(f"kitchen-b{start:03d}", frames[start : start + FRAMES_PER_BATCH])
        for start in range(0, len(frames), FRAMES_PER_BATCH)
    ]


@pytest.fixture(scope="module")
def kitchen_service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Service]:
    with serving(open_settings(tmp_path_factory.mktemp("kitchen-service"))) as running:
        yield running


def test_twenty_real_frames_through_the_client(
    real_kitchen: Path, kitchen_service: Service
) -> None:
    posted = batches(real_kitchen)
    frames = [frame for batch in posted for frame in batch.frames]
    assert len(frames) == 20 and len(posted) == 10
    assert sum(len(frame.detections) for frame in frames) >= 30  # both cubes in most frames
    with Client(kitchen_service.url) as client:
        scene = client.create_scene("7scenes-kitchen")
        for batch in posted:
            assert client.post_batch(scene.id, batch).status == "queued"
        done = [client.wait_for_batch(scene.id, b.batch_id, timeout=300) for b in posted]
        assert [status.status for status in done] == ["done"] * len(posted)
        assert [status.frame_count for status in done] == [2] * len(posted)
        events = list(client.events(scene.id, page_size=50))
        assert len(events) > 1 and events[0].type == "scene_created"
        assert {e.frame_id for e in events if e.frame_id} <= {f.frame_id for f in frames}
        graph = client.graph(scene.id)
        labels = sorted(node.label for node in graph.nodes)
        assert labels == ["book", "mug"], labels
        for node in graph.nodes:
            assert node.state == "confirmed" and node.kind == "object"
            explanation = client.explain(scene.id, node.id, events=True)
            assert explanation.events and explanation.track_id == node.id
        # The mug sits where the first frame saw it: its center is within its cube.
        camera = read_intrinsics(real_kitchen)
        with Image.open(real_kitchen / "frame-000000.depth.png") as image:
            first = world_points(
                np.asarray(image).astype(np.uint16),
                np.loadtxt(real_kitchen / "frame-000000.pose.txt"),
                camera,
            )
        u, v = ANCHORS["mug"]
        mug = next(node for node in graph.nodes if node.label == "mug")
        assert np.abs(np.array(mug.center) - first[v, u]).max() <= HALF_M
