"""Hand-built truth and prediction frames for the evaluation metrics' tests."""

from __future__ import annotations

from evaluation.predictions import FramePrediction, PredictedNode
from sim.truth import FrameTruth, TruthObject, Vec3

ORIGIN: Vec3 = (0.0, 0.0, 0.0)
FAR: Vec3 = (3.0, 0.0, 0.0)


def truth_object(
    object_id: str, center: Vec3 = ORIGIN, present: bool = True, label: str = "mug"
) -> TruthObject:
    """A ground-truth object with the fields the metrics ignore filled in."""
    return TruthObject(object_id, label, center, present, parent=None, visible_pixels=500)


def node(
    track_id: str, center: Vec3 = ORIGIN, kind: str = "object", label: str = "mug"
) -> PredictedNode:
    """A published graph node."""
    return PredictedNode(track_id, label, center, parent=None, kind=kind)


def truth_frames(*frames: list[TruthObject]) -> list[FrameTruth]:
    """Frames of ground truth numbered from 0."""
    return [FrameTruth(index, tuple(objects)) for index, objects in enumerate(frames)]


def prediction_frames(*frames: list[PredictedNode]) -> list[FramePrediction]:
    """Published graphs numbered from 0."""
    return [FramePrediction(index, tuple(nodes)) for index, nodes in enumerate(frames)]
