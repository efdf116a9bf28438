"""Simulator outputs in the service's JSON wire format, through the client's encoders
(`pbdag_client.encoding`): the dictionaries are the client's request models, dumped."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import numpy as np

from api_schema import DetectionIn
from pbdag_client import encoding
from sim.camera import CameraModel
from sim.detector import SimDetection


def encode_depth_png16(depth: np.ndarray, scale: float = 0.001) -> dict[str, Any]:
    """Depth as a 16-bit grayscale PNG of round(metres / scale); 0 stays 0 (no return)."""
    return encoding.encode_depth_png16(depth, scale).model_dump()


def encode_depth_f32(depth: np.ndarray) -> dict[str, Any]:
    """Depth as base64 of little-endian float32 metres, row-major."""
    return encoding.encode_depth_f32(depth).model_dump(exclude_unset=True)


def encode_mask(mask: np.ndarray) -> dict[str, Any]:
    """Boolean mask as COCO compressed RLE: {"size": [h, w], "counts": str}."""
    return encoding.encode_mask(mask).model_dump()


def encode_detection(detection: SimDetection) -> dict[str, Any]:
    """One detection on the wire; the ground-truth object id stays on the robot's side."""
    return _detection(detection).model_dump(exclude_none=True)


def _detection(detection: SimDetection) -> DetectionIn:
    return encoding.detection(
        detection.label,
        detection.score,
        detection.mask,
        kind="fixture" if detection.kind == "fixture" else "object",
        embedding=detection.embedding,
        class_scores=detection.class_scores,
    )


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
    if depth_encoding not in ("png16", "f32"):
        raise ValueError(f"unknown depth encoding {depth_encoding!r}")
    chosen: Literal["png16", "f32"] = "png16" if depth_encoding == "png16" else "f32"
    frame = encoding.build_frame(
        frame_id,
        timestamp,
        depth,
        camera.intrinsics_dict(),
        pose,
        [_detection(d) for d in detections],
        depth_encoding=chosen,
    )
    # Unset defaults (the scale of f32 depth) and absent options stay off the wire.
    return frame.model_dump(exclude_none=True, exclude_unset=True)


def make_batch(batch_id: str, frames: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """A batch of encoded frames under a client-chosen idempotency key."""
    return {"batch_id": batch_id, "frames": list(frames)}
