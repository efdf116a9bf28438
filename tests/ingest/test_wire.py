"""Frames and detections on the wire: the service's own decoder reads back what ingest encodes
(the encoders themselves are the typed client's, tested in tests/client/test_encoding.py)."""

from __future__ import annotations

import numpy as np
import pytest

from api_schema.requests import FrameIn
from codec.observations import decode_frames
from ingest.detectors import Detection
from ingest.frames import CameraIntrinsics, SourceFrame
from ingest.wire import batches, frame_in

INTRINSICS = CameraIntrinsics(width=40, height=30, fx=50.0, fy=50.0, cx=20.0, cy=15.0)


def masks() -> list[np.ndarray]:
    """Masks with every edge case: empty, full, first pixel set, last pixel set, random."""
    rng = np.random.default_rng(7)
    shape = (30, 40)
    first, last = np.zeros(shape, bool), np.zeros(shape, bool)
    first[0, 0] = True
    last[-1, -1] = True
    box = np.zeros(shape, bool)
    box[5:20, 8:33] = True
    return [
        np.zeros(shape, bool),
        np.ones(shape, bool),
        first,
        last,
        box,
        *(rng.random(shape) < p for p in (0.05, 0.5, 0.95)),
    ]


def frame(depth: np.ndarray) -> SourceFrame:
    pose = np.eye(4)
    pose[:3, 3] = (1.0, -2.0, 0.5)
    return SourceFrame(
        index=3, frame_id="f3", timestamp=0.1, depth=depth, intrinsics=INTRINSICS, pose=pose
    )


def test_uint16_depth_and_masks_decode_to_the_same_metres_and_pixels() -> None:
    depth = (500 + np.arange(30 * 40) % 4000).astype(np.uint16).reshape(30, 40)
    depth[:4, :6] = 0
    box = masks()[4]
    wire = frame_in(frame(depth), [Detection("table", 0.8, box, "fixture", [0.5, 1.5])])
    decoded = decode_frames([FrameIn.model_validate(wire.model_dump(mode="json"))])[0]
    np.testing.assert_allclose(decoded.depth, depth.astype(np.float64) / 1000, rtol=1e-6)
    assert (decoded.depth[:4, :6] == 0).all()
    np.testing.assert_allclose(decoded.pose, frame(depth).pose)
    (detection,) = decoded.detections
    assert (detection.label, detection.kind, detection.score) == ("table", "fixture", 0.8)
    np.testing.assert_array_equal(detection.mask.to_array(), box)
    assert detection.embedding is not None and detection.embedding.tolist() == [0.5, 1.5]


def test_float_depth_goes_as_millimetres_with_nan_as_no_measurement() -> None:
    metres = np.full((30, 40), 1.2344, dtype=np.float32)
    metres[0, 0], metres[0, 1], metres[0, 2] = np.nan, 0.0, 0.0002
    decoded = decode_frames([frame_in(frame(metres), [])])[0]
    assert decoded.depth[0, 0] == 0 and decoded.depth[0, 1] == 0
    assert decoded.depth[0, 2] == pytest.approx(0.001)  # a tiny valid depth stays valid
    assert decoded.depth[5, 5] == pytest.approx(1.234, abs=1e-6)


def test_batches_group_frames_with_stable_ids() -> None:
    frames = [frame_in(frame(np.ones((30, 40), np.uint16)), []) for _ in range(5)]
    frames = [f.model_copy(update={"frame_id": f"f{i}"}) for i, f in enumerate(frames)]
    grouped = list(batches(frames, "kitchen", 2))
    assert [b.batch_id for b in grouped] == ["kitchen-000000", "kitchen-000001", "kitchen-000002"]
    assert [[f.frame_id for f in b.frames] for b in grouped] == [["f0", "f1"], ["f2", "f3"], ["f4"]]
