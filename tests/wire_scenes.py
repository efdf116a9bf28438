"""Wire batches of an analytic scene (no renderer): the camera of tests/core/scenes.py looks at a
wall with a 10 cm mug in front of it. Service tests post these, so they run in a service-only
install (the simulator's renderer needs the `eval` extra)."""

from __future__ import annotations

import base64
import io
from typing import Any

import numpy as np
import numpy.typing as npt
from PIL import Image
from pycocotools import mask as coco_mask

from tests.core.scenes import INTRINSICS, look_pose, paint_box, wall

MUG_CENTER = (0.0, 0.1, 2.0)  # camera frame = world frame (the pose is the identity)
MUG_SIZE = 0.1
# A fixed, unit appearance embedding: every sighting is the same mug.
MUG_EMBEDDING = [0.6, 0.8, 0.0]


def _png16(depth_m: npt.NDArray[np.float32]) -> str:
    millimetres = np.round(depth_m * 1000.0).astype(np.uint16)
    buffer = io.BytesIO()
    Image.fromarray(millimetres).save(buffer, format="PNG")
    return base64.b64encode(buffer.getvalue()).decode()


def _rle(mask: npt.NDArray[np.bool_]) -> dict[str, Any]:
    encoded = coco_mask.encode(np.asfortranarray(mask.astype(np.uint8)))
    return {"size": [int(s) for s in encoded["size"]], "counts": encoded["counts"].decode()}


def frame(index: int, *, mug: bool = True) -> dict[str, Any]:
    """One frame: the wall, with the mug (detected) or without it (the camera sees the wall
    where the mug stood)."""
    depth = wall()
    detections = []
    if mug:
        mask = paint_box(depth, MUG_CENTER, MUG_SIZE)
        detections.append(
            {
                "label": "mug",
                "score": 0.9,
                "kind": "object",
                "mask": _rle(mask),
                "embedding": MUG_EMBEDDING,
            }
        )
    return {
        "frame_id": f"f{index:05d}",
        "timestamp": float(index),
        "intrinsics": {
            "width": INTRINSICS.width,
            "height": INTRINSICS.height,
            "fx": INTRINSICS.fx,
            "fy": INTRINSICS.fy,
            "cx": INTRINSICS.cx,
            "cy": INTRINSICS.cy,
        },
        "pose": look_pose().tolist(),
        "depth": {"encoding": "png16", "scale": 0.001, "data": _png16(depth)},
        "detections": detections,
    }


def batch(batch_id: str, index: int, *, mug: bool = True) -> dict[str, Any]:
    """A one-frame batch."""
    return {"batch_id": batch_id, "frames": [frame(index, mug=mug)]}
