"""Numpy arrays to the wire: depth as png16 or f32, masks as COCO RLE, frames and batches.

The RLE is pycocotools' format (column-major runs starting with background, and its compressed
string form), written with numpy alone so that a robot needs no evaluation stack to post.
"""

from __future__ import annotations

import base64
import io
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from PIL import Image

from api_schema import BatchIn, DepthImage, DetectionIn, FrameIn, Intrinsics, RleMask

__all__ = [
    "build_batch",
    "build_frame",
    "detection",
    "encode_depth_f32",
    "encode_depth_png16",
    "encode_mask",
    "rle_runs",
    "rle_string",
]

UINT16_MAX = int(np.iinfo(np.uint16).max)
# Characters of COCO's compressed RLE: 5 value bits and a continuation bit per character,
# offset into printable ASCII from '0'.
_RLE_FIRST_CHAR = 48
_RLE_MORE = 0x20
_RLE_VALUE_BITS = 5
_RLE_MAX_GROUPS = 7  # 35 bits: any run of any image the wire accepts


def _base64(raw: bytes) -> str:
    return base64.b64encode(raw).decode("ascii")


def encode_depth_png16(depth: npt.ArrayLike, scale: float = 0.001) -> DepthImage:
    """Depth as a 16-bit PNG: a uint16 array is taken as is (units of `scale` metres, e.g.
    millimetres from a Kinect or RealSense); a float array is metres, rounded to `scale` steps.

    Float depth: 0, NaN and infinities are "no return" (0); a positive depth too small to
    survive rounding stays valid (1 step); depth beyond 65535 steps is clipped; a negative
    depth is a ValueError.
    """
    array = np.asarray(depth)
    if array.ndim != 2:
        raise ValueError(f"depth must be a 2-D image, got shape {list(array.shape)}")
    if array.dtype == np.uint16:
        steps = array
    elif np.issubdtype(array.dtype, np.integer):
        raise ValueError(
            f"integer depth must be uint16 (units of scale), got {array.dtype}; "
            "pass metres as floats"
        )
    else:
        metres = array.astype(np.float64)
        valid = np.isfinite(metres)
        metres = np.where(valid, metres, 0.0)
        if (metres < 0).any():
            raise ValueError("depth contains negative values")
        rounded = np.rint(metres / scale)
        rounded[(metres > 0) & (rounded < 1)] = 1
        steps = np.clip(rounded, 0, UINT16_MAX).astype(np.uint16)
    buffer = io.BytesIO()
    # compress_level 1: the service decodes either way, and level 6 costs several ms per frame.
    Image.fromarray(np.ascontiguousarray(steps)).save(buffer, format="PNG", compress_level=1)
    return DepthImage(encoding="png16", scale=scale, data=_base64(buffer.getvalue()))


def encode_depth_f32(depth: npt.ArrayLike) -> DepthImage:
    """Depth as base64 of little-endian float32 metres, row-major (0 or NaN: no return)."""
    array = np.asarray(depth)
    if array.ndim != 2:
        raise ValueError(f"depth must be a 2-D image, got shape {list(array.shape)}")
    little_endian = np.ascontiguousarray(array, dtype="<f4")
    return DepthImage(encoding="f32", data=_base64(little_endian.tobytes(order="C")))


def rle_runs(mask: npt.ArrayLike) -> npt.NDArray[np.int64]:
    """COCO's uncompressed RLE of a 2-D mask: alternating background and foreground run lengths
    over the pixels in column-major order, starting with background (possibly 0)."""
    array = np.asarray(mask)
    if array.ndim != 2 or array.size == 0:
        raise ValueError(f"a mask must be a non-empty 2-D array, got shape {list(array.shape)}")
    flat = array.astype(bool).ravel(order="F")
    changes = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    bounds = np.concatenate(([0], changes, [flat.size]))
    runs = np.diff(bounds).astype(np.int64)
    if flat[0]:
        runs = np.concatenate(([0], runs))
    return runs


def rle_string(runs: npt.ArrayLike) -> str:
    """COCO's compressed RLE string of run lengths (pycocotools' `rleToString`, vectorized).

    From the fourth run on, each is stored as the difference to the run two places back; every
    value is written in 5-bit groups, least significant first, as few as its sign allows.
    """
    counts = np.asarray(runs, dtype=np.int64)
    if counts.ndim != 1 or counts.size == 0:
        raise ValueError("run lengths must be a non-empty 1-D sequence")
    values = counts.copy()
    values[3:] = counts[3:] - counts[1:-2]
    # Groups per value: the fewest 5-bit groups that hold it in two's complement.
    groups_per_value = np.ones(values.size, dtype=np.int64)
    for groups in range(1, _RLE_MAX_GROUPS):
        half_range = 1 << (_RLE_VALUE_BITS * groups - 1)
        groups_per_value += (values < -half_range) | (values >= half_range)
    starts = np.cumsum(groups_per_value) - groups_per_value
    owner = np.repeat(np.arange(values.size), groups_per_value)
    position = np.arange(int(groups_per_value.sum())) - np.repeat(starts, groups_per_value)
    chars = (values[owner] >> (_RLE_VALUE_BITS * position)) & 0x1F
    chars |= np.where(position < groups_per_value[owner] - 1, _RLE_MORE, 0)
    return (chars + _RLE_FIRST_CHAR).astype(np.uint8).tobytes().decode("ascii")


def encode_mask(mask: npt.ArrayLike, compressed: bool = True) -> RleMask:
    """A boolean mask (height x width, the depth image's size) as COCO RLE: the compressed
    string by default, or the list of run lengths."""
    array = np.asarray(mask)
    runs = rle_runs(array)
    height, width = (int(side) for side in array.shape)
    counts: str | list[int] = rle_string(runs) if compressed else [int(r) for r in runs]
    return RleMask(size=[height, width], counts=counts)


def detection(
    label: str,
    score: float,
    mask: npt.ArrayLike,
    *,
    kind: Literal["object", "fixture"] = "object",
    embedding: npt.ArrayLike | None = None,
    class_scores: Mapping[str, float] | None = None,
) -> DetectionIn:
    """One 2D detection from a boolean mask, with optional appearance and label similarities."""
    return DetectionIn(
        label=label,
        score=float(score),
        kind=kind,
        mask=encode_mask(mask),
        embedding=None
        if embedding is None
        else [float(v) for v in np.asarray(embedding, dtype=np.float64).ravel()],
        class_scores=None
        if class_scores is None
        else {str(name): float(value) for name, value in class_scores.items()},
    )


def build_frame(
    frame_id: str,
    timestamp: float,
    depth: npt.ArrayLike,
    intrinsics: Intrinsics | Mapping[str, Any],
    pose: npt.ArrayLike,
    detections: Sequence[DetectionIn] = (),
    *,
    depth_encoding: Literal["png16", "f32"] = "png16",
    depth_scale: float = 0.001,
) -> FrameIn:
    """One posed depth frame: `pose` is the 4x4 camera-to-world transform (metres, OpenCV
    axes), `intrinsics` an `Intrinsics` or a mapping of width, height, fx, fy, cx, cy."""
    matrix = np.asarray(pose, dtype=np.float64)
    if matrix.shape != (4, 4):
        raise ValueError(f"pose must be a 4x4 matrix, got shape {list(matrix.shape)}")
    if isinstance(intrinsics, Intrinsics):
        camera = intrinsics
    else:
        camera = Intrinsics(
            width=int(intrinsics["width"]),
            height=int(intrinsics["height"]),
            fx=float(intrinsics["fx"]),
            fy=float(intrinsics["fy"]),
            cx=float(intrinsics["cx"]),
            cy=float(intrinsics["cy"]),
        )
    encoded = (
        encode_depth_png16(depth, depth_scale)
        if depth_encoding == "png16"
        else encode_depth_f32(depth)
    )
    return FrameIn(
        frame_id=frame_id,
        timestamp=float(timestamp),
        intrinsics=camera,
        pose=[[float(value) for value in row] for row in matrix],
        depth=encoded,
        detections=list(detections),
    )


def build_batch(batch_id: str, frames: Sequence[FrameIn]) -> BatchIn:
    """A batch of frames under a client-chosen idempotency key (the paper's update step t)."""
    return BatchIn(batch_id=batch_id, frames=list(frames))
