"""Wire -> domain: decode a validated `BatchIn` (or an inspection's frames) into
`core.observation` arrays; any content that cannot be decoded or is not physical raises
`InvalidObservation` naming the field."""

from __future__ import annotations

import base64
import binascii
import io
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from PIL import Image

from api_schema import BatchIn, DepthImage, DetectionIn, FrameIn, RleMask
from codec.rle import compressed_rle_counts
from core.masks import Mask
from core.observation import Batch, Detection, Frame, Intrinsics
from pbdag_errors import Refused

SIXTEEN_BIT_PNG_MODES = frozenset({"I;16", "I;16B", "I"})
# Tolerances of the rigid-pose check: float32 round trips on the client stay well inside them.
POSE_LAST_ROW_ATOL = 1e-6
# Real pose sources (SLAM, 7-Scenes ground truth) drift from orthonormal by ~1e-4; a scale or
# shear error is orders of magnitude larger.
ROTATION_ATOL = 1e-3


class InvalidObservation(Refused):
    """A structurally valid observation whose content cannot be decoded or is not physical."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field}: {reason}", field)
        self.reason = reason


@dataclass(frozen=True)
class InputLimits:
    """What one request may ask the service to decode; the settings say (PBDAG_MAX_*)."""

    max_frames_per_batch: int = 16
    max_detections_per_frame: int = 256
    max_image_pixels: int = 2_400_000  # 1920 x 1200 fits
    max_embedding_length: int = 4096
    max_class_scores: int = 64
    max_label_length: int = 100
    # The pixels all masks of a batch cover together: grounding works in proportion to them.
    max_mask_pixels_per_batch: int = 40_000_000


# A camera pose further than this from the world origin is a unit or frame error (voxel keys
# also hold +-52 km only).
MAX_POSE_TRANSLATION_M = 10_000.0


def decode_batch(
    batch: BatchIn,
    limits: InputLimits | None = None,
    depth_bytes: Mapping[int, bytes] | None = None,
) -> Batch:
    """Decode every frame of a batch; raise `InvalidObservation` on the first bad field.
    `depth_bytes`: frames whose depth is given as its bytes, by index, instead of the base64 of
    their `depth.data` (a stored batch, `service.store.raw_batches.raw_batch_parts`)."""
    frames = decode_frames(batch.frames, "frames", limits, depth_bytes)
    return Batch(batch_id=batch.batch_id, frames=frames)


def decode_frames(
    frames: list[FrameIn],
    path: str = "frames",
    limits: InputLimits | None = None,
    depth_bytes: Mapping[int, bytes] | None = None,
) -> tuple[Frame, ...]:
    """Decode a list of frames (a batch, an inspection's views); the error names the field.

    Every limit is checked before anything is decoded, so a request over a limit costs nothing.
    """
    limits = limits or InputLimits()
    if len(frames) > limits.max_frames_per_batch:
        raise InvalidObservation(
            path,
            f"has {len(frames)} frames; the limit is {limits.max_frames_per_batch} "
            "(PBDAG_MAX_FRAMES_PER_BATCH)",
        )
    for index, frame in enumerate(frames):
        _check_limits(frame, f"{path}[{index}]", limits)
    decoded = []
    covered = 0
    for index, frame in enumerate(frames):
        raw = None if depth_bytes is None else depth_bytes.get(index)
        decoded.append(_decode_frame(frame, f"{path}[{index}]", raw))
        for number, detection in enumerate(decoded[-1].detections):
            covered += detection.mask.area
            if covered > limits.max_mask_pixels_per_batch:
                raise InvalidObservation(
                    f"{path}[{index}].detections[{number}].mask",
                    f"the masks of the batch cover more than {limits.max_mask_pixels_per_batch} "
                    "pixels together (PBDAG_MAX_MASK_PIXELS_PER_BATCH)",
                )
    return tuple(decoded)


def _check_limits(frame: FrameIn, path: str, limits: InputLimits) -> None:
    """Sizes and physical ranges of one frame, before any decoding."""
    intrinsics = frame.intrinsics
    pixels = intrinsics.width * intrinsics.height
    if pixels > limits.max_image_pixels:
        raise InvalidObservation(
            f"{path}.intrinsics",
            f"a {intrinsics.width} x {intrinsics.height} image has {pixels} pixels; the limit is "
            f"{limits.max_image_pixels} (PBDAG_MAX_IMAGE_PIXELS)",
        )
    for name, value, side in (
        ("cx", intrinsics.cx, intrinsics.width),
        ("cy", intrinsics.cy, intrinsics.height),
    ):
        if not -side <= value <= 2 * side:
            raise InvalidObservation(
                f"{path}.intrinsics.{name}",
                f"principal point {value} is more than an image size outside the image",
            )
    translation = max(abs(frame.pose[row][3]) for row in range(3))
    if math.isfinite(translation) and translation > MAX_POSE_TRANSLATION_M:  # NaN: see _decode_pose
        raise InvalidObservation(
            f"{path}.pose",
            f"translation {translation:g} m is beyond {MAX_POSE_TRANSLATION_M:g} m of the origin",
        )
    if len(frame.detections) > limits.max_detections_per_frame:
        raise InvalidObservation(
            f"{path}.detections",
            f"has {len(frame.detections)} detections; the limit is "
            f"{limits.max_detections_per_frame} (PBDAG_MAX_DETECTIONS_PER_FRAME)",
        )
    for index, detection in enumerate(frame.detections):
        where = f"{path}.detections[{index}]"
        labels = [detection.label, *(detection.class_scores or {})]
        if max(len(label) for label in labels) > limits.max_label_length:
            raise InvalidObservation(
                f"{where}.label"
                if len(detection.label) > limits.max_label_length
                else f"{where}.class_scores",
                f"labels have at most {limits.max_label_length} characters (PBDAG_MAX_LABEL_LENGTH)",
            )
        if (
            detection.embedding is not None
            and len(detection.embedding) > limits.max_embedding_length
        ):
            raise InvalidObservation(
                f"{where}.embedding",
                f"has {len(detection.embedding)} values; the limit is "
                f"{limits.max_embedding_length} (PBDAG_MAX_EMBEDDING_LENGTH)",
            )
        if (
            detection.class_scores is not None
            and len(detection.class_scores) > limits.max_class_scores
        ):
            raise InvalidObservation(
                f"{where}.class_scores",
                f"has {len(detection.class_scores)} entries; the limit is "
                f"{limits.max_class_scores} (PBDAG_MAX_CLASS_SCORES)",
            )


def _decode_frame(frame: FrameIn, path: str, depth_bytes: bytes | None = None) -> Frame:
    """Decode one frame: pose, depth, then each detection against the depth size."""
    intrinsics = Intrinsics(**frame.intrinsics.model_dump())
    pose = _decode_pose(frame.pose, f"{path}.pose")
    shape = (intrinsics.height, intrinsics.width)
    depth = _decode_depth(frame.depth, shape, f"{path}.depth", depth_bytes)
    detections = tuple(
        _decode_detection(detection, depth.shape, f"{path}.detections[{index}]")
        for index, detection in enumerate(frame.detections)
    )
    return Frame(
        frame_id=frame.frame_id,
        timestamp=frame.timestamp,
        intrinsics=intrinsics,
        pose=pose,
        depth=depth,
        detections=detections,
    )


def _decode_pose(rows: list[list[float]], path: str) -> npt.NDArray[np.float64]:
    """Check that the 4x4 matrix is a finite rigid transform (rotation + translation)."""
    try:
        pose = np.array(rows, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise InvalidObservation(path, "must be a 4x4 matrix of numbers") from error
    if pose.shape != (4, 4):
        raise InvalidObservation(path, f"must be a 4x4 matrix, got shape {list(pose.shape)}")
    if not np.isfinite(pose).all():
        raise InvalidObservation(path, "contains NaN or infinite values")
    if not np.allclose(pose[3], (0.0, 0.0, 0.0, 1.0), rtol=0.0, atol=POSE_LAST_ROW_ATOL):
        raise InvalidObservation(path, f"last row must be [0, 0, 0, 1], got {pose[3].tolist()}")
    rotation = pose[:3, :3]
    orthonormality_error = float(np.abs(rotation.T @ rotation - np.eye(3)).max())
    if orthonormality_error > ROTATION_ATOL:
        raise InvalidObservation(
            path,
            "rotation part is not orthonormal "
            f"(max |R^T R - I| = {orthonormality_error:.3g}, tolerance {ROTATION_ATOL:g})",
        )
    determinant = float(np.linalg.det(rotation))
    if abs(determinant - 1.0) > ROTATION_ATOL:
        raise InvalidObservation(
            path,
            f"rotation part has determinant {determinant:.6g}, expected +1 (not a reflection)",
        )
    return pose


def _decode_depth(
    depth: DepthImage, expected_shape: tuple[int, int], path: str, raw: bytes | None = None
) -> npt.NDArray[np.float32]:
    """Decode depth to float32 metres with 0 marking invalid pixels (from `raw`, its bytes,
    when given, else from the base64 of `depth.data`)."""
    if raw is None:
        raw = _decode_base64(depth.data, f"{path}.data")
    if depth.encoding == "png16":
        metres = _decode_png16(raw, depth.scale, expected_shape, path)
    else:
        metres = _decode_f32(raw, expected_shape, path)
    # NaN/inf mean "no measurement" on many sensors; the domain marks those pixels with 0.
    metres[~np.isfinite(metres)] = 0.0
    if (metres < 0).any():
        raise InvalidObservation(f"{path}.data", "depth contains negative values")
    return metres


def _decode_base64(data: str, path: str) -> bytes:
    """Strict base64 decode: any character outside the alphabet is an error, not skipped."""
    try:
        return base64.b64decode(data, validate=True)
    except (binascii.Error, ValueError) as error:
        raise InvalidObservation(path, f"is not valid base64 ({error})") from error


def _decode_png16(
    raw: bytes, scale: float, expected_shape: tuple[int, int], path: str
) -> npt.NDArray[np.float32]:
    """Decode a 16-bit single-channel PNG and scale it to metres."""
    try:
        image = Image.open(io.BytesIO(raw), formats=["PNG"])
    # Pillow reports malformed input through many exception types; all mean "not a PNG".
    except Exception as error:
        raise InvalidObservation(f"{path}.data", "is not a PNG image") from error
    with image:
        if image.mode not in SIXTEEN_BIT_PNG_MODES:
            raise InvalidObservation(
                f"{path}.data",
                f"PNG must be 16-bit single channel, got Pillow mode {image.mode!r}",
            )
        # Compare the header size before decoding pixels, so a huge PNG costs nothing.
        height_width = (image.height, image.width)
        if height_width != expected_shape:
            raise InvalidObservation(
                f"{path}.data",
                f"depth size [height, width] = {list(height_width)} does not match "
                f"the intrinsics {list(expected_shape)}",
            )
        try:
            pixels = np.asarray(image)
        except Exception as error:
            raise InvalidObservation(f"{path}.data", f"PNG is corrupt ({error})") from error
    if pixels.shape != expected_shape:
        raise InvalidObservation(f"{path}.data", "PNG must have a single channel")
    # float64 for the product keeps mm -> m exact to float32 rounding.
    return (pixels.astype(np.float64) * scale).astype(np.float32)


def _decode_f32(raw: bytes, expected_shape: tuple[int, int], path: str) -> npt.NDArray[np.float32]:
    """Read little-endian float32 metres, row-major."""
    height, width = expected_shape
    expected_bytes = height * width * 4
    if len(raw) != expected_bytes:
        raise InvalidObservation(
            f"{path}.data",
            f"f32 depth must be exactly height x width x 4 = {expected_bytes} bytes, "
            f"got {len(raw)}",
        )
    return np.frombuffer(raw, dtype="<f4").reshape(expected_shape).astype(np.float32)


def _decode_detection(detection: DetectionIn, depth_shape: tuple[int, ...], path: str) -> Detection:
    """Decode a detection's mask and embedding."""
    mask = _decode_mask(detection.mask, depth_shape, f"{path}.mask")
    embedding = None
    if detection.embedding is not None:
        embedding = np.asarray(detection.embedding, dtype=np.float64)
        if not np.isfinite(embedding).all():
            raise InvalidObservation(f"{path}.embedding", "contains NaN or infinite values")
    class_scores = None if detection.class_scores is None else dict(detection.class_scores)
    return Detection(
        label=detection.label,
        score=detection.score,
        kind=detection.kind,
        mask=mask,
        embedding=embedding,
        class_scores=class_scores,
    )


def _decode_mask(rle: RleMask, depth_shape: tuple[int, ...], path: str) -> Mask:
    """Validate a COCO RLE mask of exactly the depth size; its pixels are decoded later, lazily."""
    height, width = rle.size
    if (height, width) != depth_shape:
        raise InvalidObservation(
            f"{path}.size",
            f"mask size {[height, width]} does not match the depth size {list(depth_shape)}",
        )
    pixels = height * width
    if isinstance(rle.counts, str):
        try:
            runs = compressed_rle_counts(rle.counts)
        except ValueError as error:
            raise InvalidObservation(f"{path}.counts", str(error)) from error
        # Each value holds at most 30 bits, so runs (and their int64 sum) cannot wrap round.
        total = int(runs.sum())
        too_long = runs.size > pixels + 1
    else:
        # Python ints: a hostile run of 2**62 must not wrap an int64 sum round to height x width.
        too_long = len(rle.counts) > pixels + 1
        total = sum(rle.counts) if not too_long else -1
        runs = np.asarray(rle.counts, dtype=np.int64) if total == pixels else np.zeros(0, np.int64)
    if too_long:
        raise InvalidObservation(f"{path}.counts", f"has more runs than the {pixels} pixels")
    # A short RLE does not say what the remaining pixels are (pycocotools.mask.decode fills
    # them with uninitialized memory), so the total must be exact.
    if total != pixels:
        raise InvalidObservation(
            f"{path}.counts",
            f"run lengths sum to {total}, expected height x width = {pixels}",
        )
    return Mask(height, width, runs)
