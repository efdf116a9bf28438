"""One batch of fixture masks: voxel evidence, query, DBSCAN, association (sections 3.2, 3.3)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from core.events import FixtureEvidence
from core.fixture_association import (
    FixtureTrackView,
    associate_fixtures,
    compatible,
    holds,
    same_place,
)
from core.fixtures import (
    FixtureProposal,
    VoxelEvidence,
    fixture_proposals,
    kept_voxels,
    merged_voxels,
    voxel_evidence,
)
from core.observation import Batch
from core.params import Params
from core.state import SceneState
from core.values import VoxelDetection
from core.voxels import unpack


@dataclass(frozen=True, eq=False)
class FixtureBatch:
    """What the batch's fixture masks say: new evidence, and per track the proposal it explains."""

    evidence_event: FixtureEvidence | None = None
    observed: Mapping[str, FixtureProposal] = field(default_factory=dict)  # track id -> proposal
    unexplained: tuple[FixtureProposal, ...] = ()  # new hypotheses
    proposals: tuple[FixtureProposal, ...] = ()  # every plausible cluster
    merged: Mapping[str, str] = field(default_factory=dict)  # second track -> the one it joins


def fixture_batch(
    state: SceneState, batch: Batch, params: Params, *, incremental: bool = True
) -> FixtureBatch:
    """Add the batch's fixture evidence to the voxel map, cluster it and associate the clusters.

    The clusters are the map's kept between batches, updated near the voxels the batch covered
    (`core.fixture_map`); `incremental=False` clusters the whole map anew, the reference they
    equal.
    """
    fixture_params = params.fixtures
    evidence = batch_voxel_evidence(batch, params)
    if not evidence:
        return FixtureBatch()
    evidence_event = FixtureEvidence(
        detections=tuple(
            VoxelDetection(
                frame_id=e.frame_id,
                class_scores=e.class_scores,
                voxels=tuple(unpack(e.voxels).ravel().tolist()),
            )
            for e in evidence
        )
    )
    # Query the accumulated map against the taxonomy, then cluster each class.
    if incremental:
        update = state.voxels.update(
            fixture_params, [(e.voxels, e.class_scores) for e in evidence], evidence_event
        )
        proposals = update.proposals(evidence)
    else:
        voxels = state.voxels
        keys, counts, sums = merged_voxels((voxels.keys, voxels.counts, voxels.sums), evidence)
        kept, scores, margins = kept_voxels(counts, sums, fixture_params)
        proposals = fixture_proposals(
            keys, counts, sums, kept, scores, margins, evidence, fixture_params
        )
    # A hypothesis retired unseen has left the memory in play, as retired objects do: seen
    # again, its place makes a new hypothesis. One retired by a rejection still explains its
    # cluster, so that what a verifier rejected is not proposed anew.
    tracks = [
        FixtureTrackView(t.track_id, t.label, t.center, t.extent)
        for t in (state.tracks[i] for i in sorted(state.tracks))
        if t.kind == "fixture" and (t.lifecycle != "retired" or t.verification == "rejected")
    ]
    matches, absorbed = associate_fixtures(proposals, tracks, fixture_params)
    # Positive evidence only from what this batch saw.
    observed = {
        matches[j]: p for j, p in enumerate(proposals) if j in matches and p.contributed > 0
    }
    unexplained = tuple(
        p
        for j, p in enumerate(proposals)
        if j not in matches and j not in absorbed and p.contributed > 0
    )
    merged = (
        contained_tracks(state, tracks, matches, proposals, params)
        if fixture_params.absorb_contained_tracks
        else {}
    )
    return FixtureBatch(evidence_event, observed, unexplained, tuple(proposals), merged)


def batch_voxel_evidence(batch: Batch, params: Params) -> list[VoxelEvidence]:
    """The voxels each fixture mask of the batch covers, within the batch's point and voxel
    budgets."""
    fixture_params = params.fixtures
    evidence: list[VoxelEvidence] = []
    budget = fixture_params.max_voxels_per_batch
    points = fixture_params.max_points_per_batch
    for frame in batch.frames:
        for detection in frame.detections:
            if detection.kind != "fixture":
                continue
            points -= detection.mask.area // fixture_params.mask_pixel_stride**2
            if points < 0 or budget <= 0:
                break
            item = voxel_evidence(
                detection,
                frame,
                fixture_params,
                params.visibility.min_range_m,
                params.visibility.max_range_m,
            )
            # Masks past the batch's voxel budget add nothing: a batch's evidence (and its
            # event) stays bounded whatever the detector sent, and the order decides which.
            if item is not None and item.voxels.size <= budget:
                evidence.append(item)
                budget -= item.voxels.size
    return evidence


def contained_tracks(
    state: SceneState,
    tracks: list[FixtureTrackView],
    matches: dict[int, str],
    proposals: list[FixtureProposal],
    params: Params,
) -> dict[str, str]:
    """Second tracks of one fixture: inside the expanded footprint of a confirmed track this
    batch's cluster matched, of a class that cluster supports, or of any class in the same
    place (`same_place`) with fewer supporting batches; each -> the track it joins. A pinned
    fixture (a frozen baseline's) is never one: it is exempt from dynamic removal (section
    3.3)."""
    matched = set(matches.values())
    merged: dict[str, str] = {}
    views = {view.track_id: view for view in tracks}
    for j, keeper_id in sorted(matches.items(), key=lambda item: item[1]):
        proposal = proposals[j]
        if proposal.contributed <= 0 or state.tracks[keeper_id].lifecycle != "confirmed":
            continue
        keeper = views[keeper_id]
        for other in tracks:
            track = state.tracks[other.track_id]
            if (
                other.track_id in matched
                or other.track_id in merged
                or track.lifecycle not in ("tentative", "confirmed", "demoted")
                or track.verification == "pending"
                or track.pinned
            ):
                continue
            same_class = other.label == keeper.label or compatible(
                other.label, proposal, params.fixtures
            )
            if (same_class and holds(keeper, other, params.fixtures)) or (
                track.batches_observed < state.tracks[keeper_id].batches_observed
                and same_place(keeper, other, params.fixtures)
            ):
                merged[other.track_id] = keeper_id
    return merged
