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

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

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
from core.params import FixtureParams
from core.voxels import MASK, OFFSET, pack, unpack

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
Evidence = Sequence[tuple[IntArray, tuple[float, ...]]]  # per mask: sorted unique keys, scores

# The local grid of one update holds at most this many cells (about 100 MB of int32 indices
# at the limit); a batch whose neighbourhood spans more re-clusters the whole map instead.
# An implementation bound, not a constant of the method: it changes the cost, not the result.
MAX_GRID_CELLS = 24_000_000


@dataclass(frozen=True, eq=False)
class Clusters:
    """DBSCAN of a map's kept voxels, per voxel (aligned with the map's keys) and per cluster."""

    params: FixtureParams
    kept: IntArray  # class index per voxel, -1 when the voxel is dropped
    core: BoolArray
    cluster: IntArray  # the cluster's name (its smallest core key) per voxel, -1 for none
    summaries: Mapping[int, ClusterSummary]  # name -> summary


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
        _, where = _new_keys(self.keys, touched)
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
    new, where = _new_keys(keys, touched)
    merged = np.insert(keys, where, new) if new.size else keys
    return merged, np.searchsorted(merged, touched)


def _new_keys(keys: IntArray, touched: IntArray) -> tuple[IntArray, IntArray]:
    """(the touched keys not in `keys`, where they go in them)."""
    where = np.searchsorted(keys, touched)
    present = where < keys.size
    present[present] = keys[where[present]] == touched[present]
    return touched[~present], where[~present]


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
            None if offsets is None else _local_update(before, old, touched, counts, sums, offsets)
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
        _, where = _new_keys(before.keys, self.touched)
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


def _inside(voxels: IntArray, low: IntArray, high: IntArray) -> BoolArray:
    """Whether each voxel key lies in the box [low, high]."""
    inside: BoolArray = (voxels[:, 0] >= low[0]) & (voxels[:, 0] <= high[0])
    for axis in (1, 2):
        inside &= (voxels[:, axis] >= low[axis]) & (voxels[:, axis] <= high[axis])
    return inside


def _in_box(keys: IntArray, low: IntArray, high: IntArray) -> tuple[IntArray, IntArray]:
    """(indices, voxel keys) of the map's voxels inside [low, high]: keys sort by x, then y,
    then z, so each (x, y) row of the box is one run of the sorted keys."""
    low = np.clip(low, -OFFSET, MASK - OFFSET)
    high = np.clip(high, -OFFSET, MASK - OFFSET)
    xs, ys = np.meshgrid(
        np.arange(low[0], high[0] + 1), np.arange(low[1], high[1] + 1), indexing="ij"
    )
    rows = np.stack((xs.ravel(), ys.ravel()), axis=1)
    starts = np.searchsorted(keys, pack(np.column_stack((rows, np.full(len(rows), low[2])))))
    stops = np.searchsorted(
        keys, pack(np.column_stack((rows, np.full(len(rows), high[2])))), side="right"
    )
    lengths = stops - starts
    total = int(lengths.sum())
    # The runs, concatenated: each index is its run's start plus its place in the run.
    run_starts = np.repeat(starts - np.concatenate(([0], np.cumsum(lengths)[:-1])), lengths)
    index: IntArray = run_starts + np.arange(total)
    return index, unpack(keys[index])


def _local_update(
    before: VoxelMap,
    old: Clusters,
    touched: IntArray,
    counts: IntArray,
    sums: FloatArray,
    offsets: IntArray,
) -> tuple[IntArray, IntArray, BoolArray, IntArray, dict[int, ClusterSummary]] | None:
    """The clusters near the touched voxels after the batch, or None when the local grid would
    be too large."""
    params = old.params
    touched_kept, _scores, _margins = kept_voxels(counts, sums, params)
    touched_voxels = unpack(touched)
    reach = int(np.abs(offsets).max(initial=0))
    # Box 1: the touched voxels, every voxel whose core flag may change (within eps of one)
    # and their neighbours.
    low1 = touched_voxels.min(axis=0) - 2 * reach
    high1 = touched_voxels.max(axis=0) + 2 * reach
    # Dirty: the clusters whose box meets box 1 (every cluster with a voxel in it, and maybe
    # a few more), re-clustered whole.
    names = np.fromiter(old.summaries, dtype=np.int64, count=len(old.summaries))
    lows = np.array([s.low for s in old.summaries.values()], dtype=np.int64).reshape(-1, 3)
    highs = np.array([s.high for s in old.summaries.values()], dtype=np.int64).reshape(-1, 3)
    meets = np.all((lows <= high1) & (highs >= low1), axis=1)
    dirty = np.sort(names[meets])
    low2 = np.minimum(low1, lows[meets].min(axis=0, initial=OFFSET))
    high2 = np.maximum(high1, highs[meets].max(axis=0, initial=-OFFSET))
    # Box 2: those clusters and a margin of two neighbourhoods (borders around them).
    low2, high2 = low2 - 2 * reach, high2 + 2 * reach
    shape = high2 - low2 + 1 + 2  # one empty cell of padding on every side
    if math.prod(shape.tolist()) > MAX_GRID_CELLS:
        return None
    index2, voxels2 = _in_box(before.keys, low2, high2)
    # The local points: the map's voxels in box 2 and the new touched ones, in key order.
    fresh, _ = _new_keys(before.keys, touched)
    keys = np.concatenate((before.keys[index2], fresh))
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    voxels = np.concatenate((voxels2, unpack(fresh)))[order]
    old_index = np.concatenate((index2, np.full(fresh.size, -1, np.int64)))[order]
    known = old_index >= 0
    kept = np.full(keys.size, -1, np.int64)
    kept[known] = old.kept[old_index[known]]
    at_touched = np.searchsorted(keys, touched)
    kept[at_touched] = touched_kept
    old_core = np.zeros(keys.size, dtype=bool)
    old_core[known] = old.core[old_index[known]]
    old_cluster = np.full(keys.size, -1, np.int64)
    old_cluster[known] = old.cluster[old_index[known]]
    # A dense grid over box 2 (one empty cell of padding around): which local voxel is in a
    # cell, and its class; neighbours are flat index offsets.
    strides = np.array([shape[1] * shape[2], shape[2], 1], dtype=np.int64)
    flat = (voxels - low2 + 1) @ strides
    index_grid = np.full(int(math.prod(shape.tolist())), -1, dtype=np.int32)
    index_grid[flat] = np.arange(keys.size, dtype=np.int32)
    class_grid = np.full(index_grid.size, -1, dtype=np.int16)
    class_grid[flat] = kept
    steps = offsets @ strides

    def same_class(points: IntArray, along: IntArray) -> tuple[IntArray, BoolArray]:
        """(neighbour cells, whether each holds a voxel of the point's class) per point."""
        cells = flat[points][:, None] + along[None, :]
        same = (class_grid[cells] == kept[points][:, None]) & (kept[points] >= 0)[:, None]
        return cells, same

    # Core flags within eps of a touched voxel (and a little beyond): the degree counts the
    # same-class voxels within eps, the voxel itself included.
    near1 = _inside(voxels, low1 + reach, high1 - reach)
    core = old_core.copy()
    recount = np.flatnonzero(near1)
    degree = same_class(recount, steps)[1].sum(axis=1)
    core[recount] = (kept[recount] >= 0) & (degree >= params.dbscan_min_points)
    # Re-cluster box 1 and the dirty clusters whole: components of their core voxels (each
    # edge looked up once, along the offsets that point forward in the grid).
    in_box1 = _inside(voxels, low1, high1)
    region = in_box1 | np.isin(old_cluster, dirty)
    seeds = np.flatnonzero(region & core)
    cells, same = same_class(seeds, steps[steps > 0])
    rows, columns = np.nonzero(same)
    targets = index_grid[cells[rows, columns]].astype(np.int64)
    linked = core[targets]
    rows, targets = rows[linked], targets[linked]
    if not region[targets].all():  # the core edges of the region stay inside it
        raise AssertionError("fixture clusters: a core edge leaves the re-clustered region")
    position = np.full(keys.size, -1, np.int64)
    position[seeds] = np.arange(seeds.size)
    # The edges as a sparse matrix, row by row (np.nonzero gave them in row order).
    indptr = np.concatenate(([0], np.cumsum(np.bincount(rows, minlength=seeds.size))))
    graph = csr_matrix(
        (np.ones(rows.size, dtype=np.int8), position[targets], indptr),
        shape=(seeds.size, seeds.size),
    )
    _, component = connected_components(graph, directed=False)
    cluster = old_cluster.copy()
    cluster[region] = -1
    if seeds.size:
        _, first = np.unique(component, return_index=True)
        cluster[seeds] = keys[seeds[first]][component]
    # Borders: a kept voxel that is not core joins the cluster of smallest name among its core
    # neighbours; every voxel but the outer layers of box 2 is recomputed.
    inner = _inside(voxels, low2 + reach, high2 - reach)
    borders = np.flatnonzero(inner & ~core & (kept >= 0))
    if borders.size:
        cells, same = same_class(borders, steps)
        found = np.where(same, index_grid[cells], -1).astype(np.int64)
        anchor = (found >= 0) & core[np.maximum(found, 0)]
        names = np.where(anchor, cluster[np.maximum(found, 0)], np.iinfo(np.int64).max)
        best = names.min(axis=1)
        cluster[borders] = np.where(anchor.any(axis=1), best, -1)
    cluster[kept < 0] = -1
    # Summaries of every cluster whose members or rows changed.
    changed = region | (cluster != old_cluster) | (core != old_core) | ~known
    affected = np.union1d(old_cluster[changed], cluster[changed])
    affected = affected[affected >= 0]
    summaries = dict(old.summaries)
    # Their members, in key order, grouped by cluster.
    members = np.flatnonzero(np.isin(cluster, affected))
    members = members[np.argsort(cluster[members], kind="stable")]
    row_counts = np.zeros(keys.size, np.int64)
    row_sums = np.zeros((keys.size, sums.shape[1]))
    row_counts[known] = before.counts[old_index[known]]
    row_sums[known] = before.sums[old_index[known]].reshape(-1, sums.shape[1])
    row_counts[at_touched] = counts
    row_sums[at_touched] = sums
    member_counts, member_sums = row_counts[members], row_sums[members]
    _kept, member_scores, member_margins = kept_voxels(member_counts, member_sums, params)
    starts = np.searchsorted(cluster[members], affected)
    stops = np.searchsorted(cluster[members], affected, side="right")
    dirty_set = set(dirty.tolist())
    for name, start, stop in zip(affected.tolist(), starts.tolist(), stops.tolist(), strict=True):
        rows = members[start:stop]
        if name in dirty_set or name not in old.summaries:
            # Re-clustered here: every member is a local voxel.
            if start == stop:
                summaries.pop(name, None)  # the cluster is no more
                continue
            part = slice(start, stop)
            summaries[name] = cluster_summary(
                int(kept[rows[0]]),
                keys[rows],
                member_counts[part],
                member_sums[part],
                member_scores[part],
                member_margins[part],
                params,
            )
            continue
        # A cluster outside the re-clustered region whose borders changed: its members beyond
        # box 2 are as they were.
        outside = np.flatnonzero(old.cluster == name)
        outside = outside[~np.isin(outside, index2)]
        all_keys = np.concatenate((keys[rows], before.keys[outside]))
        all_counts = np.concatenate((row_counts[rows], before.counts[outside]))
        all_sums = np.concatenate((row_sums[rows], before.sums[outside].reshape(-1, sums.shape[1])))
        order = np.argsort(all_keys, kind="stable")
        all_keys, all_counts, all_sums = all_keys[order], all_counts[order], all_sums[order]
        all_kept, all_scores, all_margins = kept_voxels(all_counts, all_sums, params)
        summaries[name] = cluster_summary(
            int(all_kept[0]), all_keys, all_counts, all_sums, all_scores, all_margins, params
        )
    return keys, kept, core, cluster, summaries
