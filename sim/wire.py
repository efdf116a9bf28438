"""Encoders from simulator outputs to the service's JSON wire format for observation batches."""

from __future__ import annotations

import base64
import io
from collections.abc import Sequence
from typing import Any

import numpy as np
from PIL import Image
from pycocotools import mask as coco_mask

from sim.camera import CameraModel
from sim.detector import SimDetection

UINT16_MAX = np.iinfo(np.uint16).max


def _base64(raw: bytes) -> str:
    """ASCII base64 text of raw bytes."""
    return base64.b64encode(raw).decode("ascii")


def encode_depth_png16(depth: np.ndarray, scale: float = 0.001) -> dict[str, Any]:
    """Depth as a 16-bit grayscale PNG of round(metres / scale); 0 stays 0 (no return)."""
    steps = np.rint(np.asarray(depth, dtype=np.float64) / scale)
    # A valid depth too small to survive rounding would read back as "no return"; keep it valid.
    steps[(depth > 0) & (steps < 1)] = 1
    counts = np.clip(steps, 0, UINT16_MAX).astype(np.uint16)
    buffer = io.BytesIO()
    # compress_level 1: the service decodes either way, and level 6 costs several ms per frame.
    Image.fromarray(counts).save(buffer, format="PNG", compress_level=1)
    return {"encoding": "png16", "scale": scale, "data": _base64(buffer.getvalue())}


def encode_depth_f32(depth: np.ndarray) -> dict[str, Any]:
    """Depth as base64 of little-endian float32 metres, row-major."""
    little_endian = np.ascontiguousarray(depth, dtype="<f4")
    return {"encoding": "f32", "data": _base64(little_endian.tobytes(order="C"))}


def encode_mask(mask: np.ndarray) -> dict[str, Any]:
    """Boolean mask as COCO compressed RLE: {"size": [h, w], "counts": str}."""
    rle = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    height, width = (int(extent) for extent in rle["size"])
    return {"size": [height, width], "counts": rle["counts"].decode("ascii")}


def encode_detection(detection: SimDetection) -> dict[str, Any]:
    """One detection on the wire; the ground-truth object id stays on the robot's side."""
    encoded: dict[str, Any] = {
        "label": detection.label,
        "score": float(detection.score),
        "kind": detection.kind,
        "mask": encode_mask(detection.mask),
    }
    if detection.embedding is not None:
        encoded["embedding"] = [float(component) for component in detection.embedding]
    if detection.class_scores is not None:
        encoded["class_scores"] = {
            str(label): float(score) for label, score in detection.class_scores.items()
        }
    return encoded


def make_frame(
    frame_id: str,
    timestamp: float,
    camera: CameraModel,
    pose: np.ndarray,
    depth: np.ndarray,
    detections: Sequence[SimDetection],
    depth_encoding: str = "png16",
) -> dict[str, Any]:
    """One posed depth frame with its detections, as the service's batch endpoint expects it."""
    if depth_encoding == "png16":
        encoded_depth = encode_depth_png16(depth)
    elif depth_encoding == "f32":
        encoded_depth = encode_depth_f32(depth)
    else:
        raise ValueError(f"unknown depth encoding {depth_encoding!r}")
    return {
        "frame_id": frame_id,
        "timestamp": float(timestamp),
        "intrinsics": camera.intrinsics_dict(),
        "pose": [[float(value) for value in row] for row in np.asarray(pose, dtype=np.float64)],
        "depth": encoded_depth,
        "detections": [encode_detection(detection) for detection in detections],
    }


def make_batch(batch_id: str, frames: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """A batch of encoded frames under a client-chosen idempotency key."""
    return {"batch_id": batch_id, "frames": list(frames)}
