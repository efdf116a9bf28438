"""Existence updates: equation (3) for every track a batch, a verdict or a capture speaks of
(section 3.3, "Persistent state fusion" and "Visibility-gated existence").

    l_t = l_{t-1} + eta_o O + eta_c K - eta_m U V - eta_r R      (`core.belief.update_existence`)

A sighted track gains eta_o (O = 1) when the match corroborates it; an unmatched track loses
eta_m only when the visibility gate says it was observable (U V = 1); a verdict adds eta_c or
subtracts eta_r. Each update also carries the fused values its event records: the fixture
center's EMA, the batch's appearance, the best frame to crop.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from core.belief import update_existence
from core.decisions import (
    Existence,
    FixtureSighting,
    Miss,
    ObjectSighting,
    Reidentification,
    Verdict,
)
from core.fixtures import FixtureProposal, ema_center
from core.frontend import BatchAssociation
from core.geometry import Proposal
from core.params import Params
from core.state import SceneState, Track, logistic
from core.values import vec3
from core.visibility import BatchVisibility, Sighting


@dataclass(frozen=True)
class BatchUpdates:
    """One update per track the batch has evidence about."""

    new: tuple[ObjectSighting | FixtureSighting, ...]  # new hypotheses, in the order of their ids
    existing: Mapping[str, ObjectSighting | FixtureSighting | Miss]  # of existing tracks
    reidentified: tuple[Reidentification, ...]  # by object track id


def existence_updates(
    state: SceneState,
    association: BatchAssociation,
    parents: Mapping[str, tuple[str | None, ...]],
    visibility: BatchVisibility,
    last_frame: str,
    timestamp: float,
    params: Params,
) -> BatchUpdates:
    """Equation (3) once per track per batch: new hypotheses, positive batches, visible misses
    (U V = 1: unmatched, and observable), re-identified objects. A second fixture track merged
    away, and both sides of a re-identification, take no other update."""
    tracks, fixtures, observations = state.tracks, association.fixtures, association.observations
    new: list[ObjectSighting | FixtureSighting] = [
        new_fixture(track_id, fixtures[track_id], last_frame, timestamp, params)
        if track_id in fixtures
        else object_sighting(None, track_id, observations[track_id], parents[track_id], params)
        for track_id in association.new_tracks
    ]
    skipped = association.settled
    existing: dict[str, ObjectSighting | FixtureSighting | Miss] = {}
    for track_id, proposal in fixtures.items():
        if track_id in skipped:
            continue
        update = fixture_sighting(tracks[track_id], proposal, last_frame, timestamp, params)
        if update is not None:  # a fixture a verifier rejected explains its cluster, unchanged
            existing[track_id] = update
    for track_id, proposals in observations.items():
        if track_id not in skipped:
            existing[track_id] = object_sighting(
                tracks[track_id], track_id, proposals, parents[track_id], params
            )
    for track_id in visibility.visible - skipped - fixtures.keys() - observations.keys():
        existing[track_id] = miss(tracks[track_id], visibility.best[track_id], params)
    reidentified = tuple(
        reidentification(tracks[track_id], tracks[hypothesis], cosine, last_frame, params)
        for track_id, (hypothesis, cosine) in sorted(association.reidentified.items())
    )
    return BatchUpdates(tuple(new), existing, reidentified)


def capture_updates(
    state: SceneState,
    children: Sequence[tuple[Proposal, str]],
    fixture_id: str,
    held: Sequence[tuple[Track, Sighting]],
    params: Params,
) -> tuple[tuple[ObjectSighting, ...], tuple[Miss, ...]]:
    """Equation (3) for an inspection capture: each child (its proposal and track, new or not)
    seen on the fixture, and each fine node the ledger holds there that the capture showed and
    did not find, a visible miss."""
    found = {track_id for _, track_id in children}
    sightings = tuple(
        object_sighting(state.tracks.get(track_id), track_id, [proposal], [fixture_id], params)
        for proposal, track_id in children
    )
    misses = tuple(
        miss(track, sighting, params) for track, sighting in held if track.track_id not in found
    )
    return sightings, misses


# -- equation (3), term by term --------------------------------------------------------------


def first_sighting(params: Params) -> Existence:
    """A new hypothesis: the prior plus one positive observation."""
    logodds = update_existence(params.existence.prior_logodds, params.existence, observed=True)
    return Existence(logodds, logistic(logodds), 1, 0, False, "tentative")


def positive_batch(track: Track, params: Params) -> Existence:
    """One observation's worth of evidence (eta_o); a removed track restarts from the prior."""
    reacquired = track.lifecycle == "removed"
    prior = params.existence.prior_logodds if reacquired else track.existence_logodds
    logodds = update_existence(prior, params.existence, observed=True)
    batches = 1 if reacquired else track.batches_observed + 1
    lifecycle = "tentative" if reacquired else track.lifecycle
    return Existence(logodds, logistic(logodds), batches, 0, reacquired, lifecycle)


def unchanged(track: Track) -> Existence:
    """No existence evidence from this batch; the misses stand."""
    return Existence(
        track.existence_logodds,
        track.p_exist,
        track.batches_observed,
        track.visible_misses,
        False,
        track.lifecycle,
    )


def visible_miss(track: Track, params: Params, weight: float = 1.0) -> Existence:
    """An unmatched, observable track: U V = 1 (eta_m, times `weight`), one more visible miss."""
    logodds = update_existence(track.existence_logodds, params.existence, visible_miss=weight)
    return Existence(
        logodds,
        logistic(logodds),
        track.batches_observed,
        track.visible_misses + 1,
        False,
        track.lifecycle,
    )


def verdict_existence(track: Track, confirm: bool, params: Params) -> Existence:
    """A cached confirmation (eta_c) or rejection (eta_r)."""
    logodds = update_existence(
        track.existence_logodds, params.existence, confirmed=confirm, rejected=not confirm
    )
    return Existence(
        logodds,
        logistic(logodds),
        track.batches_observed,
        track.visible_misses,
        False,
        track.lifecycle,
    )


def reidentified_existence(track: Track, hypothesis: Track, params: Params) -> Existence:
    """One positive update per batch the hypothesis was seen in, as if the fallback had matched
    its sightings to the object; a removed object restarts from the prior."""
    reacquired = track.lifecycle == "removed"
    logodds = params.existence.prior_logodds if reacquired else track.existence_logodds
    seen = max(1, hypothesis.batches_observed)
    for _ in range(seen):
        logodds = update_existence(logodds, params.existence, observed=True)
    batches = seen + (0 if reacquired else track.batches_observed)
    lifecycle = "tentative" if reacquired else track.lifecycle
    return Existence(logodds, logistic(logodds), batches, 0, reacquired, lifecycle)


# -- updates ---------------------------------------------------------------------------------


def object_sighting(
    track: Track | None,
    track_id: str,
    proposals: Sequence[Proposal],
    parents: Sequence[str | None],
    params: Params,
) -> ObjectSighting:
    """An object's sighting (`track` None: a new hypothesis). An uncorroborated match (see
    `corroborates`) adds no existence evidence and keeps the miss count."""
    corroborated = track is None or corroborates(track, proposals, params)
    if track is None:
        existence = first_sighting(params)
    else:
        existence = positive_batch(track, params) if corroborated else unchanged(track)
    embedding_sum, embedding_count = _embedding_sum(track, proposals)
    return ObjectSighting(
        track_id,
        track is None,
        tuple(proposals),
        tuple(parents),
        embedding_sum,
        embedding_count,
        corroborated,
        existence,
    )


def corroborates(track: Track, proposals: Sequence[Proposal], params: Params) -> bool:
    """Does this batch's match support the track itself, not just something of its class nearby?

    Yes at its place (a center inside the stored box grown by the tolerance) or by appearance
    (both embeddings, cosine past the gate). A re-acquired track restarts as a hypothesis anyway.
    """
    if track.lifecycle == "removed" or not params.lifecycle.corroborate_at_place:
        return True
    embedding = track.embedding()
    grow = params.lifecycle.place_tolerance_m
    for proposal in proposals:
        offset = np.abs(np.asarray(proposal.center) - np.asarray(track.center))
        if (offset <= np.asarray(track.extent) / 2 + grow).all():
            return True
        if (
            embedding is not None
            and proposal.embedding is not None
            and embedding.shape == proposal.embedding.shape
            and float(embedding @ proposal.embedding) > params.association.min_appearance_cosine
        ):
            return True
    return False


def _embedding_sum(
    track: Track | None, proposals: Sequence[Proposal]
) -> tuple[tuple[float, ...] | None, int]:
    """The batch's appearance (summed) in the track's dimension, and how many vectors it sums."""
    dim = (
        len(track.embedding_sum) if track is not None and track.embedding_sum is not None else None
    )
    embeddings = [p.embedding for p in proposals if p.embedding is not None]
    if dim is None and embeddings:
        dim = embeddings[0].shape[0]
    embeddings = [e for e in embeddings if e.shape[0] == dim]
    if not embeddings:
        return None, 0
    return tuple(np.sum(embeddings, axis=0).tolist()), len(embeddings)


def new_fixture(
    track_id: str, proposal: FixtureProposal, batch_frame: str, timestamp: float, params: Params
) -> FixtureSighting:
    """A new coarse fixture hypothesis from a cluster no fixture track explains."""
    return FixtureSighting(
        track_id,
        True,
        proposal,
        batch_frame,
        timestamp,
        vec3(proposal.center),
        proposal.best_frame,
        proposal.contributed,
        first_sighting(params),
    )


def fixture_sighting(
    track: Track,
    proposal: FixtureProposal,
    batch_frame: str,
    timestamp: float,
    params: Params,
) -> FixtureSighting | None:
    """Support for a fixture from one more batch; None for a hypothesis a verifier rejected,
    which explains its cluster and stays retired. The center is the EMA of the cluster centers
    (alpha 0.35), restarted when the fixture is re-acquired."""
    if track.verification == "rejected":
        return None
    existence = positive_batch(track, params)
    center = (
        vec3(proposal.center)
        if existence.reacquired
        else ema_center(track.center, proposal.center, params.fusion.fixture_center_alpha)
    )
    best_frame, best_frame_support = proposal.best_frame, proposal.contributed
    if proposal.contributed <= track.best_frame_support:
        best_frame, best_frame_support = track.best_frame, track.best_frame_support
    return FixtureSighting(
        track.track_id,
        False,
        proposal,
        batch_frame,
        timestamp,
        center,
        best_frame,
        best_frame_support,
        existence,
    )


def miss(track: Track, sighting: Sighting, params: Params) -> Miss:
    """A visible miss, named by the frame that showed the track best; an object's weighted by
    how clearly that frame showed its place (a fixture's counts once: its views are large)."""
    weight = miss_weight(sighting, params) if track.kind == "object" else 1.0
    existence = visible_miss(track, params, weight)
    return Miss(track.track_id, sighting.frame_id, sighting.passed, existence)


def miss_weight(sighting: Sighting, params: Params) -> float:
    """How much a visible miss counts: 1 (the paper's U V), or with `clear_view_miss_weight`
    above 1, up to that much for a clear view. The weight grows linearly with the share of the
    image the observable part of the box covers, times the share of the box inside the image,
    from 1 at the missed-detection condition's floor to the full weight at
    `clear_view_image_fraction`: a glimpse of a place may miss a small object, a clear view of it
    rarely does (detectors find objects worst when small or cut by the border)."""
    top = params.existence.clear_view_miss_weight
    if top <= 1.0:
        return 1.0
    floor = params.visibility.min_expected_image_fraction
    clear = params.existence.clear_view_image_fraction
    shown = sighting.expected_fraction * sighting.in_image_share
    clarity = min(1.0, max(0.0, (shown - floor) / max(clear - floor, 1e-12)))
    return 1.0 + (top - 1.0) * clarity


def reidentification(
    track: Track, hypothesis: Track, cosine: float, frame_id: str, params: Params
) -> Reidentification:
    """The object takes the hypothesis's place, box and evidence."""
    box = hypothesis.box
    if box is None:
        low = np.asarray(hypothesis.center) - np.asarray(hypothesis.extent) / 2
        box = (*vec3(low), *vec3(low + np.asarray(hypothesis.extent)))
    existence = reidentified_existence(track, hypothesis, params)
    return Reidentification(track.track_id, hypothesis, cosine, frame_id, box, existence)


def verdict_update(
    track: Track,
    confirm: bool,
    label: str,
    source: str,
    frame_id: str | None,
    params: Params,
) -> Verdict:
    """A verdict's update: evidence weight 3 for `label` (in the fold), eta_c or eta_r."""
    return Verdict(
        track.track_id,
        "confirm" if confirm else "reject",
        label,
        source,
        frame_id,
        verdict_existence(track, confirm, params),
    )
