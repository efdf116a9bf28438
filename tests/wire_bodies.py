"""Valid wire bodies of batches and frames (png16 depth, COCO masks, a rigid pose) for the tests
that post or decode them.
"""

from __future__ import annotations

import base64
import io
from typing import Any

import numpy as np
import numpy.typing as npt
from PIL import Image
from pycocotools import mask as coco_mask

HEIGHT, WIDTH = 48, 64


def png_base64(pixels: npt.NDArray[Any], image_format: str = "PNG") -> str:
    """Encode an array with Pillow (uint16 -> 16-bit grayscale) and base64 it."""
    buffer = io.BytesIO()
    Image.fromarray(pixels).save(buffer, format=image_format)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def f32_base64(metres: npt.NDArray[np.float32]) -> str:
    """Little-endian float32, row-major, base64."""
    return base64.b64encode(metres.astype("<f4").tobytes()).decode("ascii")


def rle_of(mask: npt.NDArray[np.bool_]) -> dict[str, Any]:
    """COCO compressed RLE of a boolean mask, as a client would post it."""
    encoded = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(s) for s in encoded["size"]], "counts": encoded["counts"].decode("ascii")}


def uncompressed_rle_of(mask: npt.NDArray[np.bool_]) -> dict[str, Any]:
    """COCO uncompressed RLE (list of ints, column-major, starting with a run of zeros)."""
    column_major = mask.T.ravel().astype(np.int8)
    change_points = np.flatnonzero(np.diff(column_major)) + 1
    boundaries = np.concatenate(([0], change_points, [column_major.size]))
    runs = np.diff(boundaries).tolist()
    if column_major[0]:
        runs = [0, *runs]
    return {"size": list(mask.shape), "counts": runs}


def sample_depth_mm() -> npt.NDArray[np.uint16]:
    """A depth ramp in millimetres with a block of invalid (0) pixels."""
    depth = (500 + np.arange(HEIGHT * WIDTH) % 4000).astype(np.uint16).reshape(HEIGHT, WIDTH)
    depth[:5, :7] = 0
    return depth


def sample_masks() -> list[npt.NDArray[np.bool_]]:
    """Two masks: a box, and a diagonal band touching the first pixel."""
    box = np.zeros((HEIGHT, WIDTH), dtype=bool)
    box[10:30, 20:50] = True
    rows, cols = np.indices((HEIGHT, WIDTH))
    band = np.abs(rows - cols) < 3
    return [box, band]


def sample_pose() -> list[list[float]]:
    """A rigid pose: 30 degrees about z plus a translation."""
    angle = np.deg2rad(30.0)
    pose = np.eye(4)
    pose[:2, :2] = [[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]]
    pose[:3, 3] = [1.5, -0.25, 0.8]
    return pose.tolist()


def frame_body(frame_id: str = "f0") -> dict[str, Any]:
    """One valid wire frame with a png16 depth and two detections."""
    box, band = sample_masks()
    return {
        "frame_id": frame_id,
        "timestamp": 12.5,
        "intrinsics": {
            "width": WIDTH,
            "height": HEIGHT,
            "fx": 50.0,
            "fy": 51.0,
            "cx": 31.5,
            "cy": 23.5,
        },
        "pose": sample_pose(),
        "depth": {"encoding": "png16", "scale": 0.001, "data": png_base64(sample_depth_mm())},
        "detections": [
            {
                "label": "mug",
                "score": 0.93,
                "kind": "object",
                "mask": rle_of(box),
                "embedding": [0.1, 0.2, -0.3],
                "class_scores": {"mug": 0.93, "cup": 0.05},
            },
            {"label": "table", "score": 0.6, "kind": "fixture", "mask": uncompressed_rle_of(band)},
        ],
    }


def batch_body(*frames: dict[str, Any]) -> dict[str, Any]:
    """A valid wire batch (one frame unless frames are given)."""
    return {"batch_id": "robot-1:batch.0001", "frames": list(frames) or [frame_body()]}
