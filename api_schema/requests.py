"""Request bodies of the v1 HTTP API: structural checks only (decoding lives in codec.observations)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PlainValidator,
    Strict,
    WithJsonSchema,
    field_validator,
)
from pydantic_core import PydanticCustomError

from api_schema.text import PRINTABLE as PRINTABLE  # service.deps checks queries with it
from api_schema.text import check_text

# Strict numbers: the body is JSON, so "525" or true where a number belongs is a client bug,
# not something to coerce silently. Every number is finite and inside a physical range; the
# service's configurable limits (frames, detections, pixels, lengths) come on top of these.
FiniteNumber = Annotated[float, Strict(), Field(allow_inf_nan=False)]
# 8192 px per side bounds decoding work and stays under Pillow's decompression-bomb threshold.
MAX_IMAGE_SIDE = 8192
ImageSide = Annotated[int, Strict(), Field(gt=0, le=MAX_IMAGE_SIDE)]
# Focal lengths of real cameras lie between a few tens and a few thousand pixels.
FocalLength = Annotated[float, Strict(), Field(ge=1.0, le=100_000.0, allow_inf_nan=False)]
PrincipalPoint = Annotated[float, Strict(), Field(ge=-100_000.0, le=100_000.0, allow_inf_nan=False)]
PoseRow = Annotated[list[FiniteNumber], Field(min_length=4, max_length=4)]
# Seconds; unix time in 2026 is 1.8e9.
Timestamp = Annotated[float, Strict(), Field(ge=-1e11, le=1e11, allow_inf_nan=False)]
# An appearance vector's components (CLIP/SigLIP features are small numbers).
EmbeddingValue = Annotated[float, Strict(), Field(ge=-1e6, le=1e6, allow_inf_nan=False)]
# Open-vocabulary similarities: cosines or probabilities.
Similarity = Annotated[float, Strict(), Field(ge=-1.0, le=1.0, allow_inf_nan=False)]
# Text by the rule of api_schema.text: no control characters, DEL, lone surrogates or
# non-characters. The check names the character; the pattern states the rule in the schema.
NonEmptyLabel = Annotated[
    str, Field(min_length=1, max_length=200, pattern=PRINTABLE), BeforeValidator(check_text)
]
Identifier = Annotated[str, Field(min_length=1, max_length=200, pattern=r"^[A-Za-z0-9._:-]+$")]
# Integers a JSON number carries exactly (and the databases' 64-bit integers hold).
MAX_INT = 2**53 - 1


def _check_rle_counts(value: object) -> str | list[int]:
    """Accept a compressed RLE string or a list of non-negative ints, with one plain error."""
    # A hand-written check instead of `str | list[int]`: pydantic would report union failures
    # under member tags (`counts.list[int][3]`), which are not paths a client can act on.
    if isinstance(value, str):
        return value
    if isinstance(value, list) and all(type(count) is int and count >= 0 for count in value):
        return value
    raise PydanticCustomError(
        "rle_counts",
        "counts must be a compressed COCO RLE string or a list of non-negative integers",
    )


RleCounts = Annotated[
    str | list[int],
    PlainValidator(_check_rle_counts),
    WithJsonSchema(
        {
            "anyOf": [
                {"type": "string"},
                {"type": "array", "items": {"type": "integer", "minimum": 0}},
            ]
        }
    ),
]


class BaselineRef(BaseModel):
    """A frozen baseline package of a scene."""

    model_config = ConfigDict(extra="forbid")

    scene_id: Identifier = Field(description="Scene the baseline was frozen in.")
    version: int = Field(ge=1, le=MAX_INT, description="Baseline version in that scene.")


class SceneCreate(BaseModel):
    """Body of `POST /v1/scenes`."""

    model_config = ConfigDict(extra="forbid")

    name: NonEmptyLabel = Field(description="Human-readable scene name.")
    profile: Literal["extended", "paper"] = Field(
        "extended",
        description="The method's parameter set: `extended` (the default: the paper's rules "
        "plus our extensions, each a named switch) or `paper` (every rule as the paper writes "
        "it, every extension off); `params` apply on top.",
    )
    params: dict[str, Any] | None = Field(
        None,
        description="Overrides of the profile's parameters (a partial nested object); the "
        "resolved parameters are recorded in the scene's log.",
    )
    baseline: BaselineRef | None = Field(
        None,
        description="Start a later session in the same house from this frozen baseline: its "
        "fixtures keep their canonical identities and are pinned.",
    )


class Intrinsics(BaseModel):
    """Pinhole intrinsics of one frame, in pixels."""

    model_config = ConfigDict(extra="forbid")

    width: ImageSide = Field(description="Image width in pixels.")
    height: ImageSide = Field(description="Image height in pixels.")
    fx: FocalLength = Field(description="Focal length along x, in pixels (1 to 100000).")
    fy: FocalLength = Field(description="Focal length along y, in pixels (1 to 100000).")
    cx: PrincipalPoint = Field(
        description="Principal point x, in pixels (within a width of the image)."
    )
    cy: PrincipalPoint = Field(
        description="Principal point y, in pixels (within a height of the image)."
    )


class DepthImage(BaseModel):
    """One depth image, base64-encoded."""

    model_config = ConfigDict(extra="forbid")

    encoding: Literal["png16", "f32"] = Field(
        description=(
            "`png16`: a 16-bit single-channel PNG, pixel value x scale = metres, 0 = invalid. "
            "`f32`: little-endian float32 metres, row-major, 0 or NaN = invalid."
        )
    )
    scale: Annotated[float, Strict(), Field(gt=0, le=1.0, allow_inf_nan=False)] = Field(
        default=0.001,
        description="Metres per PNG unit for `png16` (0.001 = millimetres, at most 1); "
        "ignored for `f32`.",
    )
    data: str = Field(min_length=1, description="Base64 of the PNG file or of the float32 bytes.")


class RleMask(BaseModel):
    """A binary mask in COCO run-length encoding (column-major, as pycocotools writes it)."""

    model_config = ConfigDict(extra="forbid")

    size: Annotated[list[ImageSide], Field(min_length=2, max_length=2)] = Field(
        description="[height, width] of the mask; must equal the depth image size."
    )
    counts: RleCounts = Field(
        description=(
            "Run lengths: a compressed COCO RLE string, or a list of integers "
            "(uncompressed RLE) summing to height x width."
        )
    )


class DetectionIn(BaseModel):
    """One 2D detection in a frame."""

    model_config = ConfigDict(extra="forbid")

    label: NonEmptyLabel = Field(description="Top class label from the detector.")
    score: Annotated[float, Strict(), Field(ge=0, le=1, allow_inf_nan=False)] = Field(
        description="Detector confidence of the label, in [0, 1]."
    )
    kind: Literal["object", "fixture"] = Field(
        default="object",
        description="`object` for movable things, `fixture` for furniture and structure.",
    )
    mask: RleMask = Field(description="Instance mask, the size of the frame's depth image.")
    embedding: Annotated[list[EmbeddingValue], Field(min_length=1)] | None = Field(
        default=None, description="Optional appearance embedding (raw, not normalized)."
    )
    class_scores: dict[NonEmptyLabel, Similarity] | None = Field(
        default=None, description="Optional similarities (-1 to 1) of alternative labels, by label."
    )


class FrameIn(BaseModel):
    """One posed RGB-D frame: depth plus detections."""

    model_config = ConfigDict(extra="forbid")

    frame_id: NonEmptyLabel = Field(description="Client frame identifier, unique in the batch.")
    timestamp: Timestamp = Field(description="Capture time of the frame, in seconds.")
    intrinsics: Intrinsics = Field(description="Pinhole intrinsics of the depth image.")
    pose: Annotated[list[PoseRow], Field(min_length=4, max_length=4)] = Field(
        description=(
            "4x4 camera-to-world rigid transform, row-major, metres, OpenCV camera axes "
            "(x right, y down, z forward)."
        )
    )
    depth: DepthImage = Field(description="Depth image registered to the detections.")
    detections: list[DetectionIn] = Field(
        default_factory=list, description="Detections in this frame (may be empty)."
    )


class BatchIn(BaseModel):
    """Body of `POST /v1/scenes/{scene_id}/batches`: one semantic update batch."""

    model_config = ConfigDict(extra="forbid")

    batch_id: Identifier = Field(
        description="Client-chosen idempotency key: re-posting the same batch is a no-op."
    )
    frames: list[FrameIn] = Field(min_length=1, description="Frames of the batch, at least one.")

    @field_validator("frames")
    @classmethod
    def _frame_ids_unique(cls, frames: list[FrameIn]) -> list[FrameIn]:
        """Reject a batch that names the same frame twice."""
        first_index: dict[str, int] = {}
        for index, frame in enumerate(frames):
            if frame.frame_id in first_index:
                raise PydanticCustomError(
                    "duplicate_frame_id",
                    "frame_id '{frame_id}' is used by both frames[{first}] and frames[{again}]",
                    {
                        "frame_id": frame.frame_id,
                        "first": first_index[frame.frame_id],
                        "again": index,
                    },
                )
            first_index[frame.frame_id] = index
        return frames


class VerdictIn(BaseModel):
    """Body of `POST /v1/scenes/{scene_id}/tracks/{track_id}/verification`."""

    model_config = ConfigDict(extra="forbid")

    verdict: Literal["confirm", "reject"] = Field(description="The verifier's answer.")
    label: NonEmptyLabel | None = Field(
        None, description="Corrected label (default: the track's label)."
    )
    source: NonEmptyLabel = Field(description="Who answered (model name, operator...).")
    frame_id: NonEmptyLabel | None = Field(
        None,
        description="The observation the verdict is about; a second verdict must name a new one.",
    )


# A planar robot pose: within 10 km of the origin (as frame poses), yaw within ten radians.
# Metres: within the largest map a scene may have (occupancy.half_extent_m is at most 200); a
# pose outside the scene's own map is a conflict with its parameters (409).
Coordinate = Annotated[float, Strict(), Field(ge=-200.0, le=200.0, allow_inf_nan=False)]
Yaw = Annotated[float, Strict(), Field(ge=-10.0, le=10.0, allow_inf_nan=False)]


class RobotPose(BaseModel):
    """A planar pose of the robot's base in the world frame (z up)."""

    model_config = ConfigDict(extra="forbid")

    x: Coordinate = Field(description="Metres.")
    y: Coordinate = Field(description="Metres.")
    yaw: Yaw = Field(description="Heading about z from +x, radians.")


class PlanIn(BaseModel):
    """Body of `POST /v1/scenes/{scene_id}/plan`."""

    model_config = ConfigDict(extra="forbid")

    robot_pose: RobotPose = Field(description="Where the robot is now.")


class InspectionIn(BaseModel):
    """Body of `POST /v1/scenes/{scene_id}/inspections`: one fixture-centered capture."""

    model_config = ConfigDict(extra="forbid")

    fixture_id: Identifier = Field(description="The confirmed fixture inspected.")
    frames: list[FrameIn] = Field(
        min_length=1,
        description=(
            "The sweep's views, the robot's primary view first. The one grounded is the first"
            " that shows the fixture's support region, or (inspection.primary_view"
            " most_grounded, the default) the one of those grounding the most objects on it;"
            " views are never fused."
        ),
    )
    fixture_verified: bool | None = Field(
        None,
        description="The client's model's verification of the fixture class at its support region.",
    )
    capture_id: Identifier | None = Field(
        None, description="Client id of the capture (default: generated)."
    )
    view: RobotPose | None = Field(
        None,
        description="Where the robot stood for the capture (default: the locked view when the "
        "fixture is the plan's target). A failed capture excludes views near it.",
    )

    @field_validator("frames")
    @classmethod
    def _frame_ids_unique(cls, frames: list[FrameIn]) -> list[FrameIn]:
        """Reject a capture that names the same frame twice."""
        return BatchIn._frame_ids_unique(frames)
