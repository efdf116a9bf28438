"""The fixture map's DBSCAN clusters recomputed near the voxels one batch touched (section 3.2).

`core.fixture_map` keeps the clusters between batches; this is their local update, which gives
exactly what clustering the whole map anew would (see that module's docstring for why):

- core flags are recounted within eps of a touched voxel;
- box 1 (the touched voxels and two neighbourhoods around them) and every cluster whose box
  meets it ("dirty") are re-clustered whole: components of their core voxels;
- border voxels join the core neighbour cluster of smallest name, recomputed in box 2 (box 1,
  the dirty clusters and two neighbourhoods around them);
- every cluster whose members or rows changed gets a new summary.

The work is a dense grid over box 2, with neighbours as flat index offsets.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import numpy.typing as npt
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from core.fixtures import ClusterSummary, cluster_summary, kept_voxels
from core.params import FixtureParams
from core.voxels import MASK, OFFSET, pack, unpack

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

# The local grid of one update holds at most this many cells (about 100 MB of int32 indices
# at the limit); a batch whose neighbourhood spans more re-clusters the whole map instead.
# An implementation bound, not a constant of the method: it changes the cost, not the result.
MAX_GRID_CELLS = 24_000_000


class MapRows(Protocol):
    """The rows of a voxel map: sorted packed keys, mask counts, class-score sums."""

    @property
    def keys(self) -> IntArray: ...
    @property
    def counts(self) -> IntArray: ...
    @property
    def sums(self) -> FloatArray: ...


@dataclass(frozen=True, eq=False)
class Clusters:
    """DBSCAN of a map's kept voxels, per voxel (aligned with the map's keys) and per cluster."""

    params: FixtureParams
    kept: IntArray  # class index per voxel, -1 when the voxel is dropped
    core: BoolArray
    cluster: IntArray  # the cluster's name (its smallest core key) per voxel, -1 for none
    summaries: Mapping[int, ClusterSummary]  # name -> summary


LocalClusters = tuple[IntArray, IntArray, BoolArray, IntArray, dict[int, ClusterSummary]]


def new_keys(keys: IntArray, touched: IntArray) -> tuple[IntArray, IntArray]:
    """(the touched keys not in `keys`, where they go in them)."""
    where = np.searchsorted(keys, touched)
    present = where < keys.size
    present[present] = keys[where[present]] == touched[present]
    return touched[~present], where[~present]


def local_update(
    before: MapRows,
    old: Clusters,
    touched: IntArray,
    counts: IntArray,
    sums: FloatArray,
    offsets: IntArray,
) -> LocalClusters | None:
    """(keys, kept, core, cluster, summaries) of the voxels near the touched ones after the
    batch (`counts` and `sums`: the touched rows after it), or None when the local grid would
    be too large."""
    boxes = _boxes(old, touched, offsets)
    if boxes is None:
        return None
    grid = _grid(before, old, touched, kept_voxels(counts, sums, old.params)[0], boxes, offsets)
    core = _core_flags(grid, boxes, old.params)
    region, cluster = _components(grid, boxes, core)
    cluster = _borders(grid, boxes, core, cluster)
    summaries = _summaries(before, old, grid, boxes, core, cluster, region, (counts, sums))
    return grid.keys, grid.kept, core, cluster, summaries


@dataclass(frozen=True)
class _Boxes:
    """Box 1 (where core flags and clusters may change), the dirty clusters, box 2 (the grid)."""

    low1: IntArray
    high1: IntArray
    dirty: IntArray  # sorted names of the clusters re-clustered whole
    low2: IntArray
    high2: IntArray
    shape: IntArray  # of the grid over box 2, one empty cell of padding on every side
    reach: int  # the largest offset along an axis


def _boxes(old: Clusters, touched: IntArray, offsets: IntArray) -> _Boxes | None:
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
    return _Boxes(low1, high1, dirty, low2, high2, shape, reach)


@dataclass(frozen=True, eq=False)
class _Grid:
    """The local points (the map's voxels in box 2 and the new touched ones, in key order) and
    a dense grid over box 2: which local voxel is in a cell, and its class."""

    keys: IntArray
    voxels: IntArray
    index2: IntArray  # the map's rows in box 2
    old_index: IntArray  # each local point's row in the map, -1 for a new one
    at_touched: IntArray  # where the touched keys are among the local points
    kept: IntArray  # class index after the batch
    old_core: BoolArray
    old_cluster: IntArray
    flat: IntArray  # each local point's cell
    index_grid: npt.NDArray[np.int32]
    class_grid: npt.NDArray[np.int16]
    steps: IntArray  # the offsets as flat index steps

    @property
    def known(self) -> BoolArray:
        """Local points the map held before the batch."""
        known: BoolArray = self.old_index >= 0
        return known

    def same_class(self, points: IntArray, along: IntArray) -> tuple[IntArray, BoolArray]:
        """(neighbour cells, whether each holds a voxel of the point's class) per point."""
        cells = self.flat[points][:, None] + along[None, :]
        kept = self.kept[points]
        same = (self.class_grid[cells] == kept[:, None]) & (kept >= 0)[:, None]
        return cells, same


def _grid(
    before: MapRows,
    old: Clusters,
    touched: IntArray,
    touched_kept: IntArray,
    boxes: _Boxes,
    offsets: IntArray,
) -> _Grid:
    index2, voxels2 = _in_box(before.keys, boxes.low2, boxes.high2)
    fresh, _ = new_keys(before.keys, touched)
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
    shape = boxes.shape
    strides = np.array([shape[1] * shape[2], shape[2], 1], dtype=np.int64)
    flat = (voxels - boxes.low2 + 1) @ strides
    index_grid = np.full(int(math.prod(shape.tolist())), -1, dtype=np.int32)
    index_grid[flat] = np.arange(keys.size, dtype=np.int32)
    class_grid = np.full(index_grid.size, -1, dtype=np.int16)
    class_grid[flat] = kept
    return _Grid(
        keys,
        voxels,
        index2,
        old_index,
        at_touched,
        kept,
        old_core,
        old_cluster,
        flat,
        index_grid,
        class_grid,
        offsets @ strides,
    )


def _core_flags(grid: _Grid, boxes: _Boxes, params: FixtureParams) -> BoolArray:
    """Core flags within eps of a touched voxel (and a little beyond): the degree counts the
    same-class voxels within eps, the voxel itself included."""
    reach = boxes.reach
    near1 = _inside(grid.voxels, boxes.low1 + reach, boxes.high1 - reach)
    core = grid.old_core.copy()
    recount = np.flatnonzero(near1)
    degree = grid.same_class(recount, grid.steps)[1].sum(axis=1)
    core[recount] = (grid.kept[recount] >= 0) & (degree >= params.dbscan_min_points)
    return core


def _components(grid: _Grid, boxes: _Boxes, core: BoolArray) -> tuple[BoolArray, IntArray]:
    """Box 1 and the dirty clusters re-clustered whole: components of their core voxels (each
    edge looked up once, along the offsets that point forward in the grid), named by their
    smallest key. Returns the re-clustered region and every local point's cluster."""
    region = _inside(grid.voxels, boxes.low1, boxes.high1) | np.isin(grid.old_cluster, boxes.dirty)
    seeds = np.flatnonzero(region & core)
    cells, same = grid.same_class(seeds, grid.steps[grid.steps > 0])
    rows, columns = np.nonzero(same)
    targets = grid.index_grid[cells[rows, columns]].astype(np.int64)
    linked = core[targets]
    rows, targets = rows[linked], targets[linked]
    if not region[targets].all():  # the core edges of the region stay inside it
        raise AssertionError("fixture clusters: a core edge leaves the re-clustered region")
    position = np.full(grid.keys.size, -1, np.int64)
    position[seeds] = np.arange(seeds.size)
    # The edges as a sparse matrix, row by row (np.nonzero gave them in row order).
    indptr = np.concatenate(([0], np.cumsum(np.bincount(rows, minlength=seeds.size))))
    graph = csr_matrix(
        (np.ones(rows.size, dtype=np.int8), position[targets], indptr),
        shape=(seeds.size, seeds.size),
    )
    _, component = connected_components(graph, directed=False)
    cluster = grid.old_cluster.copy()
    cluster[region] = -1
    if seeds.size:
        _, first = np.unique(component, return_index=True)
        cluster[seeds] = grid.keys[seeds[first]][component]
    return region, cluster


def _borders(grid: _Grid, boxes: _Boxes, core: BoolArray, cluster: IntArray) -> IntArray:
    """A kept voxel that is not core joins the cluster of smallest name among its core
    neighbours; every voxel but the outer layers of box 2 is recomputed."""
    reach = boxes.reach
    inner = _inside(grid.voxels, boxes.low2 + reach, boxes.high2 - reach)
    borders = np.flatnonzero(inner & ~core & (grid.kept >= 0))
    cluster = cluster.copy()
    if borders.size:
        cells, same = grid.same_class(borders, grid.steps)
        found = np.where(same, grid.index_grid[cells], -1).astype(np.int64)
        anchor = (found >= 0) & core[np.maximum(found, 0)]
        names = np.where(anchor, cluster[np.maximum(found, 0)], np.iinfo(np.int64).max)
        best = names.min(axis=1)
        cluster[borders] = np.where(anchor.any(axis=1), best, -1)
    cluster[grid.kept < 0] = -1
    return cluster


def _summaries(
    before: MapRows,
    old: Clusters,
    grid: _Grid,
    boxes: _Boxes,
    core: BoolArray,
    cluster: IntArray,
    region: BoolArray,
    touched_rows: tuple[IntArray, FloatArray],
) -> dict[int, ClusterSummary]:
    """Summaries of every cluster whose members or rows changed; the others as they were."""
    params, keys, known = old.params, grid.keys, grid.known
    changed = region | (cluster != grid.old_cluster) | (core != grid.old_core) | ~known
    affected = np.union1d(grid.old_cluster[changed], cluster[changed])
    affected = affected[affected >= 0]
    summaries = dict(old.summaries)
    # Their members, in key order, grouped by cluster.
    members = np.flatnonzero(np.isin(cluster, affected))
    members = members[np.argsort(cluster[members], kind="stable")]
    counts, sums = touched_rows
    width = sums.shape[1]
    row_counts = np.zeros(keys.size, np.int64)
    row_sums = np.zeros((keys.size, width))
    row_counts[known] = before.counts[grid.old_index[known]]
    row_sums[known] = before.sums[grid.old_index[known]].reshape(-1, width)
    row_counts[grid.at_touched] = counts
    row_sums[grid.at_touched] = sums
    member_counts, member_sums = row_counts[members], row_sums[members]
    _kept, member_scores, member_margins = kept_voxels(member_counts, member_sums, params)
    starts = np.searchsorted(cluster[members], affected)
    stops = np.searchsorted(cluster[members], affected, side="right")
    dirty = set(boxes.dirty.tolist())
    for name, start, stop in zip(affected.tolist(), starts.tolist(), stops.tolist(), strict=True):
        rows = members[start:stop]
        if name in dirty or name not in old.summaries:
            # Re-clustered here: every member is a local voxel.
            if start == stop:
                summaries.pop(name, None)  # the cluster is no more
                continue
            part = slice(start, stop)
            summaries[name] = cluster_summary(
                int(grid.kept[rows[0]]),
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
        outside = outside[~np.isin(outside, grid.index2)]
        all_keys = np.concatenate((keys[rows], before.keys[outside]))
        all_counts = np.concatenate((row_counts[rows], before.counts[outside]))
        all_sums = np.concatenate((row_sums[rows], before.sums[outside].reshape(-1, width)))
        order = np.argsort(all_keys, kind="stable")
        all_keys, all_counts, all_sums = all_keys[order], all_counts[order], all_sums[order]
        all_kept, all_scores, all_margins = kept_voxels(all_counts, all_sums, params)
        summaries[name] = cluster_summary(
            int(all_kept[0]), all_keys, all_counts, all_sums, all_scores, all_margins, params
        )
    return summaries


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
