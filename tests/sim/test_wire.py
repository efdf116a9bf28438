"""Wire encoders round-trip through the decoders the service will use."""

from __future__ import annotations

import base64
import io
import json
from typing import Any

import numpy as np
import pytest
from PIL import Image
from pycocotools import mask as coco_mask

from sim.camera import CameraModel, look_at
from sim.detector import SimDetection
from sim.wire import (
    encode_depth_f32,
    encode_depth_png16,
    encode_detection,
    encode_mask,
    make_batch,
    make_frame,
)


def sample_depth() -> np.ndarray:
    """A depth image with holes, a far region and sub-millimetre detail."""
    rng = np.random.default_rng(11)
    depth = rng.uniform(0.3, 6.0, size=(48, 64)).astype(np.float32)
    depth[5:10, 5:20] = 0.0
    return depth


def test_png16_round_trip_within_half_a_step() -> None:
    depth = sample_depth()
    encoded = encode_depth_png16(depth, scale=0.001)
    assert encoded["encoding"] == "png16" and encoded["scale"] == 0.001
    image = Image.open(io.BytesIO(base64.b64decode(encoded["data"])))
    assert image.format == "PNG" and image.mode == "I;16"
    decoded = np.array(image).astype(np.float64) * encoded["scale"]
    assert decoded.shape == depth.shape
    assert np.abs(decoded - depth).max() <= 0.0005 + 1e-9
    assert np.array_equal(decoded == 0, depth == 0)


def test_png16_clips_far_depth_to_uint16() -> None:
    encoded = encode_depth_png16(np.array([[70.0, 1.0]], dtype=np.float32), scale=0.001)
    decoded = np.array(Image.open(io.BytesIO(base64.b64decode(encoded["data"]))))
    assert decoded.tolist() == [[65535, 1000]]


def test_f32_round_trip_is_exact() -> None:
    depth = sample_depth()
    encoded = encode_depth_f32(depth)
    assert encoded["encoding"] == "f32"
    decoded = np.frombuffer(base64.b64decode(encoded["data"]), dtype="<f4").reshape(depth.shape)
    assert np.array_equal(decoded, depth)


# pycocotools 2.0.11's decode trips numpy 2's __array__ copy-keyword deprecation; harmless here.
@pytest.mark.filterwarnings("ignore:__array__ implementation:DeprecationWarning")
def test_mask_rle_round_trips_through_pycocotools() -> None:
    mask = np.zeros((48, 64), dtype=bool)
    mask[10:30, 7:40] = True
    mask[40, 60] = True
    encoded = encode_mask(mask)
    assert encoded["size"] == [48, 64] and isinstance(encoded["counts"], str)
    rle = {"size": encoded["size"], "counts": encoded["counts"].encode("ascii")}
    assert np.array_equal(coco_mask.decode(rle).astype(bool), mask)


def test_make_batch_is_json_with_the_wire_fields() -> None:
    camera = CameraModel(width=64, height=48, fx=50.0, fy=50.0, cx=31.5, cy=23.5)
    mask = np.zeros((48, 64), dtype=bool)
    mask[4:9, 4:9] = True
    detections = [
        SimDetection("mug-1", "mug", 0.93, mask, np.array([0.1, 0.2])),
        SimDetection("book-1", "book", 0.8, mask, None),
    ]
    pose = look_at((1.0, 1.0, 1.3), (2.0, 1.0, 0.8))
    frame = make_frame("f000123", 12.5, camera, pose, sample_depth(), detections)
    batch = json.loads(json.dumps(make_batch("batch-1", [frame])))

    assert batch["batch_id"] == "batch-1" and len(batch["frames"]) == 1
    sent = batch["frames"][0]
    assert sent["frame_id"] == "f000123" and sent["timestamp"] == 12.5
    assert sent["intrinsics"] == {
        "width": 64,
        "height": 48,
        "fx": 50.0,
        "fy": 50.0,
        "cx": 31.5,
        "cy": 23.5,
    }
    assert np.allclose(np.array(sent["pose"]), pose) and len(sent["pose"]) == 4
    assert sent["depth"]["encoding"] == "png16"
    first, second = sent["detections"]
    assert first == {
        "label": "mug",
        "score": 0.93,
        "kind": "object",
        "mask": encode_mask(mask),
        "embedding": [0.1, 0.2],
    }
    assert "embedding" not in second and "class_scores" not in second
    assert "object_id" not in first  # ground truth must not leak to the service


def test_make_frame_can_send_float_depth() -> None:
    camera = CameraModel(width=64, height=48)
    frame = make_frame("f1", 0.0, camera, np.eye(4), sample_depth(), [], depth_encoding="f32")
    assert frame["depth"]["encoding"] == "f32" and frame["detections"] == []


def test_fixture_detection_sends_kind_and_class_scores() -> None:
    mask = np.zeros((48, 64), dtype=bool)
    mask[20:40, 10:50] = True
    # numpy scalars must come out as plain floats, or json.dumps refuses them.
    class_scores: dict[str, Any] = {"desk": np.float64(0.51), "table": np.float32(0.49)}
    desk = SimDetection("desk-1", "desk", 0.51, mask, None, "fixture", class_scores)
    encoded = json.loads(json.dumps(encode_detection(desk)))
    assert encoded["kind"] == "fixture" and encoded["label"] == "desk"
    assert encoded["class_scores"] == pytest.approx({"desk": 0.51, "table": 0.49})
    assert list(encoded["class_scores"]) == ["desk", "table"]
    assert "embedding" not in encoded and "desk-1" not in json.dumps(encoded)
