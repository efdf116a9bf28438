"""Frames and detections as the wire's batch request (`api_schema.requests`).

Depth goes as a 16-bit PNG (`png16`: value x scale = metres), masks as COCO compressed RLE
(column-major runs, starting with a run of zeros), both encoded with numpy and Pillow.
"""

from __future__ import annotations

import base64
import io
from collections.abc import Iterable, Iterator, Sequence

import numpy as np
import numpy.typing as npt
from PIL import Image

from api_schema.requests import BatchIn, DepthImage, DetectionIn, FrameIn, Intrinsics, RleMask
from ingest.detectors import Detection
from ingest.frames import SourceFrame

UINT16_MAX = int(np.iinfo(np.uint16).max)
FLOAT_DEPTH_SCALE = 0.001  # float depth is sent in millimetres: a Kinect's noise is larger


def encode_depth(frame: SourceFrame) -> DepthImage:
    """The frame's depth as png16: uint16 depth as it is, float metres rounded to millimetres."""
    if frame.depth.dtype == np.uint16:
        counts = np.asarray(frame.depth, dtype=np.uint16)
        scale = frame.depth_scale
    else:
        metres = frame.depth_metres().astype(np.float64)
        steps = np.rint(metres / FLOAT_DEPTH_SCALE)
        steps[(metres > 0) & (steps < 1)] = 1  # a tiny valid depth must not read back as invalid
        counts = np.clip(steps, 0, UINT16_MAX).astype(np.uint16)
        scale = FLOAT_DEPTH_SCALE
    buffer = io.BytesIO()
    # compress_level 1: several times faster than the default for a few percent more bytes.
    Image.fromarray(counts).save(buffer, format="PNG", compress_level=1)
    return DepthImage(
        encoding="png16", scale=scale, data=base64.b64encode(buffer.getvalue()).decode("ascii")
    )


def rle_runs(mask: npt.NDArray[np.bool_]) -> list[int]:
    """COCO run lengths of a mask: column-major, alternating zeros and ones, zeros first."""
    column_major = np.asarray(mask, dtype=bool).T.ravel()
    changes = np.flatnonzero(column_major[1:] != column_major[:-1]) + 1
    bounds = np.concatenate(([0], changes, [column_major.size]))
    runs = np.diff(bounds).tolist()
    return [0, *runs] if column_major.size and column_major[0] else runs


def compress_runs(runs: Sequence[int]) -> str:
    """COCO's compressed RLE string of run lengths (pycocotools' `rleToString`)."""
    characters = []
    for index, run in enumerate(runs):
        # From the fourth value on, each is stored as a delta to the value two places back.
        value = run - runs[index - 2] if index > 2 else run
        more = True
        while more:
            group = value & 0x1F
            value >>= 5  # arithmetic shift, as in C for a signed long
            more = value != -1 if group & 0x10 else value != 0
            if more:
                group |= 0x20
            characters.append(chr(group + 48))
    return "".join(characters)


def encode_mask(mask: npt.NDArray[np.bool_]) -> RleMask:
    """A boolean mask as compressed COCO RLE."""
    height, width = mask.shape
    return RleMask(size=[height, width], counts=compress_runs(rle_runs(mask)))


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
        intrinsics=Intrinsics(
            width=intrinsics.width,
            height=intrinsics.height,
            fx=float(intrinsics.fx),
            fy=float(intrinsics.fy),
            cx=float(intrinsics.cx),
            cy=float(intrinsics.cy),
        ),
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
