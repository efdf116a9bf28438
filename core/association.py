"""Dynamic association front end (section 3.3, "Type-specific association").

Proposals match tracks by class compatibility, 3D distance < 0.8 m and appearance cosine > 0.78
(omitted when an embedding is missing), greedily one to one. A detector's label flickers between
confusable classes (cup/mug), so class agreement is the compatibility of the proposal's class
scores with the track's class belief, not equality of two labels. Then the unique-class fallback
recovers an identity after large motion, but only of a track whose absence is established.
Last, a proposal left over that is only a piece of an object another proposal of the frame
shows (an over-segmented mask) is set aside rather than taken for a new object.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from core.belief import class_distribution, classes_agree
from core.geometry import Proposal
from core.params import AssociationParams

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class CandidatePool:
    """The tracks a frame's proposals may match, as columns; appearance is fetched lazily."""

    track_ids: Sequence[str]
    kinds: Sequence[str]
    class_belief_of: Callable[[int], Mapping[str, float]]  # p_cls of a row, fetched lazily
    centers: FloatArray  # (n, 3)
    embedding_of: Callable[[int], FloatArray | None]
    eligible: npt.NDArray[np.bool_] | None = None  # rows that may be matched (None: all)
    # Rows the fallback may recover: identities that were published and whose absence is
    # established (removed, demoted, or missed where they were). A track still in place, or a
    # retired false positive, never lends its identity to an object seen elsewhere.
    recoverable: npt.NDArray[np.bool_] | None = None
    # Rows that compete with them without lending (`unrefuted_rivals`): published tracks whose
    # absence is not established. When one is the best match, the object may be it: no lending.
    rivals: npt.NDArray[np.bool_] | None = None


def appearance_agrees(a: FloatArray | None, b: FloatArray | None, min_cosine: float) -> bool:
    """Appearance gate: cosine > 0.78, omitted when either embedding is unavailable."""
    if a is None or b is None or a.shape != b.shape:
        return True
    return float(a @ b) > min_cosine


def associate(
    proposals: Sequence[Proposal],
    pool: CandidatePool,
    params: AssociationParams,
    pieces_of: Callable[[Mapping[int, str]], set[int]] | None = None,
) -> dict[int, str]:
    """Proposal index -> track id: gated greedy one-to-one, then the unique-class fallback.

    `pieces_of(matches)` names the unmatched proposals that are pieces of an object a matched
    proposal shows (`fragments`): the fallback lends them no identity, as a second mask of an
    object already explained is no sighting of a missing one.
    """
    matches: dict[int, str] = {}
    if not proposals or len(pool.track_ids) == 0:
        return matches
    pairs: list[tuple[float, str, int]] = []
    reach = params.max_center_distance_m
    for j, (rows, distances) in enumerate(_distances(proposals, pool.centers, reach)):
        proposal = proposals[j]
        near = distances < reach
        if pool.eligible is not None:
            near &= pool.eligible[rows]
        observed = class_distribution(proposal.label, proposal.class_scores)
        for i, distance in zip(rows[near].tolist(), distances[near].tolist(), strict=True):
            if pool.kinds[i] != proposal.kind:
                continue
            if not classes_agree(pool.class_belief_of(i), proposal.label, observed, params):
                continue
            if not appearance_agrees(
                pool.embedding_of(i), proposal.embedding, params.min_appearance_cosine
            ):
                continue
            pairs.append((distance, pool.track_ids[i], j))
    used_tracks: set[str] = set()
    for _distance, track_id, j in sorted(pairs):  # greedy by distance; ties by id, then index
        if j in matches or track_id in used_tracks:
            continue
        matches[j] = track_id
        used_tracks.add(track_id)
    recoverable = pool.recoverable is not None and bool(pool.recoverable.any())
    if params.unique_class_fallback and recoverable and len(matches) < len(proposals):
        pieces = set() if pieces_of is None else pieces_of(matches)  # only when it can matter
        matches.update(_fallback(proposals, pool, matches, used_tracks, pieces, params))
    return matches


def _distances(
    proposals: Sequence[Proposal], centers: FloatArray, reach: float
) -> Iterator[tuple[npt.NDArray[np.intp], FloatArray]]:
    """Per proposal: the rows of the tracks within `reach` of all the proposals' box on every
    axis (no other track is within `reach` of any proposal), and each one's distance to the
    proposal, the value `np.linalg.norm(..., axis=1)` gives ((dx^2 + dy^2) + dz^2, rooted),
    computed by columns for many proposals at once, a few megabytes at a time."""
    points = np.array([p.center for p in proposals], dtype=np.float64)
    # The box is widened past `reach` by far more than a rounding error, so that no track the
    # norm puts within reach falls outside it (a track outside is farther on one axis alone).
    margin = reach + 1e-6 + 1e-9 * float(np.abs(points).max())
    low, high = points.min(axis=0) - margin, points.max(axis=0) + margin
    rows = np.flatnonzero(((centers >= low) & (centers <= high)).all(axis=1))
    columns = np.ascontiguousarray(centers[rows].T)
    per_chunk = max(1, (1 << 18) // max(1, rows.size))
    for start in range(0, len(proposals), per_chunk):
        chunk = points[start : start + per_chunk]
        total = np.zeros((chunk.shape[0], rows.size))
        for axis in range(3):
            offset = columns[axis][None, :] - chunk[:, axis, None]
            total += offset * offset
        for distances in np.sqrt(total):
            yield rows, distances


def _fallback(
    proposals: Sequence[Proposal],
    pool: CandidatePool,
    matches: dict[int, str],
    used_tracks: set[str],
    pieces: set[int],
    params: AssociationParams,
) -> dict[int, str]:
    """After large motion: an unmatched proposal recovers a missing track of its class.

    Candidates are the recoverable tracks of a compatible class. With appearance on both sides,
    the most similar one wins when it passes the gate and beats the runner-up by the margin (the
    re-identification that lets a carried mug keep its identity among other mugs). Without it,
    the pairing must be unique: one unmatched proposal of the class and one candidate.
    """
    assert pool.recoverable is not None

    def unmatched(mask: npt.NDArray[np.bool_] | None) -> list[int]:
        if mask is None:
            return []
        return [
            int(i)
            for i in np.flatnonzero(mask)
            if pool.track_ids[int(i)] not in used_tracks
            and (pool.eligible is None or pool.eligible[int(i)])
        ]

    candidates = unmatched(pool.recoverable)
    rivals = unmatched(pool.rivals)
    free = [j for j in range(len(proposals)) if j not in matches and j not in pieces]
    recovered: dict[int, str] = {}
    taken: set[int] = set()
    for j in free:
        proposal = proposals[j]
        observed = class_distribution(proposal.label, proposal.class_scores)

        same_class = _of_class(candidates, proposal, observed, pool, taken, params)
        if not same_class:
            continue
        unrefuted = _of_class(rivals, proposal, observed, pool, taken, params)
        choice = (
            _by_appearance(proposal, same_class, pool, params, unrefuted)
            if params.fallback_ranks_by_appearance
            else None
        )
        if choice is None:
            rivals_of_proposal = [
                k
                for k in free
                if k != j
                and proposals[k].kind == proposal.kind
                and _proposals_agree(proposals[k], proposal, params)
            ]
            if (
                len(same_class) != 1
                or unrefuted
                or rivals_of_proposal
                or not _appearance_allows(proposal, same_class[0], pool, params)
            ):
                continue
            choice = same_class[0]
        recovered[j] = pool.track_ids[choice]
        taken.add(choice)
    return recovered


def _of_class(
    rows: Sequence[int],
    proposal: Proposal,
    observed: Mapping[str, float],
    pool: CandidatePool,
    taken: set[int],
    params: AssociationParams,
) -> list[int]:
    """The rows of a class compatible with the proposal's (`observed` its class evidence)."""
    return [
        i
        for i in rows
        if i not in taken
        and pool.kinds[i] == proposal.kind
        and classes_agree(pool.class_belief_of(i), proposal.label, observed, params)
    ]


def _by_appearance(
    proposal: Proposal,
    rows: Sequence[int],
    pool: CandidatePool,
    params: AssociationParams,
    rivals: Sequence[int] = (),
) -> int | None:
    """The row whose appearance passes the gate and beats every other, rivals included, by the
    margin, if any; None too when a rival is the best match (it may be the object)."""
    if proposal.embedding is None:
        return None
    scored = []
    for row in (*rows, *rivals):
        embedding = pool.embedding_of(row)
        if embedding is None or embedding.shape != proposal.embedding.shape:
            return None  # one candidate cannot be compared: appearance cannot decide
        scored.append((float(embedding @ proposal.embedding), row in rows, row))
    scored.sort(reverse=True)
    best, lends, row = scored[0]
    runner_up = scored[1][0] if len(scored) > 1 else -1.0
    if lends and best > params.min_appearance_cosine and best - runner_up >= params.fallback_margin:
        return row
    return None


def _appearance_allows(
    proposal: Proposal, row: int, pool: CandidatePool, params: AssociationParams
) -> bool:
    return appearance_agrees(
        pool.embedding_of(row), proposal.embedding, params.min_appearance_cosine
    )


def fragments(
    proposals: Sequence[Proposal],
    matches: Mapping[int, str],
    size_of: Callable[[str], FloatArray],
    params: AssociationParams,
) -> set[int]:
    """Unmatched proposals that are pieces of an object another proposal of this frame shows.

    A detector may report one object as two masks. The leftover piece is not a new object when
    it has a compatible class and appearance and its box, joined with the box of a proposal
    that stands for the object (matched to a track, or kept before it as the larger new one),
    stays within `fragment_max_growth` times the object's size (`size_of` its track, or the
    kept proposal's own extent) on every axis.
    """
    growth = params.fragment_max_growth
    if growth <= 0.0:
        return set()
    references: list[tuple[Proposal, FloatArray]] = [
        (proposals[j], np.maximum(size_of(track_id), proposals[j].extent))
        for j, track_id in sorted(matches.items())
    ]
    leftover = sorted(
        (j for j in range(len(proposals)) if j not in matches),
        key=lambda j: (-proposals[j].valid_pixels, j),
    )
    pieces: set[int] = set()
    for j in leftover:
        proposal = proposals[j]
        if any(_piece_of(proposal, whole, size, params) for whole, size in references):
            pieces.add(j)
        else:
            references.append((proposal, proposal.extent))
    return pieces


def _piece_of(
    piece: Proposal, whole: Proposal, size: FloatArray, params: AssociationParams
) -> bool:
    if piece.kind != whole.kind:
        return False
    if not _proposals_agree(whole, piece, params):
        return False
    if not appearance_agrees(whole.embedding, piece.embedding, params.min_appearance_cosine):
        return False
    low = np.minimum(piece.center - piece.extent / 2, whole.center - whole.extent / 2)
    high = np.maximum(piece.center + piece.extent / 2, whole.center + whole.extent / 2)
    return bool(np.all(high - low <= params.fragment_max_growth * upright_size(size)))


def _proposals_agree(a: Proposal, b: Proposal, params: AssociationParams) -> bool:
    """Class agreement of two detections (the gate's, with `a`'s evidence as the belief)."""
    return classes_agree(
        class_distribution(a.label, a.class_scores),
        b.label,
        class_distribution(b.label, b.class_scores),
        params,
    )


def upright_size(size: FloatArray) -> FloatArray:
    """An object's size as the fragment rule bounds it: its larger horizontal side on both
    horizontal axes, its height on z. Objects rest upright but turn freely about the vertical,
    and one view shows only part of the side that faces away: a box seen end-on has a narrow
    stored box along its long side."""
    horizontal = max(float(size[0]), float(size[1]))
    return np.array([horizontal, horizontal, float(size[2])])
