"""The client's encoders round-trip through the service's decoders (codec.observations), and its
RLE is byte for byte pycocotools'."""

from __future__ import annotations

from typing import Literal

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from pycocotools import mask as coco_mask

from api_schema import Intrinsics
from codec.observations import decode_batch
from codec.rle import compressed_rle_counts
from core.observation import Frame
from pbdag_client import (
    build_batch,
    build_frame,
    detection,
    encode_depth_f32,
    encode_depth_png16,
    encode_mask,
    rle_runs,
    rle_string,
)

CAMERA = Intrinsics(width=64, height=48, fx=50.0, fy=50.0, cx=31.5, cy=23.5)
TILTED = np.array(
    [[0.0, -1.0, 0.0, 1.5], [1.0, 0.0, 0.0, -2.0], [0.0, 0.0, 1.0, 0.8], [0.0, 0.0, 0.0, 1.0]]
)


def sample_depth() -> np.ndarray:
    rng = np.random.default_rng(3)
    depth = rng.uniform(0.3, 6.0, size=(48, 64))
    depth[5:10, 5:20] = 0.0
    return depth


def decoded_frame(
    depth: np.ndarray, masks: list[np.ndarray], depth_encoding: Literal["png16", "f32"] = "png16"
) -> Frame:
    """The frame the service decodes from what the client encodes."""
    detections = [detection("mug", 0.9, m, embedding=[1.0, 2.0]) for m in masks]
    frame = build_frame("f1", 1.5, depth, CAMERA, TILTED, detections, depth_encoding=depth_encoding)
    return decode_batch(build_batch("b1", [frame])).frames[0]


def test_float_metres_as_png16_decode_within_half_a_millimetre() -> None:
    depth = sample_depth()
    depth[0, 0], depth[0, 1], depth[0, 2] = np.nan, np.inf, 0.0002  # no return, no return, tiny
    frame = decode_batch(build_batch("b", [build_frame("f", 0.0, depth, CAMERA, TILTED)])).frames[0]
    finite = np.where(np.isfinite(depth), depth, 0.0)
    assert frame.depth.dtype == np.float32 and frame.depth.shape == (48, 64)
    assert frame.depth[0, 0] == 0 and frame.depth[0, 1] == 0 and frame.depth[0, 2] == 0.001
    rest = np.ones_like(depth, dtype=bool)
    rest[0, :3] = False
    assert np.abs(frame.depth[rest] - finite[rest]).max() <= 0.0005 + 1e-6
    assert np.array_equal(frame.depth[rest] == 0, finite[rest] == 0)
    np.testing.assert_array_equal(frame.pose, TILTED)
    assert frame.intrinsics.fx == 50.0 and frame.timestamp == 0.0


def test_uint16_millimetres_are_sent_as_they_are() -> None:
    millimetres = (sample_depth() * 1000).astype(np.uint16)
    millimetres[0, 0] = 65535
    encoded = encode_depth_png16(millimetres)
    assert encoded.encoding == "png16" and encoded.scale == 0.001
    frame = decode_batch(build_batch("b", [build_frame("f", 0.0, millimetres, CAMERA, TILTED)]))
    expected = (millimetres.astype(np.float64) * 0.001).astype(np.float32)
    np.testing.assert_array_equal(frame.frames[0].depth, expected)
    # Another unit: tenths of millimetres.
    tenths = encode_depth_png16(millimetres, scale=0.0001)
    assert tenths.scale == 0.0001


def test_f32_depth_is_exact() -> None:
    depth = sample_depth().astype(np.float32)
    assert encode_depth_f32(depth).encoding == "f32"
    frame = decoded_frame(depth, [], depth_encoding="f32")
    np.testing.assert_array_equal(frame.depth, depth)


def test_bad_depth_is_refused_before_sending() -> None:
    with pytest.raises(ValueError, match="negative"):
        encode_depth_png16(np.full((4, 4), -1.0))
    with pytest.raises(ValueError, match="uint16"):
        encode_depth_png16(np.ones((4, 4), dtype=np.int32))
    with pytest.raises(ValueError, match="2-D"):
        encode_depth_png16(np.ones((4, 4, 1)))
    with pytest.raises(ValueError, match="4x4"):
        build_frame("f", 0.0, np.ones((48, 64)), CAMERA, np.eye(3))


def test_masks_decode_to_the_same_pixels_compressed_or_not() -> None:
    mask = np.zeros((48, 64), dtype=bool)
    mask[10:30, 7:40] = True
    mask[0, 0] = mask[47, 63] = True
    frame = decoded_frame(sample_depth(), [mask])
    decoded = frame.detections[0]
    np.testing.assert_array_equal(decoded.mask.to_array(), mask)
    np.testing.assert_array_equal(decoded.embedding, [1.0, 2.0])
    plain = encode_mask(mask, compressed=False)
    assert isinstance(plain.counts, list) and sum(plain.counts) == 48 * 64
    compressed = encode_mask(mask).counts
    assert isinstance(compressed, str)
    assert plain.counts == compressed_rle_counts(compressed).tolist()


# pycocotools 2.0.11's encode trips numpy 2's __array__ copy-keyword deprecation; harmless here.
@pytest.mark.filterwarnings("ignore:__array__ implementation:DeprecationWarning")
@settings(max_examples=150, deadline=None)
@given(
    hnp.arrays(
        bool,
        st.tuples(st.integers(1, 40), st.integers(1, 40)),
        elements=st.booleans(),
    ),
    st.integers(0, 3),
)
def test_rle_is_pycocotools_byte_for_byte(mask: np.ndarray, grow: int) -> None:
    # Blocks as well as noise: long runs need multi-character values and negative deltas.
    mask = np.kron(mask, np.ones((1 + grow * 7, 1 + grow * 5), dtype=bool))
    ours = encode_mask(mask)
    reference = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    assert ours.size == [int(side) for side in reference["size"]]
    assert ours.counts == reference["counts"].decode("ascii")
    runs = rle_runs(mask)
    assert int(runs.sum()) == mask.size
    np.testing.assert_array_equal(compressed_rle_counts(rle_string(runs)), runs)


@pytest.mark.filterwarnings("ignore:__array__ implementation:DeprecationWarning")
def test_rle_of_a_large_mask_holds_long_runs() -> None:
    mask = np.zeros((2400, 1000), dtype=bool)
    mask[100:, 5:] = True  # runs of about 2.4 million pixels: six characters each
    reference = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    assert encode_mask(mask).counts == reference["counts"].decode("ascii")
    assert rle_string([0]) == "0" and rle_runs(np.ones((2, 2))).tolist() == [0, 4]
