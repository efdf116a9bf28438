"""The deferred fallback and the hand-over (section 3.3, unique-class fallback; ours): which
missing objects are tracks seen since elsewhere, once a batch's frames are associated.

The scores are computed as matrices over the tracks in play, so that a scene with hundreds of
published tracks and a few missing ones pays a matrix product per batch, not a Python call per
pair: the time condition and appearance for every pair, class compatibility only for the pairs
whose appearance could matter.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from core.belief import class_compatibility
from core.params import AssociationParams
from core.track_columns import TrackColumns

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
Rows = npt.NDArray[np.intp]


def reidentifications(
    columns: TrackColumns, eligible: BoolArray | None, absent: BoolArray, params: AssociationParams
) -> dict[str, tuple[str, float]]:
    """Missing objects that are tracks seen since elsewhere: object -> (track, appearance
    cosine).

    The object: published, its absence established, not matched in this batch. The other: an
    object track not matched in this batch, never published and last seen after the object
    was, or (`reidentify_published`) published, not itself seen empty, and first seen after
    the object was last seen. Their classes are compatible, and each is the other's best
    appearance match past the gate, by the fallback margin over every other candidate on
    either side, the unrefuted tracks of the class included (`unrefuted_rivals`): a mug carried
    among mugs keeps its identity; a mug still in place lends none.
    """
    if not (params.unique_class_fallback and params.reidentify_hypotheses):
        return {}
    arrays = columns.state.arrays
    objects = _unmatched_objects(columns, eligible)
    missing = objects & arrays.published & absent
    if not missing.any():
        return {}
    objects &= ~arrays.gone
    unrefuted = objects & arrays.published & ~absent
    candidates = objects & arrays.unpublished_tentative
    if params.reidentify_published:
        candidates |= unrefuted
    lenders = np.flatnonzero(missing)
    rows = np.flatnonzero(candidates)
    since = _seen_since(columns, rows)
    # Only a track seen after some missing object was can be one of them.
    rows = rows[(arrays.last_observed[lenders][None, :] < since[:, None]).any(axis=1)]
    if rows.size == 0:
        return {}
    lent = _scores(columns, rows, lenders, params)
    passing = lent > params.min_appearance_cosine
    hopeful = np.flatnonzero(passing.any(axis=1))
    if hopeful.size == 0:
        return {}
    rivals = np.flatnonzero(unrefuted) if params.unrefuted_rivals else np.zeros(0, np.intp)
    rival = dict(
        zip(hopeful.tolist(), _scores(columns, rows[hopeful], rivals, params), strict=True)
    )
    found = {}
    for i, j in zip(*np.nonzero(passing), strict=True):
        best = float(lent[i, j])
        others = np.concatenate((np.delete(lent[i], j), rival[int(i)], np.delete(lent[:, j], i)))
        if others.size == 0 or best - float(others.max()) >= params.fallback_margin:
            # The event records the pair's own dot product (the matrix's may differ in the
            # last bit).
            a, b = columns.embedding_of(int(rows[i])), columns.embedding_of(int(lenders[j]))
            assert a is not None and b is not None
            found[arrays.track_ids[lenders[j]]] = (arrays.track_ids[rows[i]], float(a @ b))
    return found


def claimed_hypotheses(
    columns: TrackColumns, eligible: BoolArray | None, absent: BoolArray, params: AssociationParams
) -> frozenset[str]:
    """The hypotheses this batch sighted whose publication waits (`claimed_hold_max_batches`):
    never published, seen in at most that many batches, whose best appearance match among the
    published objects of a compatible class last seen before them (missing or unrefuted) that
    this batch did not see passes the gate by the fallback margin and beats every other one by
    the margin: a single known object it may well be, not one of several look-alikes."""
    limit = params.claimed_hold_max_batches
    if limit <= 0 or not params.unique_class_fallback:
        return frozenset()
    state, arrays = columns.state, columns.state.arrays
    hypotheses = []
    for track_id in columns.observations:
        row = columns.row[track_id]
        old = row < columns.count
        if old and not arrays.unpublished_tentative[row]:
            continue
        if (state.tracks[track_id].batches_observed if old else 0) + 1 <= limit:
            hypotheses.append(row)
    if not hypotheses:
        return frozenset()
    claimants = _unmatched_objects(columns, eligible) & arrays.published
    claimants &= absent | ~arrays.gone  # a removed object still claims; a rejected one does not
    rows = np.asarray(hypotheses, dtype=np.intp)
    scores = _scores(columns, rows, np.flatnonzero(claimants), params)
    if scores.shape[1] == 0:
        return frozenset()
    ranked = -np.sort(-scores, axis=1)
    best = ranked[:, 0]
    runner_up = ranked[:, 1] if scores.shape[1] > 1 else np.full(rows.size, -1.0)
    margin = params.fallback_margin
    claimed = (best > params.min_appearance_cosine + margin) & (best - runner_up >= margin)
    return frozenset(columns.ids[row] for row in rows[claimed].tolist())


def _unmatched_objects(columns: TrackColumns, eligible: BoolArray | None) -> BoolArray:
    """The state's object tracks the front end may weigh here: not held by the capture ledger,
    eligible, and not matched in this batch."""
    arrays = columns.state.arrays
    objects: BoolArray = arrays.objects & ~arrays.captured
    if eligible is not None:
        objects &= eligible
    for track_id in columns.observations:
        row = columns.row[track_id]
        if row < columns.count:
            objects[row] = False
    return objects


def _seen_since(columns: TrackColumns, rows: Rows) -> FloatArray:
    """When each candidate was seen, as the time condition reads it: a published track's first
    observation (one seen while the object still was is another object), a hypothesis's last;
    one created in this batch, now (after every track of the state)."""
    arrays, tracks = columns.state.arrays, columns.state.tracks
    since = np.full(rows.size, np.inf)
    old = rows < columns.count
    known = rows[old]
    first = np.array(
        [tracks[arrays.track_ids[row]].first_observed for row in known.tolist()], dtype=np.float64
    )
    since[old] = np.where(arrays.published[known], first, arrays.last_observed[known])
    return since


def _scores(
    columns: TrackColumns, rows: Rows, others: Rows, params: AssociationParams
) -> FloatArray:
    """Appearance cosine of every (row, other) pair that may be one object: the other last seen
    before the row was (`_seen_since`), not the row itself, both with appearance of one
    dimension, classes compatible; -1 for every other pair. Class compatibility is computed
    only where the cosine could matter (within the margin of the gate or above)."""
    scores = np.full((rows.size, others.size), -1.0)
    if rows.size == 0 or others.size == 0:
        return scores
    arrays = columns.state.arrays
    since = _seen_since(columns, rows)
    possible = (arrays.last_observed[others][None, :] < since[:, None]) & (
        rows[:, None] != others[None, :]
    )
    row_vectors, row_valid = _embeddings(columns, rows)
    other_vectors, other_valid = _embeddings(columns, others, row_vectors.shape[1])
    possible &= row_valid[:, None] & other_valid[None, :]
    cosine = row_vectors @ other_vectors.T
    floor = params.min_appearance_cosine - params.fallback_margin
    for i, j in zip(*np.nonzero(possible & (cosine > floor)), strict=True):
        belief, other = (
            columns.class_belief_of(int(rows[i])),
            columns.class_belief_of(int(others[j])),
        )
        if class_compatibility(belief, other) >= params.min_class_compatibility:
            scores[i, j] = cosine[i, j]
    return scores


def _embeddings(
    columns: TrackColumns, rows: Rows, dimension: int | None = None
) -> tuple[FloatArray, BoolArray]:
    """The rows' appearance vectors (zeros where missing or of another dimension) and which are
    valid; the dimension is the first vector's unless given."""
    vectors = [columns.embedding_of(int(row)) for row in rows]
    if dimension is None:
        dimension = next((v.shape[0] for v in vectors if v is not None), 1)
    valid = np.array([v is not None and v.shape == (dimension,) for v in vectors], dtype=np.bool_)
    matrix = np.zeros((len(vectors), dimension))
    for k, vector in enumerate(vectors):
        if valid[k]:
            matrix[k] = vector
    return matrix, valid
