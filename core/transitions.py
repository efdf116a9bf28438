"""From one batch's evidence about one track to its events (section 3.3, lifecycle and audit)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from core.belief import update_existence
from core.events import (
    Event,
    FixtureAdded,
    FixtureObserved,
    ObjectAdded,
    ObjectObserved,
    ObjectReidentified,
    TrackConfirmed,
    TrackDemoted,
    TrackMoved,
    TrackRemoved,
    TrackReparented,
    TrackRetired,
    VerificationRequested,
    VisibleMiss,
)
from core.fixtures import FixtureProposal, ema_center
from core.geometry import Proposal
from core.lifecycle import moved_distance, should_confirm, should_demote, should_move, should_remove
from core.params import Params
from core.state import Track, logistic
from core.values import LifecycleState, Observation, Vec3, vec3


def _top(evidence: Mapping[str, float], current: str | None = None) -> str | None:
    """Most supported key; the current one keeps ties, then names decide."""
    if not evidence:
        return None
    best = max(evidence.values())
    if current is not None and evidence.get(current) == best:
        return current
    return min(key for key, weight in evidence.items() if weight == best)


# -- objects ---------------------------------------------------------------------------------


def _observations(
    proposals: Sequence[Proposal], parents: Sequence[str | None]
) -> tuple[Observation, ...]:
    return tuple(
        Observation(
            frame_id=p.frame_id,
            label=p.label,
            score=float(p.score),
            center=vec3(p.center),
            extent=vec3(p.extent),
            valid_pixels=p.valid_pixels,
            parent=parent,
            class_scores=None if not p.class_scores else dict(sorted(p.class_scores.items())),
        )
        for p, parent in zip(proposals, parents, strict=True)
    )


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
    return tuple(float(v) for v in np.sum(embeddings, axis=0)), len(embeddings)


def _support_events(
    track_id: str,
    lifecycle: LifecycleState,
    frame_id: str,
    old_parent: str | None,
    evidence: Mapping[str, float],
) -> list[Event]:
    """A valid support change emits `reparent` naming the old and the new parent."""
    new_parent = _top(evidence, old_parent)
    if new_parent is None or new_parent == old_parent:
        return []
    return [
        TrackReparented(
            track_id=track_id,
            state=lifecycle,
            frame_id=frame_id,
            old_parent=old_parent,
            new_parent=new_parent,
        )
    ]


def first_sighting(params: Params) -> float:
    """Existence log-odds of a new hypothesis: the prior plus one positive observation (eq. (3))."""
    return update_existence(params.existence.prior_logodds, params.existence, observed=True)


def confirmed(
    track_id: str,
    frame_id: str | None,
    p_exist: float,
    center: Vec3,
    batches: int,
    *,
    consensus: bool | None = None,
    reason: Literal["verification", "inspection"] | None = None,
) -> TrackConfirmed:
    """Graph publication of a track."""
    return TrackConfirmed(
        track_id=track_id,
        state="confirmed",
        frame_id=frame_id,
        p_exist=p_exist,
        center=center,
        batches_observed=batches,
        consensus=consensus,
        reason=reason,
    )


def added_object(
    track_id: str, proposals: Sequence[Proposal], parents: Sequence[str | None], params: Params
) -> list[Event]:
    """A new hypothesis (`add`), and its first support."""
    evidence = _parent_evidence({}, parents, params)
    embedding_sum, embedding_count = _embedding_sum(None, proposals)
    logodds = first_sighting(params)
    p_exist = logistic(logodds)
    frame_id = proposals[0].frame_id
    emitted: list[Event] = [
        ObjectAdded(
            track_id=track_id,
            state="tentative",
            frame_id=frame_id,
            observations=_observations(proposals, parents),
            embedding_sum=embedding_sum,
            embedding_count=embedding_count,
            timestamp=float(proposals[-1].timestamp),
            existence_logodds=logodds,
            p_exist=p_exist,
            batches_observed=1,
            parent_evidence=evidence,
        )
    ]
    lifecycle: LifecycleState = "tentative"
    if should_confirm("object", lifecycle, p_exist, 1, params):  # only when one batch may publish
        lifecycle = "confirmed"
        emitted.append(confirmed(track_id, frame_id, p_exist, vec3(proposals[-1].center), 1))
    return [*emitted, *_support_events(track_id, lifecycle, frame_id, None, evidence)]


def _parent_evidence(
    previous: Mapping[str, float], parents: Sequence[str | None], params: Params
) -> dict[str, float]:
    evidence = dict(previous)
    for parent in parents:
        if parent is not None:
            evidence[parent] = evidence.get(parent, 0.0) + params.fusion.observation_evidence_weight
    return evidence


def corroborates(track: Track, proposals: Sequence[Proposal], params: Params) -> bool:
    """Does this batch's match support the track itself, not just something of its class nearby?

    Yes at its place (a center inside the stored box grown by the tolerance) or by appearance
    (both embeddings, cosine past the gate). A re-acquired track restarts as a hypothesis anyway.
    """
    if track.lifecycle == "removed":
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


def observed_object(
    track: Track, proposals: Sequence[Proposal], parents: Sequence[str | None], params: Params
) -> list[Event]:
    """A positive batch: `update`, then `confirm`, `move` and `reparent` as they apply.

    An uncorroborated match (see `corroborates`) moves the track's center to the proposal but
    adds no existence evidence, keeps the miss count and publishes nothing yet.
    """
    frame_id = proposals[-1].frame_id
    corroborated = corroborates(track, proposals, params)
    positive = positive_batch(track, params) if corroborated else unchanged(track)
    lifecycle = positive.lifecycle
    center = vec3(proposals[-1].center)
    # Evidence about the old support is stale once the object was relocated.
    relocated = positive.reacquired or should_move(track.published_center, center, params.lifecycle)
    evidence = _parent_evidence({} if relocated else track.parent_evidence, parents, params)
    embedding_sum, embedding_count = _embedding_sum(track, proposals)
    emitted: list[Event] = [
        ObjectObserved(
            track_id=track.track_id,
            state=lifecycle,
            frame_id=frame_id,
            observations=_observations(proposals, parents),
            embedding_sum=embedding_sum,
            embedding_count=embedding_count,
            timestamp=float(proposals[-1].timestamp),
            existence_logodds=positive.logodds,
            p_exist=positive.p_exist,
            batches_observed=positive.batches,
            reacquired=positive.reacquired,
            parent_evidence=evidence,
            corroborated=None if corroborated else False,
        )
    ]
    if not corroborated:
        return emitted
    if should_confirm("object", lifecycle, positive.p_exist, positive.batches, params):
        lifecycle = "confirmed"
        emitted.append(
            confirmed(track.track_id, frame_id, positive.p_exist, center, positive.batches)
        )
    emitted.extend(_move_events(track, lifecycle, frame_id, center, params))
    emitted.extend(_support_events(track.track_id, lifecycle, frame_id, track.parent, evidence))
    return emitted


def reidentified_object(
    track: Track, hypothesis: Track, cosine: float, frame_id: str, params: Params
) -> list[Event]:
    """A missing object is the hypothesis seen since elsewhere: `update` (reidentified), then
    `confirm`, `move` and `reparent` as they apply, as if the fallback had matched the
    hypothesis's sightings to the object (one positive update per batch it was seen in)."""
    reacquired = track.lifecycle == "removed"
    logodds = params.existence.prior_logodds if reacquired else track.existence_logodds
    seen = max(1, hypothesis.batches_observed)
    for _ in range(seen):
        logodds = update_existence(logodds, params.existence, observed=True)
    batches = seen + (0 if reacquired else track.batches_observed)
    lifecycle: LifecycleState = "tentative" if reacquired else track.lifecycle
    p_exist = logistic(logodds)
    center = hypothesis.center
    box = hypothesis.box
    if box is None:
        low = np.asarray(center) - np.asarray(hypothesis.extent) / 2
        box = (*vec3(low), *vec3(low + np.asarray(hypothesis.extent)))
    emitted: list[Event] = [
        ObjectReidentified(
            track_id=track.track_id,
            state=lifecycle,
            frame_id=frame_id,
            hypothesis=hypothesis.track_id,
            appearance_cosine=cosine,
            seen_in=hypothesis.last_observed_frame,
            timestamp=float(hypothesis.last_observed or 0.0),
            center=center,
            extent=hypothesis.extent,
            box=box,
            recent_centers=hypothesis.recent_centers,
            class_evidence=dict(sorted(hypothesis.class_evidence.items())),
            embedding_sum=hypothesis.embedding_sum,
            embedding_count=hypothesis.embedding_count,
            existence_logodds=logodds,
            p_exist=p_exist,
            batches_observed=batches,
            reacquired=reacquired,
            parent_evidence=dict(hypothesis.parent_evidence),
        )
    ]
    if should_confirm("object", lifecycle, p_exist, batches, params):
        lifecycle = "confirmed"
        emitted.append(confirmed(track.track_id, frame_id, p_exist, center, batches))
    emitted.extend(_move_events(track, lifecycle, frame_id, center, params))
    evidence = hypothesis.parent_evidence
    emitted.extend(_support_events(track.track_id, lifecycle, frame_id, track.parent, evidence))
    return emitted


@dataclass(frozen=True)
class PositiveBatch:
    """Equation (3) for a matched track."""

    reacquired: bool  # a removed track keeps its identity and restarts as a hypothesis
    logodds: float
    p_exist: float
    batches: int  # distinct positive batches since (re)acquisition
    lifecycle: LifecycleState


def positive_batch(track: Track, params: Params) -> PositiveBatch:
    """A positive batch for `track`: one observation's worth of existence evidence."""
    existence = params.existence
    reacquired = track.lifecycle == "removed"
    prior = existence.prior_logodds if reacquired else track.existence_logodds
    logodds = update_existence(prior, existence, observed=True)
    return PositiveBatch(
        reacquired=reacquired,
        logodds=logodds,
        p_exist=logistic(logodds),
        batches=1 if reacquired else track.batches_observed + 1,
        lifecycle="tentative" if reacquired else track.lifecycle,
    )


def unchanged(track: Track) -> PositiveBatch:
    """No existence evidence from this batch."""
    return PositiveBatch(
        reacquired=False,
        logodds=track.existence_logodds,
        p_exist=track.p_exist,
        batches=track.batches_observed,
        lifecycle=track.lifecycle,
    )


def retired(
    track: Track,
    frame_id: str,
    reason: Literal["removed", "unseen", "merged"],
    merged_into: str | None = None,
) -> list[Event]:
    """A track leaves the memory in play: a hypothesis never published, removed or unseen too
    long, or a second track of a fixture merged into the one that stands for it."""
    return [
        TrackRetired(
            track_id=track.track_id,
            state="retired",
            frame_id=frame_id,
            reason=reason,
            last_observed=track.last_observed,
            merged_into=merged_into,
        )
    ]


def _move_events(
    track: Track, lifecycle: LifecycleState, frame_id: str, center: Vec3, params: Params
) -> list[Event]:
    published = track.published_center
    if (
        lifecycle != "confirmed"
        or published is None
        or not should_move(published, center, params.lifecycle)
    ):
        return []
    return [
        TrackMoved(
            track_id=track.track_id,
            state=lifecycle,
            frame_id=frame_id,
            moved_from=published,
            to=center,
            distance=moved_distance(published, center),
        )
    ]


def visible_miss(
    track: Track, samples: int, frame_id: str, params: Params, removal: bool = True
) -> list[Event]:
    """An unmatched, visible track: one miss (equation (3)), then `demote` / `remove` as they apply."""
    existence, lifecycle_params = params.existence, params.lifecycle
    logodds = update_existence(track.existence_logodds, existence, visible_miss=True)
    p_exist = logistic(logodds)
    misses = track.visible_misses + 1
    lifecycle = track.lifecycle
    emitted: list[Event] = [
        VisibleMiss(
            track_id=track.track_id,
            state=lifecycle,
            frame_id=frame_id,
            samples_passed=samples,
            samples_total=params.visibility.box_samples_per_axis**3,
            existence_logodds=logodds,
            p_exist=p_exist,
            visible_misses=misses,
        )
    ]
    if not removal:  # an append-only memory never resolves a disappearance
        return emitted
    if not track.pinned and should_demote(lifecycle, p_exist, lifecycle_params):
        lifecycle = "demoted"  # pinned fixtures are never unpublished
        emitted.append(
            TrackDemoted(
                track_id=track.track_id, state=lifecycle, frame_id=frame_id, p_exist=p_exist
            )
        )
    if should_remove(lifecycle, p_exist, misses, track.pinned, lifecycle_params):
        lifecycle = "removed"
        emitted.append(
            TrackRemoved(
                track_id=track.track_id,
                state=lifecycle,
                frame_id=frame_id,
                p_exist=p_exist,
                visible_misses=misses,
            )
        )
    return emitted


# -- fixtures --------------------------------------------------------------------------------


def _fixture_observation(proposal: FixtureProposal, batch_frame: str) -> tuple[Observation, ...]:
    """One cluster's evidence for a fixture track."""
    return (
        Observation(
            frame_id=proposal.best_frame or batch_frame,
            label=proposal.label,
            score=proposal.mean_score,
            center=vec3(proposal.center),
            extent=vec3(proposal.extent),
            valid_pixels=proposal.voxel_count,
            parent=None,
        ),
    )


def added_fixture(
    track_id: str, proposal: FixtureProposal, batch_frame: str, timestamp: float, params: Params
) -> list[Event]:
    """A new coarse fixture hypothesis."""
    logodds = first_sighting(params)
    return [
        FixtureAdded(
            track_id=track_id,
            state="tentative",
            frame_id=proposal.best_frame or batch_frame,
            observations=_fixture_observation(proposal, batch_frame),
            center=vec3(proposal.center),
            margin=proposal.margin,
            best_frame=proposal.best_frame,
            best_frame_support=proposal.contributed,
            existence_logodds=logodds,
            p_exist=logistic(logodds),
            batches_observed=1,
            timestamp=timestamp,
        )
    ]


def observed_fixture(
    track: Track, proposal: FixtureProposal, batch_frame: str, timestamp: float, params: Params
) -> list[Event]:
    """Support from one more batch: `update`, then promotion or a verification request."""
    if track.verification == "rejected":
        return []  # a retired hypothesis explains its cluster and stays retired
    positive = positive_batch(track, params)
    lifecycle, batches, p_exist = positive.lifecycle, positive.batches, positive.p_exist
    center = (
        vec3(proposal.center)
        if positive.reacquired
        else ema_center(track.center, proposal.center, params.fusion.fixture_center_alpha)
    )
    frame_id = proposal.best_frame or batch_frame
    best_frame, best_frame_support = proposal.best_frame, proposal.contributed
    if proposal.contributed <= track.best_frame_support:
        best_frame, best_frame_support = track.best_frame, track.best_frame_support
    emitted: list[Event] = [
        FixtureObserved(
            track_id=track.track_id,
            state=lifecycle,
            frame_id=frame_id,
            observations=_fixture_observation(proposal, batch_frame),
            center=center,
            margin=proposal.margin,
            best_frame=best_frame,
            best_frame_support=best_frame_support,
            existence_logodds=positive.logodds,
            p_exist=p_exist,
            batches_observed=batches,
            reacquired=positive.reacquired,
            timestamp=timestamp,
        )
    ]
    # Promotion: several distinct batches, then the consensus gate or one verification.
    class_evidence = dict(track.class_evidence)
    class_evidence[proposal.label] = (
        class_evidence.get(proposal.label, 0.0) + params.fusion.observation_evidence_weight
    )
    label = _top(class_evidence) or proposal.label
    agreement = class_evidence[label] / sum(class_evidence.values())
    mean_margin = (track.margin_sum + proposal.margin) / max(batches, 1)
    fixture_params = params.fixtures
    ready = should_confirm("fixture", lifecycle, p_exist, batches, params)
    consensus = (
        agreement >= fixture_params.consensus_min_agreement
        and mean_margin >= fixture_params.consensus_min_margin
    )
    if ready and (consensus or track.verification == "confirmed"):
        lifecycle = "confirmed"
        emitted.append(
            confirmed(track.track_id, frame_id, p_exist, center, batches, consensus=consensus)
        )
    elif ready and track.verification is None:
        total = sum(class_evidence.values())
        emitted.append(
            VerificationRequested(
                track_id=track.track_id,
                state=lifecycle,
                frame_id=frame_id,
                # What a verifier needs: each class's mean similarity over the cluster,
                # and how the supporting batches voted.
                candidates=dict(sorted(proposal.class_means.items(), key=lambda item: -item[1])),
                batch_votes={
                    name: weight / total for name, weight in sorted(class_evidence.items())
                },
                agreement=agreement,
                mean_margin=mean_margin,
                batches_observed=batches,
                best_frame=best_frame,
            )
        )
    emitted.extend(_move_events(track, lifecycle, frame_id, center, params))
    return emitted


def fixture_verdict_logodds(track: Track, confirm: bool, params: Params) -> float:
    """Equation (3) with a cached confirmation (eta_c) or rejection (eta_r)."""
    return update_existence(
        track.existence_logodds, params.existence, confirmed=confirm, rejected=not confirm
    )
