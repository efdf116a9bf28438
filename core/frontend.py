"""The frame-level front end (section 3.3, "Type-specific association"): which track each
grounded proposal is, for a batch's frames and for an inspection capture's view.

Proposals match tracks by class compatibility, 3D distance < 0.8 m and appearance > 0.78,
greedily one to one, then the unique-class fallback recovers tracks whose absence is
established (`core/association.py` holds these kernels). A leftover piece of an object another
proposal shows is set aside; so is, in a batch, a proposal matching a fine node the capture
ledger holds. What no track explains is a new hypothesis. After the frames, a batch also
re-identifies missing objects with hypotheses seen since, and names second tracks of one object.

Its work is bounded by the tracks in play, not by the scene's history: retired hypotheses are
not in the state's columns at all.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from functools import partial

import numpy as np
import numpy.typing as npt

from core.association import (
    appearance_agrees,
    associate,
    fragments,
)
from core.belief import class_compatibility
from core.fixture_step import FixtureBatch
from core.fixtures import FixtureProposal
from core.geometry import Proposal
from core.params import AssociationParams, Params
from core.reidentification import claimed_hypotheses, reidentifications
from core.rules import UpdateRules
from core.state import SceneState
from core.track_arrays import TrackArrays
from core.track_columns import TrackColumns
from core.visibility import BatchVisibility

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True, eq=False)
class BatchAssociation:
    """Which track each of a batch's proposals and fixture clusters is."""

    observations: Mapping[str, tuple[Proposal, ...]]  # object track -> its proposals, in order
    fixtures: Mapping[str, FixtureProposal]  # fixture track -> the cluster it explains
    new_tracks: tuple[str, ...]  # new hypotheses in the order of their ids (fixtures first)
    merged_fixtures: Mapping[str, str]  # a second fixture track -> the one it joins
    reidentified: Mapping[str, tuple[str, float]]  # missing object -> (hypothesis, cosine)
    duplicates: Mapping[str, str]  # a second object track -> the one it joins
    # Hypotheses whose publication waits: they may be a published object carried here
    # (`core.reidentification.claimed_hypotheses`).
    held: frozenset[str]
    # Tracks the batch settles apart from sightings and misses: its new hypotheses, second
    # fixture tracks merged away, and both sides of each re-identification.
    settled: frozenset[str]


def associate_frame(
    columns: TrackColumns,
    proposals: Sequence[Proposal],
    lenders: tuple[BoolArray, BoolArray | None],
    eligible: BoolArray | None,
    params: AssociationParams,
    hold_captured: bool,
) -> list[tuple[int, str]]:
    """(proposal index, track) for each proposal of one frame that stands for an object.

    A leftover piece of an object another proposal shows (an over-segmented mask) is set aside,
    not taken for a new object; with `hold_captured`, so is a proposal matching a fine node the
    capture ledger holds: only a capture of its fixture speaks of it (section 3.3).
    """
    matches = associate(
        proposals,
        columns.pool(eligible, *lenders),
        params,
        partial(fragments, proposals, size_of=columns.extent_of, params=params),
    )
    pieces = fragments(proposals, matches, columns.extent_of, params)
    assigned = []
    for j, proposal in enumerate(proposals):
        if j in pieces or (hold_captured and j in matches and columns.held_by_capture(matches[j])):
            continue
        track_id = matches.get(j) or columns.new_track(proposal)
        columns.observe(track_id, proposal)
        assigned.append((j, track_id))
    return assigned


def associate_capture(
    state: SceneState, proposals: Sequence[Proposal], params: Params
) -> list[tuple[int, str]]:
    """The front end on an inspection capture's view: (proposal index, track) of each child."""
    columns = TrackColumns(state, state.next_track_number, params.fusion.class_evidence_from_scores)
    lenders = _lenders(state.arrays, frozenset(), columns, params)
    return associate_frame(columns, proposals, lenders, None, params.association, False)


def associate_batch(
    state: SceneState,
    fixtures: FixtureBatch,
    proposals: Sequence[Sequence[Proposal]],
    visibility: BatchVisibility,
    since: float,
    params: Params,
    rules: UpdateRules,
) -> BatchAssociation:
    """The front end over a batch's frames in order, then identities across the batch.

    New fixture hypotheses take the first new ids, then objects in the order they appear.
    """
    arrays = state.arrays
    first = state.next_track_number
    new_fixtures = tuple(f"trk-{first + i:06d}" for i in range(len(fixtures.unexplained)))
    columns = TrackColumns(
        state, first + len(new_fixtures), params.fusion.class_evidence_from_scores
    )
    eligible = _eligible(arrays, since, rules.identity_memory_s)
    for frame_proposals, shown in zip(proposals, visibility.shown, strict=True):
        lenders = _lenders(arrays, shown, columns, params)
        associate_frame(columns, frame_proposals, lenders, eligible, params.association, True)
    absent = _absent(arrays, visibility.shown[-1], columns, params)
    new_tracks = (*new_fixtures, *columns.new_ids)
    reidentified = reidentifications(columns, eligible, absent, params.association)
    return BatchAssociation(
        observations={t: tuple(p) for t, p in columns.observations.items()},
        fixtures={
            **dict(sorted(fixtures.observed.items())),
            **dict(zip(new_fixtures, fixtures.unexplained, strict=True)),
        },
        new_tracks=new_tracks,
        merged_fixtures=fixtures.merged,
        reidentified=reidentified,
        duplicates=second_tracks(columns, columns.observations, eligible, params.association),
        held=claimed_hypotheses(columns, eligible, absent, params.association),
        settled=frozenset(
            (*new_tracks, *fixtures.merged, *reidentified, *(h for h, _ in reidentified.values()))
        ),
    )


def _eligible(arrays: TrackArrays, since: float, memory: float | None) -> BoolArray | None:
    """Without persistent identity: removed and long-unseen tracks cannot be matched."""
    if memory is None:
        return None
    with np.errstate(invalid="ignore"):
        recent = arrays.last_observed >= since - memory  # NaN (never seen): False
    eligible: BoolArray = ~arrays.gone & recent
    return eligible


def _lenders(
    arrays: TrackArrays, shown: Collection[str], columns: TrackColumns, params: Params
) -> tuple[BoolArray, BoolArray | None]:
    """The tracks the unique-class fallback may lend an identity from, and those that compete
    with them without lending (None: none do).

    Ours: published tracks whose absence is established lend; the other published ones, not
    removed, compete (`unrefuted_rivals`). The paper's (`fallback_requires_absence` False): any
    track lends (the frame's matches are excluded when it runs)."""
    if not params.association.fallback_requires_absence:
        return np.ones(len(arrays.track_ids), dtype=np.bool_), None
    absent = _absent(arrays, shown, columns, params)
    recoverable: BoolArray = arrays.published & absent
    if not params.association.unrefuted_rivals:
        return recoverable, None
    rivals: BoolArray = arrays.published & ~absent & ~arrays.gone
    return recoverable, rivals


def _absent(
    arrays: TrackArrays, shown: Collection[str], columns: TrackColumns, params: Params
) -> BoolArray:
    """Absence established: removed or demoted, or its place seen empty in enough batches
    (this one counting once when it showed the place and no proposal matched the track)."""
    seen_empty = np.zeros(len(arrays.track_ids), dtype=np.int64)
    for track_id in shown:
        if track_id not in columns.observations:
            seen_empty[columns.row[track_id]] = 1
    misses = arrays.visible_misses + seen_empty
    absent: BoolArray = arrays.missing | (misses >= params.association.fallback_min_misses)
    return absent


def second_tracks(
    columns: TrackColumns,
    observed: Collection[str],
    eligible: BoolArray | None,
    params: AssociationParams,
) -> dict[str, str]:
    """Second tracks of one object: a live track whose center lies inside the object box
    (center and extent) of a track this batch matched (`observed`), or whose box holds that
    track's center, of a compatible class and appearance, neither one missing; the younger one
    -> the older (an unpublished one -> a published one)."""
    arrays = columns.state.arrays
    count = len(arrays.track_ids)
    if not params.absorb_contained_tracks or count < 2:
        return {}
    live = ~arrays.gone & ~arrays.captured & ~arrays.missing
    objects = live & arrays.objects
    if eligible is not None:  # a track association may not match is not one either
        objects &= eligible
    rows = np.flatnonzero(objects)
    centers, half = arrays.centers[rows], arrays.extents[rows] / 2
    widest = half[:, 0].max(initial=0.0)
    merged: dict[str, str] = {}
    for track_id in sorted(observed):
        row = columns.row[track_id]
        if row >= count or not objects[row] or track_id in merged:
            continue
        # x first (one axis over every candidate), then the whole test on the few left.
        mine = arrays.extents[row] / 2
        near = np.flatnonzero(
            np.abs(centers[:, 0] - arrays.centers[row, 0]) <= max(mine[0], widest)
        )
        gap = np.abs(centers[near] - arrays.centers[row])
        held = (gap <= mine).all(axis=1) | (gap <= half[near]).all(axis=1)
        for other in rows[near[held]].tolist():
            other_id = arrays.track_ids[other]
            if other == row or other_id in observed or other_id in merged:
                continue
            if not _same_object(columns, row, other, params):
                continue
            keep, drop = sorted((track_id, other_id))  # ids grow with age
            if arrays.published[columns.row[drop]] and not arrays.published[columns.row[keep]]:
                keep, drop = drop, keep
            if drop in merged.values():
                continue  # it keeps another track this batch: no chain of merges
            merged[drop] = keep
            if drop == track_id:
                break
    return merged


def _same_object(columns: TrackColumns, row: int, other: int, params: AssociationParams) -> bool:
    compatible = (
        class_compatibility(columns.class_belief_of(row), columns.class_belief_of(other))
        >= params.min_class_compatibility
    )
    return compatible and appearance_agrees(
        columns.embedding_of(row), columns.embedding_of(other), params.min_appearance_cosine
    )
