"""Each reproducer of the hostile-input issue, through HTTP: a clear 4xx, nothing stored.

Each of these crashed the process, poisoned a scene's log, took unbounded work, or answered 500.
"""

from __future__ import annotations

import base64
import dataclasses
import io
import time
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image

from service.app import create_app
from service.bootstrap import Container
from tests.clients import local_client
from tests.wire_bodies import batch_body, frame_body, rle_of


def rejected(
    client: TestClient, scene_id: str, body: Any, status: int, field: str | None
) -> dict[str, Any]:
    """Post, expect a problem naming `field`, and check that nothing was stored."""
    before = client.get(f"/v1/scenes/{scene_id}").json()["head_seq"]
    queued = sum(client.get("/healthz").json()["batches"].values())
    response = client.post(f"/v1/scenes/{scene_id}/batches", json=body)
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == "application/problem+json"
    problem: dict[str, Any] = response.json()
    if field is not None:
        assert problem["field"] is not None and problem["field"].startswith(field), problem
    assert client.get(f"/v1/scenes/{scene_id}").json()["head_seq"] == before
    assert sum(client.get("/healthz").json()["batches"].values()) == queued
    return problem


def one_pixel_frame(counts: Any) -> dict[str, Any]:
    """A 1x1 frame whose only mask has the given run lengths."""
    frame = frame_body()
    frame["intrinsics"].update(width=1, height=1, cx=0.0, cy=0.0)
    frame["depth"]["data"] = base64.b64encode(png_bytes(np.full((1, 1), 1000, np.uint16))).decode()
    frame["detections"] = [
        {"label": "mug", "score": 0.9, "mask": {"size": [1, 1], "counts": counts}}
    ]
    return frame


def png_bytes(pixels: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format="PNG")
    return buffer.getvalue()


def test_run_lengths_that_wrap_an_int64_sum_are_a_422(client: TestClient, scene_id: str) -> None:
    # The 521-byte batch that killed `pbdag serve` with a segfault: runs summing to 2**64 + 1.
    wrapping = [2**62, 2**62, 2**62, 2**62 + 1]
    problem = rejected(client, scene_id, batch_body(one_pixel_frame(wrapping)), 422, "frames[0]")
    assert problem["field"] == "frames[0].detections[0].mask.counts"
    rejected(client, scene_id, batch_body(one_pixel_frame([10**30])), 422, "frames[0]")
    assert client.get("/healthz").status_code == 200  # the process is alive


@pytest.mark.parametrize("focal", [1e-310, 5e-324, 0.5])
def test_a_focal_length_below_one_pixel_is_a_422(
    client: TestClient, scene_id: str, focal: float
) -> None:
    frame = frame_body()
    frame["intrinsics"]["fx"] = focal
    rejected(client, scene_id, batch_body(frame), 422, "frames[0].intrinsics.fx")


def test_a_huge_image_is_refused_before_its_pixels_are_decoded(
    client: TestClient, scene_id: str
) -> None:
    # 8192 x 8192 constant depth: a 200 KB PNG that took the worker 140 s and 7 GB.
    frame = frame_body()
    frame["intrinsics"].update(width=8192, height=8192, cx=4096.0, cy=4096.0)
    frame["depth"]["data"] = base64.b64encode(
        png_bytes(np.full((8192, 8192), 1500, np.uint16))
    ).decode()
    frame["detections"] = []
    started = time.perf_counter()
    problem = rejected(client, scene_id, batch_body(frame), 422, "frames[0].intrinsics")
    assert time.perf_counter() - started < 5
    assert "PBDAG_MAX_IMAGE_PIXELS" in problem["detail"]


def test_thousands_of_detections_are_refused_fast(client: TestClient, scene_id: str) -> None:
    frame = frame_body()
    frame["detections"] = frame["detections"][:1] * 2000
    started = time.perf_counter()
    problem = rejected(client, scene_id, batch_body(frame), 422, "frames[0].detections")
    assert time.perf_counter() - started < 5
    assert "256" in problem["detail"]


def test_an_embedding_longer_than_the_limit_is_a_422(client: TestClient, scene_id: str) -> None:
    frame = frame_body()
    frame["detections"][0]["embedding"] = [0.1] * 4097
    problem = rejected(client, scene_id, batch_body(frame), 422, "frames[0].detections[0]")
    assert problem["field"] == "frames[0].detections[0].embedding" and "4096" in problem["detail"]


def test_too_many_frames_and_a_far_pose_are_422s(client: TestClient, scene_id: str) -> None:
    frames = [frame_body(f"f{i}") for i in range(17)]
    rejected(client, scene_id, batch_body(*frames), 422, "frames")
    far = frame_body()
    far["pose"][0][3] = 50_000.0
    rejected(client, scene_id, batch_body(far), 422, "frames[0].pose")


def test_nul_characters_are_422s_wherever_text_goes(client: TestClient, scene_id: str) -> None:
    frame = frame_body()
    frame["detections"][0]["label"] = "mu\x00g"
    rejected(client, scene_id, batch_body(frame), 422, "frames[0].detections[0].label")
    assert client.post("/v1/scenes", json={"name": "a\x00b"}).status_code == 422
    for query in ({"label": "a\x00"}, {"parent": "\x00"}):
        response = client.get(f"/v1/scenes/{scene_id}/graph", params=query)
        assert response.status_code == 422, response.text
    response = client.get(f"/v1/scenes/{scene_id}/events", params={"type": "\x00"})
    assert response.status_code == 422
    verdict = {"verdict": "confirm", "source": "x\x00y"}
    response = client.post(f"/v1/scenes/{scene_id}/tracks/trk-000001/verification", json=verdict)
    assert response.status_code == 422 and response.json()["field"] == "source"


def test_integers_beyond_64_bits_are_422s(client: TestClient, scene_id: str) -> None:
    big = 2**63
    for path, params in (
        (f"/v1/scenes/{scene_id}/events", {"after": big}),
        (f"/v1/scenes/{scene_id}/delta", {"baseline": big}),
        (f"/v1/scenes/{scene_id}/graph", {"as_of": big}),
        (f"/v1/scenes/{scene_id}/baselines/{big}", {}),
    ):
        response = client.get(path, params=params)
        assert response.status_code == 422, (path, response.text)
    body = {"name": "x", "baseline": {"scene_id": scene_id, "version": big}}
    assert client.post("/v1/scenes", json=body).status_code == 422


@pytest.mark.parametrize(
    ("params", "field"),
    [
        (
            {"visibility": {"box_samples_per_axis": 100000}},
            "params.visibility.box_samples_per_axis",
        ),
        ({"visibility": {"depth_window_px": -3}}, "params.visibility.depth_window_px"),
        ({"fixtures": {"voxel_size_m": 0}}, "params.fixtures.voxel_size_m"),
        ({"existence": {"logodds_min": 3.0, "logodds_max": -3.0}}, "params.existence"),
    ],
)
def test_scene_params_out_of_range_are_422s(
    client: TestClient, params: dict[str, Any], field: str
) -> None:
    scenes = len(client.get("/v1/scenes").json()["scenes"])
    response = client.post("/v1/scenes", json={"name": "x", "params": params})
    assert response.status_code == 422 and response.json()["field"] == field, response.text
    assert len(client.get("/v1/scenes").json()["scenes"]) == scenes


def test_a_full_scene_queue_is_a_429_with_retry_after(container: Container) -> None:
    settings = container.settings.model_copy(update={"max_queued_batches_per_scene": 2})
    with local_client(create_app(dataclasses.replace(container, settings=settings))) as client:
        scene = client.post("/v1/scenes", json={"name": "busy"}).json()["id"]
        for index in range(2):
            body = batch_body(frame_body())
            body["batch_id"] = f"b{index}"
            assert client.post(f"/v1/scenes/{scene}/batches", json=body).status_code == 202
        body = batch_body(frame_body())
        body["batch_id"] = "b2"
        response = client.post(f"/v1/scenes/{scene}/batches", json=body)
        assert response.status_code == 429 and response.headers["retry-after"] == "2"
        assert response.json()["type"] == "/problems/queue-full"
        body["batch_id"] = "b1"  # a re-post of an accepted batch is still answered
        assert client.post(f"/v1/scenes/{scene}/batches", json=body).status_code == 200


def test_a_scene_over_its_byte_quota_is_a_507(container: Container) -> None:
    settings = container.settings.model_copy(update={"max_scene_blob_bytes": 5_000})
    with local_client(create_app(dataclasses.replace(container, settings=settings))) as client:
        scene = client.post("/v1/scenes", json={"name": "full"}).json()["id"]
        body = batch_body(frame_body())
        # Random values: the quota counts the stored (compressed) bytes.
        embedding = np.random.default_rng(0).random(4000).tolist()
        body["frames"][0]["detections"][0]["embedding"] = embedding
        response = client.post(f"/v1/scenes/{scene}/batches", json=body)
        assert response.status_code == 507 and "PBDAG_MAX_SCENE_BLOB_BYTES" in response.text


def test_a_mask_of_all_ones_still_decodes(client: TestClient, scene_id: str) -> None:
    frame = frame_body()
    frame["detections"] = [
        {"label": "wall", "score": 0.5, "mask": rle_of(np.ones((48, 64), dtype=bool))}
    ]
    response = client.post(f"/v1/scenes/{scene_id}/batches", json=batch_body(frame))
    assert response.status_code == 202, response.text
