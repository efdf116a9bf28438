"""Store and core records -> the wire models of api_schema (the routes' one mapping layer)."""

from __future__ import annotations

from api_schema import (
    BaselinePackage,
    BaselineSummary,
    BatchStatus,
    Deferred,
    EventOut,
    Inspection,
    PlanOut,
    PlanTarget,
    Pose2D,
    QueueEntry,
    Scene,
    TrackBelief,
    Uncertainty,
    ViewOut,
)
from codec.occupancy import frontier_out
from core.events import InspectionRecorded
from core.planner import Candidate, Plan
from core.state import Track
from service.store.baselines import StoredPackage
from service.store.event_log import SceneRecord, StoredEvent
from service.store.queue_records import BatchRecord


def scene_out(record: SceneRecord) -> Scene:
    """A scene row."""
    return Scene.model_validate(record, from_attributes=True)


def batch_out(record: BatchRecord) -> BatchStatus:
    """A queue row."""
    status = BatchStatus.model_validate(record, from_attributes=True)
    return status.model_copy(update={"raw_collected_at": record.blob_collected_at})


def event_out(event: StoredEvent) -> EventOut:
    """A log row, its payload as stored."""
    return EventOut.model_validate(event, from_attributes=True)


def package_out(stored: StoredPackage) -> BaselinePackage:
    """A frozen package."""
    return BaselinePackage.model_validate(stored, from_attributes=True)


def package_summary(stored: StoredPackage) -> BaselineSummary:
    """A package's version, seq, hash and size."""
    return BaselineSummary(
        version=stored.version,
        seq=stored.seq,
        sha256=stored.sha256,
        fixture_count=len(stored.package["fixtures"]),
    )


def inspection_out(seq: int, event: InspectionRecorded) -> Inspection:
    """A ledger entry from its event."""
    return Inspection.model_validate({"seq": seq, **event.details()})


def belief_out(scene_id: str, seq: int, track: Track) -> TrackBelief:
    """One track's belief."""
    embedding = track.embedding()
    return TrackBelief(
        scene_id=scene_id,
        seq=seq,
        track_id=track.track_id,
        kind=track.kind,
        label=track.label,
        state=track.lifecycle,
        p_exist=track.p_exist,
        existence_logodds=track.existence_logodds,
        class_probabilities=track.class_probabilities(),
        class_evidence=dict(track.class_evidence),
        center=list(track.center),
        covariance=track.covariance(),
        extent=list(track.extent),
        recent_centers=[list(c) for c in track.recent_centers],
        parent=track.parent,
        parent_probabilities=track.parent_probabilities(),
        embedding=None if embedding is None else [float(v) for v in embedding],
        embedding_count=track.embedding_count,
        last_observed=track.last_observed,
        last_observed_frame=track.last_observed_frame,
        batches_observed=track.batches_observed,
        visible_misses=track.visible_misses,
        published_center=None if track.published_center is None else list(track.published_center),
    )


def _queue_entry(entry: Candidate) -> QueueEntry:
    return QueueEntry(
        fixture_id=entry.fixture_id,
        label=entry.label,
        uncertainty=Uncertainty(value=entry.uncertainty.value, terms=entry.uncertainty.terms),
        proximity=entry.proximity,
        score=entry.score,
    )


def plan_out(scene_id: str, plan: Plan, event_seq: int | None) -> PlanOut:
    """A plan, with the seq of the lock event it appended (if any)."""
    target = None
    if plan.target is not None:
        entry, view = plan.target.candidate, plan.target.view
        queue = _queue_entry(entry)
        target = PlanTarget(
            fixture_id=entry.fixture_id,
            label=entry.label,
            uncertainty=queue.uncertainty,
            proximity=entry.proximity,
            score=entry.score,
            view=ViewOut(
                x=view.pose.x,
                y=view.pose.y,
                yaw=view.pose.yaw,
                pitch=view.pitch,
                cost=view.cost,
                cost_terms=view.cost_terms,
                standoff_m=view.standoff_m,
                travel_m=view.travel_m,
                clearance_m=view.clearance_m,
                coverage=view.coverage,
            ),
        )
    return PlanOut(
        scene_id=scene_id,
        seq=plan.seq,
        decision=plan.decision,
        reason=plan.reason,
        robot_pose=Pose2D(x=plan.robot.x, y=plan.robot.y, yaw=plan.robot.yaw),
        lock=plan.lock,
        event_seq=event_seq,
        replaces=plan.replaces,
        target=target,
        frontier=None if plan.frontier is None else frontier_out(plan.frontier),
        deferred=[Deferred(fixture_id=d.fixture_id, reason=d.reason) for d in plan.deferred],
        queue=[_queue_entry(entry) for entry in plan.ranked],
    )
