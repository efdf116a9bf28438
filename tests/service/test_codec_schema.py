"""Wire -> domain decoding of batches: bad poses and the other schema checks, each error
naming its field."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from pydantic import ValidationError

from api_schema import BatchIn
from codec.observations import InvalidObservation, decode_batch
from tests.service.codec_errors import decode_error, schema_errors
from tests.wire_bodies import (
    batch_body,
    frame_body,
    sample_pose,
)

# --- bad poses ----------------------------------------------------------------------------


def with_pose(pose: list[list[float]]) -> dict[str, Any]:
    """A one-frame batch with this pose."""
    frame = frame_body()
    frame["pose"] = pose
    return batch_body(frame)


def scaled_rotation() -> list[list[float]]:
    pose = np.array(sample_pose())
    pose[:3, :3] *= 1.01
    rows: list[list[float]] = pose.tolist()
    return rows


def reflection() -> list[list[float]]:
    pose = np.array(sample_pose())
    pose[:3, 2] *= -1
    rows: list[list[float]] = pose.tolist()
    return rows


def projective_last_row() -> list[list[float]]:
    pose = np.array(sample_pose())
    pose[3] = [0.0, 0.0, 0.01, 1.0]
    rows: list[list[float]] = pose.tolist()
    return rows


@pytest.mark.parametrize(
    ("pose", "reason_part"),
    [
        pytest.param(scaled_rotation(), "not orthonormal", id="scaled"),
        pytest.param(reflection(), "determinant -1", id="reflection"),
        pytest.param(projective_last_row(), "last row", id="last-row"),
    ],
)
def test_non_rigid_pose_names_the_pose(pose: list[list[float]], reason_part: str) -> None:
    error = decode_error(with_pose(pose))
    assert error.field == "frames[0].pose"
    assert reason_part in error.reason


def test_pose_within_tolerance_is_accepted() -> None:
    pose = np.array(sample_pose())
    pose[:3, :3] += 1e-6  # float32 round-off on the client
    pose[3, 0] = 1e-8
    decoded = decode_batch(BatchIn.model_validate(with_pose(pose.tolist())))
    np.testing.assert_array_equal(decoded.frames[0].pose, pose)


def test_non_finite_pose_fails_the_schema_and_the_codec() -> None:
    pose = sample_pose()
    pose[1][2] = float("nan")
    assert schema_errors(with_pose(pose)) == [(("frames", 0, "pose", 1, 2), "finite_number")]

    # The codec does not trust that its input went through validation.
    batch = BatchIn.model_validate(with_pose(sample_pose()))
    batch.frames[0].pose[0][3] = float("inf")
    with pytest.raises(InvalidObservation) as caught:
        decode_batch(batch)
    assert caught.value.field == "frames[0].pose"
    assert "infinite" in caught.value.reason


def test_pose_of_wrong_shape_fails_the_schema() -> None:
    assert schema_errors(with_pose(sample_pose()[:3])) == [(("frames", 0, "pose"), "too_short")]
    bad_row = sample_pose()
    bad_row[2] = bad_row[2][:3]
    assert schema_errors(with_pose(bad_row)) == [(("frames", 0, "pose", 2), "too_short")]


# --- other schema checks ------------------------------------------------------------------


@pytest.mark.parametrize("focal", [0.0, -525.0])
@pytest.mark.parametrize("axis", ["fx", "fy"])
def test_non_positive_focal_length_fails_the_schema(axis: str, focal: float) -> None:
    frame = frame_body()
    frame["intrinsics"][axis] = focal
    assert schema_errors(batch_body(frame)) == [
        (("frames", 0, "intrinsics", axis), "greater_than_equal")
    ]


def test_empty_frame_list_fails_the_schema() -> None:
    assert schema_errors({"batch_id": "b1", "frames": []}) == [(("frames",), "too_short")]


def test_duplicate_frame_ids_fail_the_schema() -> None:
    body = batch_body(frame_body("a"), frame_body("b"), frame_body("a"))
    with pytest.raises(ValidationError) as caught:
        BatchIn.model_validate(body)
    [error] = caught.value.errors()
    assert error["loc"] == ("frames",)
    assert error["type"] == "duplicate_frame_id"
    assert "'a'" in error["msg"] and "frames[0]" in error["msg"] and "frames[2]" in error["msg"]


@pytest.mark.parametrize("batch_id", ["", "has space", "slash/no", "x" * 201])
def test_bad_batch_id_fails_the_schema(batch_id: str) -> None:
    body = batch_body()
    body["batch_id"] = batch_id
    assert [location for location, _ in schema_errors(body)] == [("batch_id",)]


@pytest.mark.parametrize(
    ("field", "value", "error_type"),
    [
        ("width", "64", "int_type"),  # numbers are not coerced from strings
        ("width", True, "int_type"),
        ("height", 0, "greater_than"),
        ("cx", float("inf"), "finite_number"),
    ],
)
def test_intrinsics_are_strict_numbers(field: str, value: Any, error_type: str) -> None:
    frame = frame_body()
    frame["intrinsics"][field] = value
    assert schema_errors(batch_body(frame)) == [(("frames", 0, "intrinsics", field), error_type)]


@pytest.mark.parametrize(
    ("field", "value", "location_tail"),
    [
        ("score", 1.5, ("score",)),
        ("kind", "person", ("kind",)),
        ("embedding", [], ("embedding",)),
        ("embedding", [0.1, float("nan")], ("embedding", 1)),
        ("class_scores", {"": 0.5}, ("class_scores", "", "[key]")),
        ("class_scores", {"cup": float("inf")}, ("class_scores", "cup")),
        ("unexpected", 1, ("unexpected",)),
    ],
)
def test_bad_detection_fields_fail_the_schema(
    field: str, value: Any, location_tail: tuple[str | int, ...]
) -> None:
    frame = frame_body()
    frame["detections"][0][field] = value
    [(location, _)] = schema_errors(batch_body(frame))
    assert location == ("frames", 0, "detections", 0, *location_tail)


def test_kind_defaults_to_object() -> None:
    frame = frame_body()
    del frame["detections"][0]["kind"]
    detection = decode_batch(BatchIn.model_validate(batch_body(frame))).frames[0].detections[0]
    assert detection.kind == "object"
