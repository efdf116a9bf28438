"""Coarse fixtures: voxel class evidence, taxonomy query, DBSCAN, proposals, association.

Section 3.2 ("the accumulated voxel map is queried against the fixture taxonomy ... clustered
by DBSCAN ... implausible clusters are discarded") and section 3.3 ("same-class planar
proximity, expanded-footprint coverage, and footprint IoU"; a strictly contained residual
cluster attaches to an already matched fixture).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from core.geometry import backproject_pixels, camera_to_world
from core.observation import Detection, Frame
from core.params import FixtureParams
from core.voxels import pack, unpack

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
Footprint = tuple[float, float, float, float]  # xmin, ymin, xmax, ymax


@dataclass(frozen=True)
class VoxelEvidence:
    """One fixture mask's contribution: the voxels it covers and its class similarities."""

    frame_id: str
    class_scores: tuple[float, ...]  # in taxonomy order
    voxels: IntArray  # (n,) unique packed voxel keys


@dataclass(frozen=True, eq=False)
class FixtureProposal:
    """A plausible same-class cluster of kept voxels."""

    label: str
    center: FloatArray  # (3,)
    extent: FloatArray  # (3,)
    voxel_count: int
    margin: float  # mean top-vs-second class margin over the cluster
    mean_score: float
    contributed: int  # voxels of this cluster covered by the current batch
    best_frame: str | None  # the batch frame that covered most of it
    class_means: dict[str, float] = field(default_factory=dict)  # mean similarity per class

    @property
    def footprint(self) -> Footprint:
        """Planar box of the cluster."""
        half = self.extent / 2
        return (
            float(self.center[0] - half[0]),
            float(self.center[1] - half[1]),
            float(self.center[0] + half[0]),
            float(self.center[1] + half[1]),
        )


def class_vector(detection: Detection, taxonomy: Sequence[str]) -> tuple[float, ...]:
    """The detection's similarity to each taxonomy class (its label alone when no map is given)."""
    scores = detection.class_scores or {detection.label: detection.score}
    return tuple(float(scores.get(name, 0.0)) for name in taxonomy)


def voxel_evidence(
    detection: Detection,
    frame: Frame,
    params: FixtureParams,
    min_range_m: float,
    max_range_m: float,
) -> VoxelEvidence | None:
    """Back-project a fixture mask's valid depth (every `mask_pixel_stride`-th pixel) into voxels."""
    stride = params.mask_pixel_stride
    flat_index = (
        detection.mask.strided_indices(stride) if stride > 1 else detection.mask.flat_indices()
    )
    depth_m = frame.depth.reshape(-1)[flat_index].astype(np.float64)
    valid = (depth_m >= min_range_m) & (depth_m <= max_range_m)
    if not valid.any():
        return None
    points = camera_to_world(
        backproject_pixels(flat_index[valid], depth_m[valid], frame.intrinsics), frame.pose
    )
    packed = np.unique(pack(np.floor(points / params.voxel_size_m).astype(np.int64)))
    return VoxelEvidence(frame.frame_id, class_vector(detection, params.taxonomy), packed)


def merged_voxels(
    base: tuple[IntArray, IntArray, FloatArray], batch: Sequence[VoxelEvidence]
) -> tuple[IntArray, IntArray, FloatArray]:
    """The map (sorted packed keys, counts, score sums) with the batch's evidence added."""
    base_keys, base_counts, base_sums = base
    width = len(batch[0].class_scores) if batch else base_sums.shape[1]
    batch_keys = np.concatenate([e.voxels for e in batch]) if batch else np.zeros(0, np.int64)
    batch_sums = (
        np.concatenate([np.tile(np.asarray(e.class_scores), (len(e.voxels), 1)) for e in batch])
        if batch
        else np.zeros((0, width))
    )
    keys, inverse = np.unique(np.concatenate((base_keys, batch_keys)), return_inverse=True)
    counts = np.zeros(len(keys), np.int64)
    np.add.at(counts, inverse, np.concatenate((base_counts, np.ones(len(batch_keys), np.int64))))
    sums = np.zeros((len(keys), width))
    np.add.at(sums, inverse, np.concatenate((base_sums.reshape(-1, width), batch_sums)))
    return keys, counts, sums


def kept_voxels(
    counts: IntArray, sums: FloatArray, params: FixtureParams
) -> tuple[IntArray, FloatArray, FloatArray]:
    """Per voxel: the kept class index (-1 when dropped), its mean score and its margin."""
    if counts.size == 0:
        return np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
    means = sums / counts[:, None]
    order = np.argsort(-means, axis=1, kind="stable")
    best = order[:, 0]
    best_score = np.take_along_axis(means, best[:, None], axis=1)[:, 0]
    second_score = (
        np.take_along_axis(means, order[:, 1:2], axis=1)[:, 0]
        if means.shape[1] > 1
        else np.zeros(len(best))
    )
    thresholds = np.array(
        [
            params.class_thresholds.get(name, params.default_class_threshold)
            for name in params.taxonomy
        ]
    )
    margin = best_score - second_score
    keep = (best_score >= thresholds[best]) & (margin >= params.min_class_margin)
    return np.where(keep, best, -1), best_score, margin


def dbscan(points: FloatArray, eps: float, min_points: int) -> IntArray:
    """DBSCAN cluster label per point (-1 for noise): core points joined within eps, borders attached."""
    return dbscan_with_core(points, eps, min_points)[0]


def dbscan_with_core(
    points: FloatArray, eps: float, min_points: int
) -> tuple[IntArray, npt.NDArray[np.bool_]]:
    """DBSCAN labels and the core flag of each point.

    Labels number the clusters in the order of their first core point; a border point joins
    the cluster of the lowest label among its core neighbours.
    """
    count = len(points)
    labels = np.full(count, -1, dtype=np.int64)
    if count == 0:
        return labels, np.zeros(0, dtype=bool)
    tree = cKDTree(points)
    pairs = tree.query_pairs(eps, output_type="ndarray")
    degree = np.bincount(pairs.ravel(), minlength=count) + 1  # a point is its own neighbour
    core = degree >= min_points
    core_pairs = pairs[core[pairs[:, 0]] & core[pairs[:, 1]]]
    graph = coo_matrix(
        (np.ones(len(core_pairs)), (core_pairs[:, 0], core_pairs[:, 1])), shape=(count, count)
    )
    _, component = connected_components(graph, directed=False)
    labels[core] = component[core]
    # Border points join the cluster of a core neighbour (the lowest index, for determinism).
    for a, b in pairs[core[pairs[:, 0]] ^ core[pairs[:, 1]]]:
        border, anchor = (b, a) if core[a] else (a, b)
        if labels[border] == -1 or labels[anchor] < labels[border]:
            labels[border] = labels[anchor]
    return labels, core


@dataclass(frozen=True, eq=False)
class ClusterSummary:
    """What a cluster says whatever the batch: its proposal but for the batch's own share, and
    its box in voxel keys (the clusters kept between batches look it up)."""

    class_index: int
    proposal: FixtureProposal | None  # None: not plausible for its class
    low: IntArray  # (3,) smallest voxel key of its members, per axis
    high: IntArray  # (3,) largest


def cluster_summary(
    class_index: int,
    keys: IntArray,
    counts: IntArray,
    sums: FloatArray,
    scores: FloatArray,
    margins: FloatArray,
    params: FixtureParams,
) -> ClusterSummary:
    """The summary of one cluster from its members' rows, in key order."""
    label = params.taxonomy[class_index]
    size = params.voxel_size_m
    voxel = unpack(keys)
    points = ((voxel + 0.5) * size).astype(np.float64)
    low, high = points.min(axis=0) - size / 2, points.max(axis=0) + size / 2
    extent = high - low
    box_low, box_high = voxel.min(axis=0), voxel.max(axis=0)
    if not plausible(label, extent, params):
        return ClusterSummary(class_index, None, box_low, box_high)
    means = np.ascontiguousarray(sums).sum(axis=0) / counts.sum()
    proposal = FixtureProposal(
        label=label,
        center=(low + high) / 2,
        extent=extent,
        voxel_count=int(keys.size),
        margin=float(margins.mean()),
        mean_score=float(scores.mean()),
        contributed=0,
        best_frame=None,
        class_means={
            name: float(value)
            for name, value in zip(params.taxonomy, means, strict=True)
            if value > 0
        },
    )
    return ClusterSummary(class_index, proposal, box_low, box_high)


def batch_proposal(
    summary: FixtureProposal, contributed: int, frames: dict[str, int]
) -> FixtureProposal:
    """A cluster's proposal in one batch: `contributed` of its voxels covered by the batch, and
    `frames` the voxels each batch frame covered (the one that covered most is cropped)."""
    best_frame = min(frames.items(), key=lambda item: (-item[1], item[0]))[0] if frames else None
    if contributed == 0 and best_frame is None:
        return summary
    return dataclasses.replace(summary, contributed=contributed, best_frame=best_frame)


def fixture_proposals(
    keys: IntArray,
    counts: IntArray,
    sums: FloatArray,
    kept: IntArray,
    scores: FloatArray,
    margins: FloatArray,
    batch: Sequence[VoxelEvidence],
    params: FixtureParams,
) -> list[FixtureProposal]:
    """Same-class DBSCAN clusters of kept voxels (packed `keys`) that pass the class's size limits.

    The whole map clustered anew: the reference the clusters kept between batches
    (`core.fixture_map`) reproduce.
    """
    proposals: list[FixtureProposal] = []
    size = params.voxel_size_m
    covered = (
        np.unique(np.concatenate([e.voxels for e in batch])) if batch else np.zeros(0, np.int64)
    )
    for class_index in range(len(params.taxonomy)):
        members = np.flatnonzero(kept == class_index)
        if members.size == 0:
            continue
        centers = ((unpack(keys[members]) + 0.5) * size).astype(np.float64)
        cluster_of = dbscan(centers, params.dbscan_eps_m, params.dbscan_min_points)
        for cluster in np.unique(cluster_of[cluster_of >= 0]):
            inside = members[cluster_of == cluster]
            summary = cluster_summary(
                class_index,
                keys[inside],
                counts[inside],
                sums[inside],
                scores[inside],
                margins[inside],
                params,
            ).proposal
            if summary is None:
                continue
            cluster_keys = keys[inside]
            # The batch frame that covered most of the cluster: the one to crop for a verifier.
            frames: dict[str, int] = {}
            for evidence in batch:
                hits = int(np.isin(evidence.voxels, cluster_keys, assume_unique=True).sum())
                if hits:
                    frames[evidence.frame_id] = frames.get(evidence.frame_id, 0) + hits
            contributed = int(np.isin(cluster_keys, covered, assume_unique=True).sum())
            proposals.append(batch_proposal(summary, contributed, frames))
    return proposals


def plausible(label: str, extent: FloatArray, params: FixtureParams) -> bool:
    """Class-specific size limits on the sorted footprint and the height."""
    limits = params.size_limits.get(label, params.default_size_limits)
    footprint = sorted((float(extent[0]), float(extent[1])), reverse=True)
    dims = (footprint[0], footprint[1], float(extent[2]))
    return all(limits[i] <= dims[i] <= limits[i + 3] for i in range(3))


def ema_center(
    previous: Sequence[float], observed: Sequence[float] | FloatArray, alpha: float
) -> tuple[float, float, float]:
    """Fixture centers: exponential moving average with alpha 0.35 (section 3.3)."""
    x, y, z = ((1 - alpha) * p + alpha * o for p, o in zip(previous, observed, strict=True))
    return (float(x), float(y), float(z))
