"""Dynamic association front end (section 3.3, "Type-specific association")."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from core.geometry import Proposal
from core.params import AssociationParams

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class CandidatePool:
    """The tracks a frame's proposals may match, as columns; appearance is fetched lazily."""

    track_ids: Sequence[str]
    kinds: Sequence[str]
    labels: Sequence[str]
    centers: FloatArray  # (n, 3)
    embedding_of: Callable[[int], FloatArray | None]
    eligible: npt.NDArray[np.bool_] | None = None  # rows that may be matched (None: all)
    # Rows whose identity was ever published: only those are recovered by the fallback, so a
    # retired false positive of the same class cannot make a moved object's class look shared.
    recoverable: npt.NDArray[np.bool_] | None = None


def appearance_agrees(a: FloatArray | None, b: FloatArray | None, min_cosine: float) -> bool:
    """Appearance gate: cosine > 0.78, omitted when either embedding is unavailable."""
    if a is None or b is None or a.shape != b.shape:
        return True
    return float(a @ b) > min_cosine


def associate(
    proposals: Sequence[Proposal], pool: CandidatePool, params: AssociationParams
) -> dict[int, str]:
    """Proposal index -> track id: gated greedy one-to-one, then the unique-class fallback."""
    matches: dict[int, str] = {}
    if not proposals or len(pool.track_ids) == 0:
        return matches
    pairs: list[tuple[float, str, int]] = []
    for j, proposal in enumerate(proposals):
        distances = np.linalg.norm(pool.centers - proposal.center, axis=1)
        near = distances < params.max_center_distance_m
        if pool.eligible is not None:
            near &= pool.eligible
        for i in (int(k) for k in np.flatnonzero(near)):
            if pool.kinds[i] != proposal.kind or pool.labels[i] != proposal.label:
                continue  # class agreement
            if not appearance_agrees(
                pool.embedding_of(i), proposal.embedding, params.min_appearance_cosine
            ):
                continue
            pairs.append((float(distances[i]), pool.track_ids[i], j))
    used_tracks: set[str] = set()
    for _distance, track_id, j in sorted(pairs):  # greedy by distance; ties by id, then index
        if j in matches or track_id in used_tracks:
            continue
        matches[j] = track_id
        used_tracks.add(track_id)
    if params.unique_class_fallback:
        matches.update(_unique_class_fallback(proposals, pool, matches, used_tracks, params))
    return matches


def _unique_class_fallback(
    proposals: Sequence[Proposal],
    pool: CandidatePool,
    matches: dict[int, str],
    used_tracks: set[str],
    params: AssociationParams,
) -> dict[int, str]:
    """After large motion: one unmatched proposal and one unmatched track of a class pair up."""
    free_proposals: dict[tuple[str, str], list[int]] = {}
    for j, proposal in enumerate(proposals):
        if j not in matches:
            free_proposals.setdefault((proposal.kind, proposal.label), []).append(j)
    if not free_proposals:
        return {}
    free_tracks: dict[tuple[str, str], list[int]] = {}
    for i, track_id in enumerate(pool.track_ids):
        key = (pool.kinds[i], pool.labels[i])
        if pool.eligible is not None and not pool.eligible[i]:
            continue
        if pool.recoverable is not None and not pool.recoverable[i]:
            continue
        if key in free_proposals and track_id not in used_tracks:
            free_tracks.setdefault(key, []).append(i)
    recovered: dict[int, str] = {}
    for key, proposal_indices in free_proposals.items():
        track_indices = free_tracks.get(key, [])
        if len(proposal_indices) != 1 or len(track_indices) != 1:
            continue
        j, i = proposal_indices[0], track_indices[0]
        if appearance_agrees(
            pool.embedding_of(i), proposals[j].embedding, params.min_appearance_cosine
        ):
            recovered[j] = pool.track_ids[i]
    return recovered
