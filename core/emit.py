"""The one emitter: decisions become audit events (section 3.3, "Lifecycle transitions and
audit events"). Each event states the track's lifecycle after it."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TypedDict

from core.decisions import (
    FixtureSighting,
    Miss,
    ObjectSighting,
    Reidentification,
    TrackDecision,
    Verdict,
)
from core.events import (
    Event,
    FixtureAdded,
    FixtureEvidence,
    FixtureObserved,
    ObjectAdded,
    ObjectObserved,
    ObjectReidentified,
    OccupancyEvidence,
    TrackConfirmed,
    TrackDemoted,
    TrackMoved,
    TrackRemoved,
    TrackReparented,
    TrackRetired,
    TrackVerified,
    VerificationRequested,
    VisibleMiss,
)
from core.fixtures import FixtureProposal
from core.geometry import Proposal
from core.params import Params
from core.values import LifecycleState, Observation, Vec3, vec3


def batch_events(
    fixture_evidence: FixtureEvidence | None,
    occupancy: OccupancyEvidence | None,
    decisions: Iterable[TrackDecision],
    params: Params,
) -> list[Event]:
    """A batch's events: its fixture and occupancy evidence, then each track's decision."""
    evidence = [e for e in (fixture_evidence, occupancy) if e is not None]
    return [*evidence, *decision_events(decisions, params)]


def decision_events(decisions: Iterable[TrackDecision], params: Params) -> list[Event]:
    """Each decision's update, then its transitions, in the order the decisions come."""
    events: list[Event] = []
    for decision in decisions:
        events += _events_of(decision, params)
    return events


def _events_of(decision: TrackDecision, params: Params) -> list[Event]:
    """Update, publication or verification request, move, reparent, demotion, removal,
    retirement."""
    update = [] if decision.update is None else [_update_event(decision, params)]
    return [*update, *_publication_events(decision), *_removal_events(decision)]


def _publication_events(decision: TrackDecision) -> list[Event]:
    """`confirm` or `verification_requested`, then `move` and `reparent`."""
    track_id, frame_id = decision.track_id, decision.frame_id
    state: LifecycleState = "confirmed" if decision.publish is not None else decision.lifecycle
    events: list[Event] = []
    if (publish := decision.publish) is not None:
        events.append(
            TrackConfirmed(
                track_id=track_id,
                state=state,
                frame_id=frame_id,
                p_exist=publish.p_exist,
                center=publish.center,
                batches_observed=publish.batches_observed,
                consensus=publish.consensus,
                reason=publish.reason,
            )
        )
    if (request := decision.request) is not None:
        events.append(
            VerificationRequested(
                track_id=track_id,
                state=state,
                frame_id=frame_id,
                candidates=request.candidates,
                batch_votes=request.batch_votes,
                agreement=request.agreement,
                mean_margin=request.mean_margin,
                batches_observed=request.batches_observed,
                best_frame=request.best_frame,
            )
        )
    if (move := decision.move) is not None:
        events.append(
            TrackMoved(
                track_id=track_id,
                state=state,
                frame_id=frame_id,
                moved_from=move.moved_from,
                to=move.to,
                distance=move.distance,
            )
        )
    if (reparent := decision.reparent) is not None:
        events.append(
            TrackReparented(
                track_id=track_id,
                state=state,
                frame_id=frame_id,
                old_parent=reparent.old_parent,
                new_parent=reparent.new_parent,
            )
        )
    return events


def _removal_events(decision: TrackDecision) -> list[Event]:
    """`demote`, `remove`, then `retire`."""
    track_id, frame_id = decision.track_id, decision.frame_id
    events: list[Event] = []
    if (demote := decision.demote) is not None:
        events.append(
            TrackDemoted(
                track_id=track_id, state="demoted", frame_id=frame_id, p_exist=demote.p_exist
            )
        )
    if (remove := decision.remove) is not None:
        events.append(
            TrackRemoved(
                track_id=track_id,
                state="removed",
                frame_id=frame_id,
                p_exist=remove.p_exist,
                visible_misses=remove.visible_misses,
                reason=remove.reason,
            )
        )
    if (retire := decision.retire) is not None:
        events.append(
            TrackRetired(
                track_id=track_id,
                state="retired",
                frame_id=retire.frame_id,
                reason=retire.reason,
                last_observed=retire.last_observed,
                merged_into=retire.merged_into,
            )
        )
    return events


def _update_event(decision: TrackDecision, params: Params) -> Event:
    """The existence update of one batch (`add` or `update`) or a verdict (`verify`)."""
    update = decision.update
    track_id, state = decision.track_id, decision.lifecycle
    if isinstance(update, ObjectSighting):
        return _object_event(decision, update)
    if isinstance(update, FixtureSighting):
        return _fixture_event(decision, update)
    if isinstance(update, Reidentification):
        hypothesis, existence = update.hypothesis, update.existence
        return ObjectReidentified(
            track_id=track_id,
            state=state,
            frame_id=update.frame_id,
            hypothesis=hypothesis.track_id,
            appearance_cosine=update.cosine,
            seen_in=hypothesis.last_observed_frame,
            timestamp=float(hypothesis.last_observed or 0.0),
            center=hypothesis.center,
            extent=hypothesis.extent,
            box=update.box,
            recent_centers=hypothesis.recent_centers,
            class_evidence=dict(sorted(hypothesis.class_evidence.items())),
            embedding_sum=hypothesis.embedding_sum,
            embedding_count=hypothesis.embedding_count,
            existence_logodds=existence.logodds,
            p_exist=existence.p_exist,
            batches_observed=existence.batches_observed,
            reacquired=existence.reacquired,
            parent_evidence=decision.parent_evidence or {},
        )
    if isinstance(update, Miss):
        return VisibleMiss(
            track_id=track_id,
            state=state,
            frame_id=update.frame_id,
            samples_passed=update.samples_passed,
            samples_total=params.visibility.box_samples_per_axis**3,
            existence_logodds=update.existence.logodds,
            p_exist=update.existence.p_exist,
            visible_misses=update.existence.visible_misses,
        )
    assert isinstance(update, Verdict)
    return TrackVerified(
        track_id=track_id,
        state=state,
        frame_id=update.frame_id,
        verdict=update.verdict,
        label=update.label,
        source=update.source,
        verdict_frame=update.frame_id,
        existence_logodds=update.existence.logodds,
        p_exist=update.existence.p_exist,
    )


def _object_event(decision: TrackDecision, sighting: ObjectSighting) -> Event:
    existence, proposals = sighting.existence, sighting.proposals
    if sighting.new:
        return ObjectAdded(
            track_id=sighting.track_id,
            state=decision.lifecycle,
            frame_id=sighting.frame_id,
            observations=_observations(proposals, sighting.parents),
            embedding_sum=sighting.embedding_sum,
            embedding_count=sighting.embedding_count,
            timestamp=float(proposals[-1].timestamp),
            existence_logodds=existence.logodds,
            p_exist=existence.p_exist,
            batches_observed=existence.batches_observed,
            parent_evidence=decision.parent_evidence or {},
        )
    return ObjectObserved(
        track_id=sighting.track_id,
        state=decision.lifecycle,
        frame_id=sighting.frame_id,
        observations=_observations(proposals, sighting.parents),
        embedding_sum=sighting.embedding_sum,
        embedding_count=sighting.embedding_count,
        timestamp=float(proposals[-1].timestamp),
        existence_logodds=existence.logodds,
        p_exist=existence.p_exist,
        batches_observed=existence.batches_observed,
        reacquired=existence.reacquired,
        parent_evidence=decision.parent_evidence or {},
        corroborated=None if sighting.corroborated else False,
    )


class _FixtureFields(TypedDict):
    """What a fixture's first sighting and each later one record alike."""

    track_id: str
    state: LifecycleState
    frame_id: str | None
    observations: tuple[Observation, ...]
    center: Vec3
    margin: float
    best_frame: str | None
    best_frame_support: int
    existence_logodds: float
    p_exist: float
    batches_observed: int
    timestamp: float


def _fixture_event(decision: TrackDecision, sighting: FixtureSighting) -> Event:
    existence, proposal = sighting.existence, sighting.proposal
    fields = _FixtureFields(
        track_id=sighting.track_id,
        state=decision.lifecycle,
        frame_id=sighting.frame_id,
        observations=_fixture_observation(proposal, sighting.batch_frame),
        center=sighting.center,
        margin=proposal.margin,
        best_frame=sighting.best_frame,
        best_frame_support=sighting.best_frame_support,
        existence_logodds=existence.logodds,
        p_exist=existence.p_exist,
        batches_observed=existence.batches_observed,
        timestamp=sighting.timestamp,
    )
    if sighting.new:
        return FixtureAdded(**fields)
    return FixtureObserved(**fields, reacquired=existence.reacquired)


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
