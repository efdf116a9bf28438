"""Evaluation metrics: identity, presence and fixtures (event recall and false absence:
`evaluation.change_metrics`).

Object metrics take per-frame ground truth and the graph a method published after each frame,
aligned by position (same length, same order). Only predicted nodes of kind "object" and ground
truth objects whose `present` flag is set take part in them.

Identity matching is class-aware, as multi-class tracking benchmarks score it (KITTI and
BDD100K match within a class) and as the false-absence measure already asks: a node stands for
an object only when it is within 0.5 m and carries the object's label. Without the label, on a
cluttered table a remote is "tracked" by the node of the mug beside it, and the mug's own move
is scored missed because the assignment handed its track to the remote. `class_aware=False`
gives the class-agnostic reading. Identity switches are read class-agnostic in every headline
(the strict reading: a track handed from one object to another counts whatever the labels, and
the count does not rest on the label rule, which came after the first results); the
class-aware count is printed beside it as the lenient one. IDF1 and the assignment stay
class-aware.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import motmetrics as mm
import numpy as np
from scipy.optimize import linear_sum_assignment

from evaluation.predictions import FramePrediction, PredictedNode
from sim.truth import FrameTruth, TruthFixture, TruthObject


@dataclass(frozen=True)
class IdentityScores:
    """IDF1 and its parts, plus CLEAR-MOT identity switches."""

    idf1: float
    idp: float
    idr: float
    id_switches: int
    num_frames: int


@dataclass(frozen=True)
class PresenceScores:
    """Frame-level presence of assigned tracks (the paper's ID-Pres.)."""

    precision: float
    recall: float
    f1: float
    tp: int
    fp: int
    fn: int


@dataclass(frozen=True)
class FixtureScores:
    """Detection quality of the static fixtures in the final graph."""

    precision: float
    recall: float
    f1: float
    matched: int
    center_error: float | None
    count_mae: float
    fixture_map: dict[str, str]


def present_objects(frame_truth: FrameTruth) -> list[TruthObject]:
    """Ground-truth objects that exist in the world at this frame."""
    return [truth_object for truth_object in frame_truth.objects if truth_object.present]


def published_objects(frame_prediction: FramePrediction) -> list[PredictedNode]:
    """Object nodes (not fixtures) of the graph published after this frame."""
    return [node for node in frame_prediction.nodes if node.kind == "object"]


def squared_distance(first: Sequence[float], second: Sequence[float]) -> float:
    """Squared Euclidean distance between two 3D points."""
    return sum((a - b) ** 2 for a, b in zip(first, second, strict=True))


def ratio(numerator: float, denominator: float) -> float:
    """numerator / denominator, or 0.0 when the denominator is zero."""
    return numerator / denominator if denominator else 0.0


def nan_as_zero(value: float) -> float:
    """The value as a float, with a 0/0 NaN (as motmetrics reports it) turned into 0.0."""
    return 0.0 if math.isnan(value) else float(value)


def harmonic_f1(precision: float, recall: float) -> float:
    """Harmonic mean of precision and recall, 0.0 when both are zero."""
    return ratio(2.0 * precision * recall, precision + recall)


def matchable(truth_object: TruthObject, node: PredictedNode, class_aware: bool) -> bool:
    """Whether a node may stand for an object at all (distance aside): same label if class-aware."""
    return not class_aware or node.label == truth_object.label


def identity_metrics(
    truth: Sequence[FrameTruth],
    predictions: Sequence[FramePrediction],
    max_distance: float = 0.5,
    *,
    class_aware: bool = True,
) -> IdentityScores:
    """IDF1, IDP, IDR (motmetrics) and CLEAR-MOT switches of published object tracks vs present truth.

    A ground-truth object and a track can be matched at a frame when their centers are at most
    `max_distance` metres apart and, class-aware, the node carries the object's label.
    idf1 = 2 IDTP / (2 IDTP + IDFP + IDFN) under the best one-to-one global identity matching;
    id_switches counts frames where an object is matched to a different track than at its
    previous match. idp is 0.0 (not NaN) when nothing was published, and every
    score is 0.0 when there is no ground truth at all. num_frames is the number of frames given.
    """
    if len(truth) != len(predictions):
        raise ValueError(f"{len(truth)} truth frames but {len(predictions)} prediction frames")
    # motmetrics 1.4.0 stores object and hypothesis ids as floats, so string ids are replaced by
    # small integers (exact as floats); separate numberings because the two id spaces are apart.
    object_numbers: dict[str, int] = {}
    track_numbers: dict[str, int] = {}
    accumulator = mm.MOTAccumulator(auto_id=False)
    truth_count = 0
    for frame_truth, frame_prediction in zip(truth, predictions, strict=True):
        objects = present_objects(frame_truth)
        nodes = published_objects(frame_prediction)
        truth_count += len(objects)
        # norm2squared_matrix returns SQUARED distances, so the gate must be squared too.
        distances = mm.distances.norm2squared_matrix(
            np.array([truth_object.center for truth_object in objects], dtype=float).reshape(-1, 3),
            np.array([node.center for node in nodes], dtype=float).reshape(-1, 3),
            max_d2=max_distance**2,
        )
        for row, truth_object in enumerate(objects):
            for column, node in enumerate(nodes):
                if not matchable(truth_object, node, class_aware):
                    distances[row, column] = np.nan  # motmetrics: never a match
        accumulator.update(
            [
                object_numbers.setdefault(truth_object.object_id, len(object_numbers))
                for truth_object in objects
            ],
            [track_numbers.setdefault(node.track_id, len(track_numbers)) for node in nodes],
            distances,
            frameid=frame_truth.frame_index,
        )
    if truth_count == 0:
        return IdentityScores(idf1=0.0, idp=0.0, idr=0.0, id_switches=0, num_frames=len(truth))
    summary = mm.metrics.create().compute(
        accumulator, metrics=["idf1", "idp", "idr", "num_switches"], name="run"
    )
    row = summary.loc["run"]
    return IdentityScores(
        idf1=nan_as_zero(row["idf1"]),
        idp=nan_as_zero(row["idp"]),
        idr=nan_as_zero(row["idr"]),
        id_switches=int(row["num_switches"]),
        num_frames=len(truth),
    )


def global_assignment(
    truth: Sequence[FrameTruth],
    predictions: Sequence[FramePrediction],
    max_distance: float = 0.5,
    *,
    class_aware: bool = True,
) -> dict[str, str]:
    """One-to-one map ground-truth object id -> track id maximizing total co-occurring frames.

    Two ids co-occur at a frame when the object is present, the track is published, their
    centers are at most `max_distance` apart and (class-aware) the track carries its label. The
    map maximizes the sum of co-occurrence counts over assigned pairs (Hungarian algorithm),
    which is IDF1's own global matching made explicit; pairs that never co-occur are left
    unassigned.
    """
    if len(truth) != len(predictions):
        raise ValueError(f"{len(truth)} truth frames but {len(predictions)} prediction frames")
    max_squared = max_distance**2
    co_occurrence: Counter[tuple[str, str]] = Counter()
    for frame_truth, frame_prediction in zip(truth, predictions, strict=True):
        nodes = published_objects(frame_prediction)
        for truth_object in present_objects(frame_truth):
            for node in nodes:
                # Same inclusive squared-distance gate as motmetrics uses in identity_metrics.
                if matchable(truth_object, node, class_aware) and (
                    squared_distance(truth_object.center, node.center) <= max_squared
                ):
                    co_occurrence[truth_object.object_id, node.track_id] += 1
    if not co_occurrence:
        return {}
    # Sorted ids make the result independent of frame and node order when counts tie.
    object_ids = sorted({object_id for object_id, _ in co_occurrence})
    track_ids = sorted({track_id for _, track_id in co_occurrence})
    counts = np.zeros((len(object_ids), len(track_ids)))
    for (object_id, track_id), count in co_occurrence.items():
        counts[object_ids.index(object_id), track_ids.index(track_id)] = count
    rows, columns = linear_sum_assignment(counts, maximize=True)
    return {
        object_ids[row]: track_ids[column]
        for row, column in zip(rows, columns, strict=True)
        if counts[row, column] > 0
    }


def presence_f1(
    truth: Sequence[FrameTruth],
    predictions: Sequence[FramePrediction],
    assignment: Mapping[str, str],
    max_distance: float = 0.5,
) -> PresenceScores:
    """Per-frame presence of assigned tracks within `max_distance`, summed over frames (ID-Pres.).

    At each frame: TP = present object whose assigned track is published with its center at most
    `max_distance` from the object's; FN = every other present object (its track unpublished,
    published elsewhere, or no track assigned); FP = published track that is not the assigned
    track of an object present at that frame (ghosts, duplicates, tracks of absent objects).
    precision = TP/(TP+FP), recall = TP/(TP+FN), f1 their harmonic mean (each 0.0 when
    undefined). Unlike IDF1, an object's own track published away from it costs one error (a
    miss), not two: ID-Pres. asks whether each object is in the graph where it is, and how much
    of the graph is nobody's.
    """
    if len(truth) != len(predictions):
        raise ValueError(f"{len(truth)} truth frames but {len(predictions)} prediction frames")
    max_squared = max_distance**2
    tp = fp = fn = 0
    for frame_truth, frame_prediction in zip(truth, predictions, strict=True):
        centers = {node.track_id: node.center for node in published_objects(frame_prediction)}
        expected_tracks = set()
        for truth_object in present_objects(frame_truth):
            track_id = assignment.get(truth_object.object_id)
            if track_id is not None:
                expected_tracks.add(track_id)
            center = centers.get(track_id) if track_id is not None else None
            if center is not None and squared_distance(center, truth_object.center) <= max_squared:
                tp += 1
            else:
                fn += 1
        fp += len(centers.keys() - expected_tracks)
    precision, recall = ratio(tp, tp + fp), ratio(tp, tp + fn)
    return PresenceScores(
        precision=precision,
        recall=recall,
        f1=harmonic_f1(precision, recall),
        tp=tp,
        fp=fp,
        fn=fn,
    )


def fixture_scores(
    truth_fixtures: Sequence[TruthFixture],
    predicted: Sequence[PredictedNode],
    max_distance: float = 1.0,
) -> FixtureScores:
    """Same-class greedy matching of predicted fixture nodes to true fixtures within max_distance.

    Only predicted nodes of kind "fixture" count. Pairs of equal label at most `max_distance`
    apart are taken in ascending center distance (ties by truth id, then track id), each side
    used at most once. precision = matched / predicted, recall = matched / truth, f1 harmonic
    (each 0.0 when undefined); center_error = mean center distance of matched pairs (None when
    nothing matched); count_mae = mean over the union of labels of |#predicted - #truth|;
    fixture_map = truth fixture id -> predicted track id.
    """
    predicted_fixtures = [node for node in predicted if node.kind == "fixture"]
    candidate_pairs = sorted(
        (math.dist(fixture.center, node.center), fixture.fixture_id, node.track_id)
        for fixture in truth_fixtures
        for node in predicted_fixtures
        if fixture.label == node.label and math.dist(fixture.center, node.center) <= max_distance
    )
    fixture_map: dict[str, str] = {}
    used_tracks: set[str] = set()
    matched_distances: list[float] = []
    for distance, fixture_id, track_id in candidate_pairs:
        if fixture_id in fixture_map or track_id in used_tracks:
            continue
        fixture_map[fixture_id] = track_id
        used_tracks.add(track_id)
        matched_distances.append(distance)
    matched = len(matched_distances)
    precision = ratio(matched, len(predicted_fixtures))
    recall = ratio(matched, len(truth_fixtures))
    truth_per_label = Counter(fixture.label for fixture in truth_fixtures)
    predicted_per_label = Counter(node.label for node in predicted_fixtures)
    labels = truth_per_label.keys() | predicted_per_label.keys()
    count_errors = [abs(predicted_per_label[label] - truth_per_label[label]) for label in labels]
    return FixtureScores(
        precision=precision,
        recall=recall,
        f1=harmonic_f1(precision, recall),
        matched=matched,
        center_error=sum(matched_distances) / matched if matched else None,
        count_mae=ratio(sum(count_errors), len(count_errors)),
        fixture_map=fixture_map,
    )


def mean_std(values: Sequence[float]) -> tuple[float, float]:
    """Mean and sample standard deviation (ddof=1; 0.0 for a single value) of repeated runs."""
    if not values:
        raise ValueError("mean_std needs at least one value")
    mean = sum(values) / len(values)
    if len(values) == 1:
        return mean, 0.0
    return mean, float(np.std(values, ddof=1))
