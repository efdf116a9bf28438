"""Store and core records -> the wire models of api_schema (the routes' one mapping layer)."""

from __future__ import annotations

import io

import numpy as np
from PIL import Image

from api_schema import (
    BaselinePackage,
    BaselineSummary,
    BatchStatus,
    Deferred,
    EventOut,
    Frontier,
    Inspection,
    Occupancy,
    PlanOut,
    PlanTarget,
    Pose2D,
    QueueEntry,
    Scene,
    TrackBelief,
    Uncertainty,
    ViewOut,
)
from core.events import InspectionRecorded
from core.navigation import Frontier as CoreFrontier
from core.navigation import frontier_clusters
from core.occupancy import CODE_FREE, CODE_OCCUPIED, CODE_UNKNOWN, MapGeometry, OccupancyGrid
from core.planner import Candidate, Plan
from core.state import SceneState, Track
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


def _known_window(grid: OccupancyGrid) -> tuple[tuple[int, int], np.ndarray]:
    """The codes of the bounding box of the known cells, and its origin (row, col)."""
    codes = grid.codes()
    rows, cols = np.nonzero(codes != CODE_UNKNOWN)
    if rows.size == 0:
        return grid.origin, np.zeros((0, 0), dtype=np.uint8)
    r0, r1, c0, c1 = int(rows.min()), int(rows.max()) + 1, int(cols.min()), int(cols.max()) + 1
    return (grid.origin[0] + r0, grid.origin[1] + c0), codes[r0:r1, c0:c1]


def _frontier_out(frontier: CoreFrontier) -> Frontier:
    return Frontier(
        size=frontier.size,
        centroid=list(frontier.centroid),
        goal=None if frontier.goal is None else list(frontier.goal),
        travel_m=frontier.travel_m,
    )


def occupancy_out(scene_id: str, state: SceneState) -> Occupancy:
    """The map's known window as (code, count) runs, with its frontier clusters."""
    geometry = MapGeometry.of(state.params.occupancy)
    origin, codes = _known_window(state.occupancy)
    flat = codes.ravel()
    runs: list[int] = []
    if flat.size:
        starts = np.concatenate(([0], np.flatnonzero(flat[1:] != flat[:-1]) + 1))
        lengths = np.diff(np.concatenate((starts, [flat.size])))
        runs = np.column_stack((flat[starts], lengths)).ravel().tolist()
    x0, y0 = geometry.center_of(origin[0], origin[1])
    half = geometry.resolution_m / 2
    counts = np.bincount(flat, minlength=3) if flat.size else np.zeros(3, np.int64)
    min_cells = state.params.planner.min_frontier_cells
    return Occupancy(
        scene_id=scene_id,
        seq=state.head_seq,
        resolution_m=geometry.resolution_m,
        origin=[float(x0) - half, float(y0) - half],
        shape=[int(codes.shape[0]), int(codes.shape[1])],
        encoding="rle",
        cells=runs,
        counts={
            "unknown": int(counts[CODE_UNKNOWN]),
            "free": int(counts[CODE_FREE]),
            "occupied": int(counts[CODE_OCCUPIED]),
        },
        frontiers=[
            _frontier_out(f) for f in frontier_clusters(state.occupancy, geometry, min_cells)
        ],
    )


# Grey levels of the PNG (as ROS map_server writes maps): occupied black, free white.
PNG_LEVELS = np.array([205, 254, 0], dtype=np.uint8)  # unknown, free, occupied


def occupancy_png(state: SceneState) -> tuple[bytes, list[float]]:
    """The known window as an 8-bit grey PNG, north (+y) up, and its origin (x, y)."""
    geometry = MapGeometry.of(state.params.occupancy)
    origin, codes = _known_window(state.occupancy)
    if codes.size == 0:
        codes = np.zeros((1, 1), dtype=np.uint8)  # one unknown cell: PNG has no empty image
    image = Image.fromarray(np.ascontiguousarray(PNG_LEVELS[codes][::-1]))
    buffer = io.BytesIO()
    image.save(buffer, format="PNG")
    x0, y0 = geometry.center_of(origin[0], origin[1])
    half = geometry.resolution_m / 2
    return buffer.getvalue(), [float(x0) - half, float(y0) - half]


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
        frontier=None if plan.frontier is None else _frontier_out(plan.frontier),
        deferred=[Deferred(fixture_id=d.fixture_id, reason=d.reason) for d in plan.deferred],
        queue=[_queue_entry(entry) for entry in plan.ranked],
    )
