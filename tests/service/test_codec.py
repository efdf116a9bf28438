"""Wire -> domain decoding of batches: arrays, field paths of bad input, content hashing."""

from __future__ import annotations

import base64
import copy
import hashlib
import json
import time
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from api_schema import BatchIn
from codec.canonical import content_sha256
from codec.observations import decode_batch
from codec.rle import compressed_rle_counts
from tests.service.codec_errors import decode_error, schema_errors
from tests.wire_bodies import (
    HEIGHT,
    WIDTH,
    batch_body,
    f32_base64,
    frame_body,
    png_base64,
    rle_of,
    sample_depth_mm,
    sample_masks,
    sample_pose,
)

# --- valid input --------------------------------------------------------------------------


def test_valid_batch_decodes_to_metres_masks_and_float64_pose() -> None:
    batch = decode_batch(BatchIn.model_validate(batch_body(frame_body("a"), frame_body("b"))))

    assert batch.batch_id == "robot-1:batch.0001"
    assert [frame.frame_id for frame in batch.frames] == ["a", "b"]
    frame = batch.frames[0]
    assert frame.timestamp == 12.5
    assert (frame.intrinsics.width, frame.intrinsics.height) == (WIDTH, HEIGHT)
    assert frame.intrinsics.fy == 51.0

    assert frame.depth.dtype == np.float32
    assert frame.depth.shape == (HEIGHT, WIDTH)
    expected_metres = sample_depth_mm().astype(np.float64) / 1000.0
    np.testing.assert_allclose(frame.depth, expected_metres, rtol=1e-6, atol=0)
    assert (frame.depth[:5, :7] == 0).all()

    assert frame.pose.dtype == np.float64
    np.testing.assert_array_equal(frame.pose, np.array(sample_pose()))

    box, band = sample_masks()
    mug, table = frame.detections
    assert mug.mask.to_array().dtype == np.bool_ and mug.mask.to_array().flags.c_contiguous
    np.testing.assert_array_equal(mug.mask.to_array(), box)
    np.testing.assert_array_equal(table.mask.to_array(), band)
    assert (mug.label, mug.score, mug.kind) == ("mug", 0.93, "object")
    assert (table.label, table.kind) == ("table", "fixture")
    assert mug.embedding is not None and mug.embedding.dtype == np.float64
    np.testing.assert_array_equal(mug.embedding, [0.1, 0.2, -0.3])
    assert mug.class_scores == {"mug": 0.93, "cup": 0.05}
    assert table.embedding is None and table.class_scores is None


def test_png16_scale_is_applied() -> None:
    frame = frame_body()
    frame["depth"]["scale"] = 0.0002  # e.g. a 1/5 mm sensor
    decoded = decode_batch(BatchIn.model_validate(batch_body(frame))).frames[0]
    np.testing.assert_allclose(decoded.depth, sample_depth_mm() * 0.0002, rtol=1e-6)


def test_f32_depth_keeps_metres_and_zeroes_nan_and_inf() -> None:
    metres = np.linspace(0.3, 4.0, HEIGHT * WIDTH, dtype=np.float32).reshape(HEIGHT, WIDTH)
    metres[0, 0] = np.nan
    metres[0, 1] = np.inf
    metres[0, 2] = -np.inf
    frame = frame_body()
    frame["depth"] = {"encoding": "f32", "data": f32_base64(metres)}

    depth = decode_batch(BatchIn.model_validate(batch_body(frame))).frames[0].depth

    assert depth.dtype == np.float32 and depth.flags.writeable
    assert (depth[0, :3] == 0).all()
    np.testing.assert_array_equal(depth[1:], metres[1:])


def test_frame_without_detections_is_valid() -> None:
    frame = frame_body()
    del frame["detections"]
    assert decode_batch(BatchIn.model_validate(batch_body(frame))).frames[0].detections == ()


def test_mask_of_all_ones_starts_with_an_empty_run() -> None:
    full = np.ones((HEIGHT, WIDTH), dtype=bool)
    frame = frame_body()
    frame["detections"][0]["mask"] = rle_of(full)
    frame["detections"][1]["mask"] = {"size": [HEIGHT, WIDTH], "counts": [0, HEIGHT * WIDTH]}
    detections = decode_batch(BatchIn.model_validate(batch_body(frame))).frames[0].detections
    assert detections[0].mask.to_array().all() and detections[1].mask.to_array().all()


# --- bad depth ----------------------------------------------------------------------------


def with_depth(**depth: Any) -> dict[str, Any]:
    """A one-frame batch whose depth object is replaced."""
    frame = frame_body()
    frame["depth"] = depth
    return batch_body(frame)


@pytest.mark.parametrize(
    ("depth", "reason_part"),
    [
        pytest.param({"encoding": "png16", "data": "not base64!"}, "base64", id="bad-base64"),
        pytest.param({"encoding": "png16", "data": "QUJ"}, "base64", id="bad-padding"),
        pytest.param(
            {"encoding": "png16", "data": base64.b64encode(b"hello, not a png").decode()},
            "not a PNG",
            id="not-an-image",
        ),
        pytest.param(
            {"encoding": "png16", "data": png_base64(sample_depth_mm(), "TIFF")},
            "not a PNG",
            id="16-bit-tiff",
        ),
        pytest.param(
            {"encoding": "png16", "data": png_base64(np.zeros((HEIGHT, WIDTH), np.uint8))},
            "16-bit",
            id="8-bit-png",
        ),
        pytest.param(
            {"encoding": "png16", "data": png_base64(np.zeros((HEIGHT, WIDTH, 3), np.uint8))},
            "16-bit",
            id="rgb-png",
        ),
        pytest.param(
            {"encoding": "png16", "data": png_base64(np.zeros((HEIGHT, WIDTH + 1), np.uint16))},
            "does not match the intrinsics",
            id="png-wrong-size",
        ),
        pytest.param(
            {"encoding": "f32", "data": f32_base64(np.ones((HEIGHT, WIDTH - 1), np.float32))},
            f"{HEIGHT * WIDTH * 4} bytes",
            id="f32-short",
        ),
        pytest.param(
            {
                "encoding": "f32",
                "data": base64.b64encode(np.ones(HEIGHT * WIDTH, "<f4").tobytes() + b"x").decode(),
            },
            f"got {HEIGHT * WIDTH * 4 + 1}",
            id="f32-long",
        ),
        pytest.param(
            {"encoding": "f32", "data": f32_base64(np.full((HEIGHT, WIDTH), -1.0, np.float32))},
            "negative",
            id="f32-negative",
        ),
    ],
)
def test_undecodable_depth_names_the_data_field(depth: dict[str, Any], reason_part: str) -> None:
    error = decode_error(with_depth(**depth))
    assert error.field == "frames[0].depth.data"
    assert reason_part in error.reason


def test_truncated_png_is_rejected() -> None:
    raw = base64.b64decode(png_base64(sample_depth_mm()))
    error = decode_error(
        with_depth(encoding="png16", data=base64.b64encode(raw[: len(raw) // 2]).decode())
    )
    assert error.field == "frames[0].depth.data"
    assert "PNG" in error.reason


def test_unknown_depth_encoding_and_bad_scale_fail_the_schema() -> None:
    data = png_base64(sample_depth_mm())
    assert schema_errors(with_depth(encoding="jpeg", data=data)) == [
        (("frames", 0, "depth", "encoding"), "literal_error")
    ]
    assert schema_errors(with_depth(encoding="png16", scale=0, data=data)) == [
        (("frames", 0, "depth", "scale"), "greater_than")
    ]


# --- bad masks ----------------------------------------------------------------------------


def with_mask(mask: dict[str, Any], detection_index: int = 1) -> dict[str, Any]:
    """A one-frame batch whose given detection has this mask."""
    frame = frame_body()
    frame["detections"][detection_index]["mask"] = mask
    return batch_body(frame)


def test_mask_size_different_from_depth_size_names_mask_size() -> None:
    small = np.zeros((HEIGHT, WIDTH - 4), dtype=bool)
    error = decode_error(with_mask(rle_of(small)))
    assert error.field == "frames[0].detections[1].mask.size"
    assert f"[{HEIGHT}, {WIDTH - 4}]" in error.reason
    assert f"[{HEIGHT}, {WIDTH}]" in error.reason


@pytest.mark.parametrize(
    ("counts", "reason_part"),
    [
        pytest.param("", "empty", id="empty-string"),
        pytest.param("abc~", "outside", id="bad-characters"),
        pytest.param("é1", "ASCII", id="non-ascii"),
        pytest.param("2P", "middle of a value", id="truncated-value"),
        pytest.param("ooooooo1", "too large", id="overlong-value"),
        pytest.param(rle_of(np.ones((4, 4), bool))["counts"], "sum to", id="short-string"),
        pytest.param("0@", "negative", id="negative-run"),
        pytest.param([10, 20], "sum to", id="short-list"),
        pytest.param([HEIGHT * WIDTH, 1], "sum to", id="long-list"),
    ],
)
def test_undecodable_mask_names_mask_counts(counts: Any, reason_part: str) -> None:
    error = decode_error(with_mask({"size": [HEIGHT, WIDTH], "counts": counts}))
    assert error.field == "frames[0].detections[1].mask.counts"
    assert reason_part in error.reason


@pytest.mark.parametrize("counts", [[1, -2], [1, True], 5, {"a": 1}, [1.5]])
def test_mask_counts_of_the_wrong_type_fail_the_schema(counts: Any) -> None:
    assert schema_errors(with_mask({"size": [HEIGHT, WIDTH], "counts": counts})) == [
        (("frames", 0, "detections", 1, "mask", "counts"), "rle_counts")
    ]


@settings(max_examples=150, deadline=None)
@given(arrays(np.bool_, st.tuples(st.integers(1, 40), st.integers(1, 40))))
def test_compressed_rle_counts_match_pycocotools(mask: npt.NDArray[np.bool_]) -> None:
    runs = compressed_rle_counts(rle_of(mask)["counts"])
    assert int(runs.sum()) == mask.size
    column_major = np.repeat(np.arange(runs.size) % 2, runs).astype(bool)
    np.testing.assert_array_equal(column_major.reshape(mask.shape[::-1]).T, mask)


# --- hashing and speed --------------------------------------------------------------------


def test_content_sha256_ignores_key_order_and_whitespace() -> None:
    body = batch_body()
    compact = json.dumps(body, separators=(",", ":"))
    pretty_reordered = json.dumps(dict(reversed(list(body.items()))), indent=4)
    assert content_sha256(json.loads(compact)) == content_sha256(json.loads(pretty_reordered))

    nested = {"b": 1, "a": {"y": [1, 2], "x": "z"}}
    expected = hashlib.sha256(b'{"a":{"x":"z","y":[1,2]},"b":1}').hexdigest()
    assert content_sha256(nested) == expected


def test_content_sha256_changes_with_content() -> None:
    body = batch_body()
    changed = copy.deepcopy(body)
    changed["frames"][0]["timestamp"] = 12.75
    assert content_sha256(body) != content_sha256(changed)


def test_two_vga_frames_with_twenty_masks_decode_quickly() -> None:
    height, width = 480, 640
    rng = np.random.default_rng(7)
    depth_mm = rng.integers(300, 5000, size=(height, width), dtype=np.uint16)
    rows, cols = np.indices((height, width))
    detections = []
    for index in range(20):
        cy, cx, radius = 40 + 20 * index, 30 + 29 * index, 25 + 3 * index
        blob = (rows - cy) ** 2 + (cols - cx) ** 2 < radius**2
        detections.append({"label": f"thing{index}", "score": 0.5, "mask": rle_of(blob)})
    frame = frame_body()
    frame["intrinsics"].update(width=width, height=height)
    frame["depth"]["data"] = png_base64(depth_mm)
    frame["detections"] = detections
    batch = BatchIn.model_validate(batch_body(frame, {**frame, "frame_id": "f1"}))

    durations = []
    for _ in range(3):
        start = time.perf_counter()
        decoded = decode_batch(batch)
        durations.append(time.perf_counter() - start)

    assert len(decoded.frames[1].detections) == 20
    # Generous bound (target is well under 0.1 s): catches an accidental per-pixel Python loop.
    assert min(durations) < 0.25
