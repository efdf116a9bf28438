"""Frames and detections as the wire's batch request (`api_schema.requests`).

Depth goes as a 16-bit PNG (`png16`: value x scale = metres), masks as COCO compressed RLE
(column-major runs, starting with a run of zeros), both by the typed client's encoders.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence

import numpy as np

from api_schema.requests import BatchIn, DepthImage, DetectionIn, FrameIn
from ingest.detectors import Detection
from ingest.frames import SourceFrame
from pbdag_client.encoding import encode_depth_png16, encode_mask

FLOAT_DEPTH_SCALE = 0.001  # float depth is sent in millimetres: a Kinect's noise is larger


def encode_depth(frame: SourceFrame) -> DepthImage:
    """The frame's depth as png16: uint16 depth as it is, float metres rounded to millimetres."""
    if frame.depth.dtype == np.uint16:
        return encode_depth_png16(frame.depth, scale=frame.depth_scale)
    return encode_depth_png16(frame.depth_metres(), scale=FLOAT_DEPTH_SCALE)


def detection_in(detection: Detection) -> DetectionIn:
    """One detection on the wire."""
    return DetectionIn(
        label=detection.label,
        score=float(detection.score),
        kind=detection.kind,
        mask=encode_mask(detection.mask),
        embedding=None
        if detection.embedding is None
        else [float(value) for value in detection.embedding],
    )


def frame_in(frame: SourceFrame, detections: Sequence[Detection]) -> FrameIn:
    """One posed depth frame with its detections on the wire."""
    intrinsics = frame.intrinsics
    return FrameIn(
        frame_id=frame.frame_id,
        timestamp=float(frame.timestamp),
        intrinsics=intrinsics.wire(),
        pose=[[float(value) for value in row] for row in np.asarray(frame.pose, dtype=np.float64)],
        depth=encode_depth(frame),
        detections=[detection_in(detection) for detection in detections],
    )


def batches(frames: Iterable[FrameIn], prefix: str, frames_per_batch: int) -> Iterator[BatchIn]:
    """Group frames into batches with ids `prefix-000000`, `prefix-000001`...: the same recording
    ingested again with the same options gives the same batches, which the service accepts once."""
    pending: list[FrameIn] = []
    number = 0
    for frame in frames:
        pending.append(frame)
        if len(pending) == frames_per_batch:
            yield BatchIn(batch_id=f"{prefix}-{number:06d}", frames=pending)
            number += 1
            pending = []
    if pending:
        yield BatchIn(batch_id=f"{prefix}-{number:06d}", frames=pending)
