"""Lifecycle transitions (section 3.3, "Lifecycle transitions and audit events").

Every publication, demotion, removal and retirement is decided here, whatever its source: a
batch (`lifecycle_decisions`), a verdict (`verdict_decision`) or an inspection capture
(`sighting_decision` with `verified_capture`, `miss_decision`). The thresholds are the `should_*`
rules; each source calls the same ones.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import replace

import numpy as np

from core.belief import add_support_evidence, most_supported
from core.decisions import (
    Demotion,
    Existence,
    FixtureSighting,
    Miss,
    Move,
    ObjectSighting,
    Publication,
    Reidentification,
    Removal,
    Reparent,
    Retirement,
    TrackDecision,
    Verdict,
    VerificationRequest,
)
from core.existence import BatchUpdates
from core.frontend import BatchAssociation
from core.params import LifecycleParams, Params
from core.state import SceneState, Track
from core.values import LifecycleState, TrackKind, Vec3, vec3

# -- the rules -------------------------------------------------------------------------------


def should_confirm(
    kind: TrackKind,
    lifecycle: LifecycleState,
    p_exist: float,
    batches_observed: int,
    params: Params,
    *,
    verified_capture: bool = False,
) -> bool:
    """Publication needs cross-batch confirmation and p_exist >= 0.72.

    The one confirmation rule of objects, fixtures, verdicts and captures: fixtures need support
    from more distinct batches (section 3.2), objects from `confirm_min_batches` (section 3.3).
    A verified capture stands in for cross-batch confirmation (section 3.2: successful
    processing attaches verified child nodes), not for the existence belief: p_exist >= 0.72
    holds for every publication.
    """
    min_batches = (
        params.fixtures.confirm_min_batches
        if kind == "fixture"
        else params.lifecycle.confirm_min_batches
    )
    return (
        lifecycle in ("tentative", "demoted")
        and (verified_capture or batches_observed >= min_batches)
        and p_exist >= params.lifecycle.confirm_min_p_exist
    )


def should_demote(lifecycle: LifecycleState, p_exist: float, params: LifecycleParams) -> bool:
    """A published node is demoted when p_exist < 0.30."""
    return lifecycle == "confirmed" and p_exist < params.demote_below_p_exist


def should_remove(
    lifecycle: LifecycleState,
    p_exist: float,
    visible_misses: int,
    pinned: bool,
    params: LifecycleParams,
) -> bool:
    """Removal needs p_exist <= 0.12 after at least three visibility-admissible misses."""
    return (
        lifecycle != "removed"
        and not pinned
        and visible_misses >= params.remove_min_visible_misses
        and p_exist <= params.remove_at_most_p_exist
    )


def moved_distance(published: Vec3 | None, center: Vec3) -> float:
    """Distance from the last published position (0 when never published)."""
    return 0.0 if published is None else math.dist(published, center)


def should_move(published: Vec3 | None, center: Vec3, params: LifecycleParams) -> bool:
    """Motion of at least 0.35 m from the last published position emits `move`."""
    return published is not None and moved_distance(published, center) >= params.move_min_distance_m


def stale_hypotheses(
    state: SceneState, sighted: Collection[str], timestamp: float, params: Params
) -> frozenset[str]:
    """Hypotheses never published that retire: removed ones, and those unseen for
    `retire_unseen_hypothesis_s` (section 3.3: raw hypotheses are unpublished tracks; these no
    longer count as any). One waiting for a verdict, or sighted in this batch, stays."""
    arrays = state.arrays
    horizon = timestamp - params.lifecycle.retire_unseen_hypothesis_s
    with np.errstate(invalid="ignore"):
        unseen = arrays.unpublished_tentative & ~(arrays.last_observed >= horizon)
    removed_unpublished = arrays.gone & ~arrays.published
    ids = (arrays.track_ids[row] for row in np.flatnonzero(unseen | removed_unpublished))
    return frozenset(
        track_id
        for track_id in ids
        if track_id not in sighted and state.tracks[track_id].verification != "pending"
    )


# -- a batch ---------------------------------------------------------------------------------


def lifecycle_decisions(
    state: SceneState,
    association: BatchAssociation,
    updates: BatchUpdates,
    last_frame: str,
    timestamp: float,
    params: Params,
    removal: bool = True,
) -> tuple[TrackDecision, ...]:
    """The batch's decisions in the order the log keeps: new hypotheses, then existing tracks
    by id (a hypothesis removed before it was ever published, or left unseen too long, retires),
    then re-identifications (the hypothesis retires into the object), then merges."""
    tracks = state.tracks
    decisions = [_unless_held(update_decision(None, u, params), association) for u in updates.new]
    sighted = {*association.observations, *association.fixtures}
    stale = stale_hypotheses(state, sighted, timestamp, params)
    skipped = association.settled
    for track_id in sorted((updates.existing.keys() | stale) - skipped):
        track = tracks[track_id]
        update = updates.existing.get(track_id)
        decision = (
            TrackDecision(track_id, None, track.lifecycle)
            if update is None
            else _unless_held(update_decision(track, update, params, removal=removal), association)
        )
        if decision.remove is not None and track.published_center is None:
            retire = Retirement("removed", last_frame, track.last_observed)
        elif track_id in stale:
            retire = Retirement(
                "removed" if track.lifecycle == "removed" else "unseen",
                last_frame,
                track.last_observed,
            )
        else:
            decisions.append(decision)
            continue
        decisions.append(replace(decision, retire=retire))
    for reidentified in updates.reidentified:
        hypothesis = reidentified.hypothesis
        decisions.append(update_decision(tracks[reidentified.track_id], reidentified, params))
        decisions.append(_merged(hypothesis, reidentified.track_id, last_frame))
    return (*decisions, *_merges(state, association, decisions, last_frame))


def _unless_held(decision: TrackDecision, association: BatchAssociation) -> TrackDecision:
    """A held hypothesis (`BatchAssociation.held`) is not published in this batch."""
    if decision.publish is None or decision.track_id not in association.held:
        return decision
    return replace(decision, publish=None)


def _merges(
    state: SceneState,
    association: BatchAssociation,
    decided: Sequence[TrackDecision],
    last_frame: str,
) -> list[TrackDecision]:
    """Second tracks retire into their keepers; a fixture's objects follow, unless this batch
    already gave them a parent. Tracks that retire or are re-identified in this batch are left
    alone."""
    gone = {d.track_id for d in decided if d.retire is not None} | set(association.reidentified)
    decisions = [
        _merged(state.tracks[track_id], keeper, last_frame)
        for track_id, keeper in sorted(association.duplicates.items())
        if track_id not in gone and keeper not in gone
    ]
    reparented = {d.track_id for d in decided if d.reparent is not None}
    for track_id, keeper in sorted(association.merged_fixtures.items()):
        decisions.append(_merged(state.tracks[track_id], keeper, last_frame))
        children = (
            t
            for t in state.tracks.values()
            if t.parent == track_id
            and t.kind == "object"
            and t.lifecycle != "retired"
            and t.track_id not in reparented
        )
        decisions += [
            TrackDecision(
                child.track_id, last_frame, child.lifecycle, reparent=Reparent(track_id, keeper)
            )
            for child in sorted(children, key=lambda t: t.track_id)
        ]
    return decisions


def _merged(track: Track, keeper: str, frame_id: str) -> TrackDecision:
    retire = Retirement("merged", frame_id, track.last_observed, keeper)
    return TrackDecision(track.track_id, frame_id, track.lifecycle, retire=retire)


def capture_decisions(
    state: SceneState,
    sightings: Sequence[ObjectSighting],
    misses: Sequence[Miss],
    params: Params,
) -> tuple[TrackDecision, ...]:
    """An inspection capture's decisions: its children in the order of its proposals, then its
    visible misses. The verified capture stands in for cross-batch confirmation."""
    seen = tuple(
        sighting_decision(state.tracks.get(s.track_id), s, params, verified_capture=True)
        for s in sightings
    )
    return (*seen, *(miss_decision(state.tracks[m.track_id], m, params) for m in misses))


# -- one update ------------------------------------------------------------------------------


def update_decision(
    track: Track | None,
    update: ObjectSighting | FixtureSighting | Reidentification | Miss,
    params: Params,
    *,
    removal: bool = True,
) -> TrackDecision:
    """The transitions one update triggers (`track` None: a new hypothesis)."""
    if isinstance(update, ObjectSighting):
        return sighting_decision(track, update, params)
    if isinstance(update, FixtureSighting):
        return _fixture_decision(track, update, params)
    assert track is not None
    if isinstance(update, Miss):
        return miss_decision(track, update, params, removal)
    return _reidentified_decision(track, update, params)


def sighting_decision(
    track: Track | None,
    sighting: ObjectSighting,
    params: Params,
    *,
    verified_capture: bool = False,
) -> TrackDecision:
    """A sighted object: `confirm`, `move` and `reparent` as they apply. An uncorroborated match
    publishes nothing yet. Support evidence about the old place is stale once the object was
    relocated (re-acquired, or moved from its published position)."""
    existence, frame_id = sighting.existence, sighting.frame_id
    center = vec3(sighting.proposals[-1].center)
    old_parent = None if track is None else track.parent
    relocated = (
        track is None
        or existence.reacquired
        or should_move(track.published_center, center, params.lifecycle)
    )
    evidence = add_support_evidence(
        {} if track is None or relocated else track.parent_evidence,
        sighting.parents,
        params.fusion.observation_evidence_weight,
    )
    decision = TrackDecision(
        sighting.track_id, frame_id, existence.lifecycle, sighting, parent_evidence=evidence
    )
    if not sighting.corroborated:
        return decision
    publish = _publication("object", existence, center, params, verified_capture)
    lifecycle = "confirmed" if publish is not None else existence.lifecycle
    return replace(
        decision,
        publish=publish,
        move=None if track is None else _move(track, lifecycle, center, params),
        reparent=_reparent(old_parent, evidence),
    )


def _fixture_decision(
    track: Track | None, sighting: FixtureSighting, params: Params
) -> TrackDecision:
    """Promotion of a fixture: several distinct batches, then the consensus gate or one
    verification (section 3.2); a confirmed verdict stands in for the consensus."""
    existence, proposal = sighting.existence, sighting.proposal
    decision = TrackDecision(sighting.track_id, sighting.frame_id, existence.lifecycle, sighting)
    if track is None:
        return decision
    class_evidence = dict(track.class_evidence)
    class_evidence[proposal.label] = (
        class_evidence.get(proposal.label, 0.0) + params.fusion.observation_evidence_weight
    )
    label = most_supported(class_evidence) or proposal.label
    total = sum(class_evidence.values())
    agreement = class_evidence[label] / total
    batches = existence.batches_observed
    mean_margin = (track.margin_sum + proposal.margin) / max(batches, 1)
    ready = should_confirm("fixture", existence.lifecycle, existence.p_exist, batches, params)
    consensus = (
        agreement >= params.fixtures.consensus_min_agreement
        and mean_margin >= params.fixtures.consensus_min_margin
    )
    publish, request = None, None
    if ready and (consensus or track.verification == "confirmed"):
        publish = Publication(existence.p_exist, sighting.center, batches, consensus=consensus)
    elif ready and track.verification is None:
        # What a verifier needs: each class's mean similarity over the cluster, and how the
        # supporting batches voted.
        request = VerificationRequest(
            candidates=dict(sorted(proposal.class_means.items(), key=lambda item: -item[1])),
            batch_votes={name: weight / total for name, weight in sorted(class_evidence.items())},
            agreement=agreement,
            mean_margin=mean_margin,
            batches_observed=batches,
            best_frame=sighting.best_frame,
        )
    lifecycle = "confirmed" if publish is not None else existence.lifecycle
    move = _move(track, lifecycle, sighting.center, params)
    return replace(decision, publish=publish, request=request, move=move)


def miss_decision(track: Track, miss: Miss, params: Params, removal: bool = True) -> TrackDecision:
    """A visible miss: `demote` below p_exist 0.30 (pinned fixtures stay published), `remove`
    at p_exist <= 0.12 after three misses. Without `removal` (an append-only memory) neither."""
    existence = miss.existence
    if not removal:
        return TrackDecision(track.track_id, miss.frame_id, track.lifecycle, miss)
    lifecycle, demote, remove = track.lifecycle, None, None
    p_exist, misses = existence.p_exist, existence.visible_misses
    if not track.pinned and should_demote(lifecycle, p_exist, params.lifecycle):
        lifecycle, demote = "demoted", Demotion(p_exist)
    if should_remove(lifecycle, p_exist, misses, track.pinned, params.lifecycle):
        remove = Removal(p_exist, visible_misses=misses)
    return TrackDecision(
        track.track_id, miss.frame_id, track.lifecycle, miss, demote=demote, remove=remove
    )


def _reidentified_decision(
    track: Track, reidentified: Reidentification, params: Params
) -> TrackDecision:
    """A re-identified object: `confirm`, `move` and `reparent` as they apply, on the
    hypothesis's place and support evidence."""
    existence, hypothesis = reidentified.existence, reidentified.hypothesis
    evidence = dict(hypothesis.parent_evidence)
    publish = _publication("object", existence, hypothesis.center, params, False)
    lifecycle = "confirmed" if publish is not None else existence.lifecycle
    return TrackDecision(
        track.track_id,
        reidentified.frame_id,
        existence.lifecycle,
        reidentified,
        parent_evidence=evidence,
        publish=publish,
        move=_move(track, lifecycle, hypothesis.center, params),
        reparent=_reparent(track.parent, evidence),
    )


def verdict_decision(track: Track, verdict: Verdict, params: Params) -> TrackDecision:
    """A rejected hypothesis is retired: removed, and never re-acquired. A confirmed one is
    published when the confirmation rule holds (the verdict adds eta_c, not batches)."""
    existence = verdict.existence
    decision = TrackDecision(track.track_id, verdict.frame_id, track.lifecycle, verdict)
    if verdict.verdict == "reject":
        return replace(decision, remove=Removal(existence.p_exist, reason="verification_rejected"))
    if not should_confirm(
        track.kind, track.lifecycle, existence.p_exist, track.batches_observed, params
    ):
        return decision
    publish = Publication(
        existence.p_exist, track.center, track.batches_observed, reason="verification"
    )
    return replace(decision, publish=publish)


# -- transitions -----------------------------------------------------------------------------


def _publication(
    kind: TrackKind, existence: Existence, center: Vec3, params: Params, verified_capture: bool
) -> Publication | None:
    """`confirm` when the rule holds; a capture's publication names the capture as its reason
    when batches alone would not have published the track."""
    lifecycle, p_exist, batches = existence.lifecycle, existence.p_exist, existence.batches_observed
    if should_confirm(kind, lifecycle, p_exist, batches, params):
        return Publication(p_exist, center, batches)
    if verified_capture and should_confirm(
        kind, lifecycle, p_exist, batches, params, verified_capture=True
    ):
        return Publication(p_exist, center, batches, reason="inspection")
    return None


def _move(track: Track, lifecycle: LifecycleState, center: Vec3, params: Params) -> Move | None:
    published = track.published_center
    if lifecycle != "confirmed" or not should_move(published, center, params.lifecycle):
        return None
    assert published is not None
    return Move(published, center, moved_distance(published, center))


def _reparent(old_parent: str | None, evidence: Mapping[str, float]) -> Reparent | None:
    """A valid support change: the most supported parent differs from the current one."""
    new_parent = most_supported(evidence, old_parent)
    if new_parent is None or new_parent == old_parent:
        return None
    return Reparent(old_parent, new_parent)
