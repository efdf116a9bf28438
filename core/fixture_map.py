"""The fixture voxel map as arrays, and its DBSCAN clusters kept between batches (section 3.2).

The map is what the log says (per voxel: how many fixture masks covered it and the summed class
similarities); `fold` merges each batch's evidence into its sorted arrays. Its clusters are
derived from it, as the track columns are: built once by clustering the whole map
(`core.fixtures.fixture_proposals`' DBSCAN), then updated near the voxels each batch touched.
The update gives exactly what clustering the whole map anew would, for any map and batch
(tests/core/test_fixture_map.py checks it on random maps and on the shipped streams):

- only the touched voxels change class; a voxel's core flag depends on the voxels within eps,
  so it can change only within eps of a touched voxel;
- a cluster (a component of the core voxels, named by its smallest key) can change only if it
  holds a core voxel near the touched ones; the update re-clusters those clusters whole, with
  every voxel near the touched ones, and the core edges of that set never leave it;
- a border voxel joins the cluster of smallest name among its core neighbours, recomputed
  around the re-clustered set.

Neighbours are looked up as integer key offsets, which equal DBSCAN's metric test on voxel
centres when eps is not within a rounding error of a neighbour's distance and stays under two
voxels; other parameters (and a touched region too large for a local grid) re-cluster the map.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from core.events import FixtureEvidence
from core.fixtures import (
    ClusterSummary,
    FixtureProposal,
    VoxelEvidence,
    batch_proposal,
    cluster_summary,
    dbscan_with_core,
    kept_voxels,
)
from core.local_clusters import Clusters, local_update, new_keys
from core.params import FixtureParams
from core.voxels import pack, unpack

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
Evidence = Sequence[tuple[IntArray, tuple[float, ...]]]  # per mask: sorted unique keys, scores


def proposals_of(
    summaries: Mapping[int, ClusterSummary],
    keys: IntArray,
    cluster: IntArray,
    batch: Sequence[VoxelEvidence],
) -> list[FixtureProposal]:
    """Plausible clusters in taxonomy order, then by name (the order of the full re-clustering),
    with the batch's share: `keys` are the voxels the batch covered and `cluster` theirs."""
    names, counts = np.unique(cluster[cluster >= 0], return_counts=True)
    contributed = dict(zip(names.tolist(), counts.tolist(), strict=True))
    frames: dict[int, dict[str, int]] = {}
    for evidence in batch:
        of = cluster[np.searchsorted(keys, evidence.voxels)]
        hit_names, hits = np.unique(of[of >= 0], return_counts=True)
        for name, count in zip(hit_names.tolist(), hits.tolist(), strict=True):
            per_frame = frames.setdefault(name, {})
            per_frame[evidence.frame_id] = per_frame.get(evidence.frame_id, 0) + count
    ordered = sorted(
        (summary.class_index, name)
        for name, summary in summaries.items()
        if summary.proposal is not None
    )
    result = []
    for _class_index, name in ordered:
        proposal = summaries[name].proposal
        assert proposal is not None
        result.append(batch_proposal(proposal, contributed.get(name, 0), frames.get(name, {})))
    return result


@dataclass(frozen=True, eq=False)
class VoxelMap:
    """Sorted packed voxel keys, how many fixture masks covered each, their class-score sums."""

    keys: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    counts: IntArray = field(default_factory=lambda: np.zeros(0, np.int64))
    sums: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    # Derived, never stored: the clusters (per fixture parameters) and the update a decide
    # computed for its batch, which the fold of that batch's evidence reuses.
    cache: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

    def __len__(self) -> int:
        return int(self.keys.size)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, VoxelMap):
            return NotImplemented
        return (
            np.array_equal(self.keys, other.keys)
            and np.array_equal(self.counts, other.counts)
            and (len(self) == 0 or np.array_equal(self.sums, other.sums))
        )

    __hash__ = None  # type: ignore[assignment]

    # -- stored form -------------------------------------------------------------------------

    def records(self) -> list[list[Any]]:
        """[x, y, z, count, [sums...]] per voxel in key order (the snapshot's form)."""
        return [
            [*key, count, sums]
            for key, count, sums in zip(
                unpack(self.keys).tolist(), self.counts.tolist(), self.sums.tolist(), strict=True
            )
        ]

    @classmethod
    def from_records(cls, records: Sequence[Sequence[Any]]) -> VoxelMap:
        """Inverse of `records`."""
        if not records:
            return cls()
        keys = pack(np.array([r[:3] for r in records], dtype=np.int64))
        counts = np.array([r[3] for r in records], dtype=np.int64)
        sums = np.array([r[4] for r in records], dtype=np.float64)
        order = np.argsort(keys, kind="stable")
        return cls(keys[order], counts[order], sums[order])

    # -- evidence ------------------------------------------------------------------------------

    def rows(self, evidence: Evidence) -> tuple[IntArray, IntArray, FloatArray]:
        """(touched keys sorted, their counts, their sums) once `evidence` is added, mask by mask."""
        width = len(evidence[0][1]) if evidence else self.sums.shape[1]
        touched = np.unique(np.concatenate([keys for keys, _ in evidence]))
        counts = np.zeros(touched.size, np.int64)
        sums = np.zeros((touched.size, width))
        position = np.searchsorted(self.keys, touched)
        found = position < self.keys.size
        found[found] = self.keys[position[found]] == touched[found]
        counts[found] = self.counts[position[found]]
        sums[found] = self.sums[position[found]].reshape(-1, width)
        for keys, scores in evidence:  # mask by mask, as each mask's event is folded
            at = np.searchsorted(touched, keys)
            row = np.asarray(scores, dtype=np.float64)
            if at.size and bool(np.all(at[1:] > at[:-1])):  # distinct keys (as decide writes)
                counts[at] += 1
                sums[at] += row
            else:  # a voxel twice in one mask counts twice, in order
                np.add.at(counts, at, 1)
                np.add.at(sums, at, row)
        return touched, counts, sums

    def merged(self, evidence: Evidence) -> VoxelMap:
        """The map with `evidence` added (no clusters)."""
        if not evidence:
            return self
        touched, counts, sums = self.rows(evidence)
        keys, at = _with_keys(self.keys, touched)
        _, where = new_keys(self.keys, touched)
        new_counts = _inserted(self.counts, where, 0)
        new_sums = _inserted(self.sums.reshape(-1, sums.shape[1]), where, 0.0)
        new_counts[at] = counts
        new_sums[at] = sums
        return VoxelMap(keys, new_counts, new_sums)

    def with_event(self, event: FixtureEvidence) -> VoxelMap:
        """The map after `event` is folded; its clusters follow when this map's were built."""
        pending = self.cache.get("next")
        if pending is not None and (pending[0] is event or pending[0] == event):
            result: VoxelMap = pending[1].applied(self)
            return result
        evidence = evidence_of(event)
        clusters = self.cache.get("clusters")
        if clusters is None or not evidence:
            return self.merged(evidence)
        return MapUpdate.of(self, clusters.params, evidence).applied(self)

    # -- clusters ------------------------------------------------------------------------------

    def clusters(self, params: FixtureParams) -> Clusters:
        """The clusters of this map for `params`, built once (by clustering the whole map)."""
        clusters: Clusters | None = self.cache.get("clusters")
        if clusters is None or not (clusters.params is params or clusters.params == params):
            clusters = full_clusters(self, params)
            self.cache["clusters"] = clusters
        return clusters

    def update(
        self, params: FixtureParams, evidence: Evidence, event: FixtureEvidence
    ) -> MapUpdate:
        """The map and clusters once `event` (whose voxels `evidence` are) is added; the fold of
        `event` takes the result from here."""
        result = MapUpdate.of(self, params, evidence)
        self.cache["next"] = (event, result)
        return result


def evidence_of(event: FixtureEvidence) -> list[tuple[IntArray, tuple[float, ...]]]:
    """An evidence event's masks as packed keys and scores."""
    return [
        (pack(np.array(d.voxels, dtype=np.int64).reshape(-1, 3)), d.class_scores)
        for d in event.detections
    ]


def _with_keys(keys: IntArray, touched: IntArray) -> tuple[IntArray, IntArray]:
    """(keys with the touched ones added, in order; where each touched key is in them)."""
    new, where = new_keys(keys, touched)
    merged = np.insert(keys, where, new) if new.size else keys
    return merged, np.searchsorted(merged, touched)


def _inserted(values: npt.NDArray[Any], where: IntArray, fill: Any) -> Any:
    """`values` with a `fill` row inserted before each index of `where` (a copy)."""
    if not where.size:
        return values.copy()
    return np.insert(values, where, fill, axis=0)


def neighbour_offsets(params: FixtureParams) -> IntArray | None:
    """Integer key offsets within eps (self included), or None when the offsets cannot stand
    for DBSCAN's metric test: eps within a rounding error of a neighbour's distance, or two
    voxels or more."""
    size, eps = params.voxel_size_m, params.dbscan_eps_m
    grid = np.stack(np.meshgrid(*([np.arange(-2, 3)] * 3), indexing="ij"), axis=-1).reshape(-1, 3)
    distance = np.sqrt((grid.astype(np.float64) ** 2).sum(axis=1)) * size
    if np.abs(distance - eps).min() <= 1e-9 * max(eps, 1.0) or eps >= 2 * size:
        return None
    offsets: IntArray = grid[distance <= eps]
    return offsets


def full_clusters(voxel_map: VoxelMap, params: FixtureParams) -> Clusters:
    """The whole map clustered anew (the full re-clustering's DBSCAN), with core flags."""
    keys = voxel_map.keys
    count = keys.size
    kept, scores, margins = kept_voxels(voxel_map.counts, voxel_map.sums, params)
    core = np.zeros(count, dtype=bool)
    cluster = np.full(count, -1, dtype=np.int64)
    summaries: dict[int, ClusterSummary] = {}
    size = params.voxel_size_m
    for class_index in range(len(params.taxonomy)):
        members = np.flatnonzero(kept == class_index)
        if members.size == 0:
            continue
        centers = ((unpack(keys[members]) + 0.5) * size).astype(np.float64)
        labels, is_core = dbscan_with_core(centers, params.dbscan_eps_m, params.dbscan_min_points)
        core[members] = is_core
        # A cluster's name: its first (smallest) core key; labels follow the same order.
        found, first = np.unique(labels[is_core], return_index=True)
        names = keys[members[is_core]][first]
        name_of = np.full(int(found.max()) + 1 if found.size else 0, -1, dtype=np.int64)
        name_of[found] = names
        inside = labels >= 0
        cluster[members[inside]] = name_of[labels[inside]]
        grouped = members[inside][np.argsort(labels[inside], kind="stable")]
        bounds = np.cumsum(np.bincount(labels[inside]))[:-1]
        for rows in np.split(grouped, bounds):
            if rows.size == 0:
                continue
            name = int(cluster[rows[0]])
            summaries[name] = cluster_summary(
                class_index,
                keys[rows],
                voxel_map.counts[rows],
                voxel_map.sums[rows],
                scores[rows],
                margins[rows],
                params,
            )
    return Clusters(params, kept, core, cluster, summaries)


@dataclass(frozen=True, eq=False)
class MapUpdate:
    """One batch's evidence on a map: the touched rows and, around them, the new clusters."""

    params: FixtureParams
    touched: IntArray  # sorted keys the batch covered
    counts: IntArray  # their counts and sums after the batch
    sums: FloatArray
    local: IntArray  # sorted keys whose class, core flag or cluster the update recomputed
    kept: IntArray  # of `local`
    core: BoolArray
    cluster: IntArray
    summaries: Mapping[int, ClusterSummary]  # every cluster's after the batch
    after: VoxelMap | None  # the map re-clustered whole instead (no local grid)

    @classmethod
    def of(cls, before: VoxelMap, params: FixtureParams, evidence: Evidence) -> MapUpdate:
        """The update of `before`'s clusters for `params` by `evidence`."""
        touched, counts, sums = before.rows(evidence)
        old = before.clusters(params)
        offsets = neighbour_offsets(params)
        if not touched.size:  # masks without voxels: nothing changes
            none = np.zeros(0, np.int64)
            return cls(
                params,
                touched,
                counts,
                sums,
                none,
                none,
                none.astype(bool),
                none,
                old.summaries,
                None,
            )
        local = (
            None if offsets is None else local_update(before, old, touched, counts, sums, offsets)
        )
        if local is None:
            after = before.merged(evidence)
            full = full_clusters(after, params)
            after.cache["clusters"] = full
            at = np.searchsorted(after.keys, touched)
            return cls(
                params,
                touched,
                counts,
                sums,
                touched,
                full.kept[at],
                full.core[at],
                full.cluster[at],
                full.summaries,
                after,
            )
        keys, kept, core, cluster, summaries = local
        return cls(params, touched, counts, sums, keys, kept, core, cluster, summaries, None)

    def proposals(self, batch: Sequence[VoxelEvidence]) -> list[FixtureProposal]:
        """The batch's proposals: every plausible cluster of the map after it."""
        of_touched = self.cluster[np.searchsorted(self.local, self.touched)]
        return proposals_of(self.summaries, self.touched, of_touched, batch)

    def applied(self, before: VoxelMap) -> VoxelMap:
        """`before` (the map this update was computed on) after the batch, with its clusters."""
        if self.after is not None:
            return self.after
        keys, at = _with_keys(before.keys, self.touched)
        _, where = new_keys(before.keys, self.touched)
        counts = _inserted(before.counts, where, 0)
        sums = _inserted(before.sums.reshape(-1, self.sums.shape[1]), where, 0.0)
        counts[at] = self.counts
        sums[at] = self.sums
        after = VoxelMap(keys, counts, sums)
        old = before.clusters(self.params)
        kept = _inserted(old.kept, where, -1)
        core = _inserted(old.core, where, False)
        cluster = _inserted(old.cluster, where, -1)
        where = np.searchsorted(keys, self.local)
        kept[where], core[where], cluster[where] = self.kept, self.core, self.cluster
        after.cache["clusters"] = Clusters(self.params, kept, core, cluster, self.summaries)
        return after
