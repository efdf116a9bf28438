"""Response models of the v1 API."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field

BatchStatusName = Literal["queued", "running", "done", "failed", "dead"]


class Scene(BaseModel):
    """A scene and the head of its log."""

    id: str = Field(description="Scene id.")
    name: str = Field(description="Human-readable name.")
    head_seq: int = Field(description="Seq of the newest event; 0 is the scene's creation.")
    created_at: float = Field(description="Unix seconds.")
    params: dict[str, Any] = Field(
        description="The method parameters the scene's events are decided with."
    )
    quarantined: str | None = Field(
        None,
        description="Why the scene takes no more writes (an unreadable event; `pbdag repair` "
        "names the scene that replaces it), or null.",
    )


class SceneList(BaseModel):
    """A page of scenes, oldest first; pass `next_after` as `after` for the next page (null at
    the end)."""

    scenes: list[Scene]
    next_after: str | None = None


class BatchStatus(BaseModel):
    """Where a posted batch is in the queue, and the events it appended."""

    batch_id: str
    scene_id: str
    status: BatchStatusName = Field(
        description="queued, running, done, failed (will retry) or dead."
    )
    attempts: int
    frame_count: int
    content_sha256: str
    first_seq: int | None = Field(
        description="First event appended by this batch (null until done)."
    )
    last_seq: int | None = Field(description="Last event appended by this batch (null until done).")
    error: str | None = Field(description="Why the last attempt failed.")
    received_at: float
    finished_at: float | None
    raw_collected_at: float | None = Field(
        None,
        description="When `pbdag gc` deleted the batch's raw body (PBDAG_RAW_RETENTION); its "
        "events stay. Null while it is kept.",
    )


class GraphNode(BaseModel):
    """One track as a graph node."""

    id: str
    kind: str
    label: str
    state: str = Field(description="tentative, confirmed, demoted or removed.")
    p_exist: float
    center: list[float] = Field(description="[x, y, z] in metres, world frame.")
    extent: list[float] = Field(description="[dx, dy, dz] of the stored box, metres.")
    parent: str | None = Field(description="Support parent track id.")
    class_probabilities: dict[str, float]
    last_observed: float | None = Field(description="Timestamp of the last reliable observation.")
    last_observed_frame: str | None
    pinned: bool = Field(description="A fixture of a frozen baseline: exempt from dynamic removal.")
    verification: str | None = Field(
        description="pending, confirmed or rejected (coarse verification)."
    )
    inspection: str | None = Field(
        description="Fixtures: completed or abandoned close-range inspection."
    )


class GraphEdge(BaseModel):
    """object -on-> support."""

    source: str
    target: str
    relation: str


class Graph(BaseModel):
    """The published graph at `seq`."""

    scene_id: str
    seq: int
    nodes: list[GraphNode]
    edges: list[GraphEdge]
    pending_verifications: list[str] = Field(
        description="Fixture hypotheses waiting for a verdict (not published until then)."
    )


class NodeLinkGraph(BaseModel):
    """The graph as networkx's node-link JSON (`format=json-graph`): `networkx.node_link_graph`
    reads it back. Node attributes are those of the default format, `id` the track id."""

    directed: bool
    multigraph: bool
    graph: dict[str, Any] = Field(description="`scene_id` and `seq`.")
    nodes: list[dict[str, Any]]
    edges: list[dict[str, Any]] = Field(description="`source` -on-> `target` (its support).")


class EventOut(BaseModel):
    """One event of the log, its payload as stored."""

    seq: int
    type: str = Field(
        description="The audit type, in the paper's vocabulary (add, update, confirm, move, "
        "reparent, demote, remove, retire, ...); several topics share one."
    )
    topic: str = Field(
        description="The event's class, one name per class and payload form (object_added, "
        "visible_miss, confirm, ...): what `details` holds."
    )
    track_id: str | None
    state: str | None
    batch_id: str | None
    frame_id: str | None
    recorded_at: float
    details: dict[str, Any]


class EventPage(BaseModel):
    """A page of events; pass `next_after` as `after` for the next page (null at the end)."""

    events: list[EventOut]
    next_after: int | None


class TrackBelief(BaseModel):
    """The full belief b_i of one track (equation (2)) at `seq`."""

    scene_id: str
    seq: int
    track_id: str
    kind: str
    label: str
    state: str
    p_exist: float
    existence_logodds: float
    class_probabilities: dict[str, float]
    class_evidence: dict[str, float]
    center: list[float]
    covariance: list[list[float]] = Field(description="Of at most the 32 most recent centers.")
    extent: list[float]
    recent_centers: list[list[float]]
    parent: str | None
    parent_probabilities: dict[str, float]
    embedding: list[float] | None = Field(
        description="Appearance, count-averaged and l2-normalized."
    )
    embedding_count: int
    last_observed: float | None
    last_observed_frame: str | None
    batches_observed: int
    visible_misses: int
    published_center: list[float] | None


class VisibleMiss(BaseModel):
    """One visibility-admissible miss that lowered p_exist."""

    seq: int
    frame_id: str | None
    samples_passed: int
    p_exist_after: float


class Removal(BaseModel):
    """The removal and the evidence behind it."""

    seq: int
    frame_id: str | None
    p_exist: float
    visible_misses: list[VisibleMiss]


class Explanation(BaseModel):
    """Why a track is in its state, from the log alone."""

    track_id: str
    state: str
    summary: str = Field(description="One plain sentence.")
    visible_misses: list[VisibleMiss] = Field(
        description="The visibility-admissible misses since the track's last sighting, oldest "
        "first: their frames and p_exist after each (for a removal, those behind it)."
    )
    removal: Removal | None
    events: list[EventOut] | None = Field(
        None,
        description="Every event of the track, oldest first, with `?events=true`; null otherwise "
        "(each sighting carries its appearance sum, tens of KB for a track seen often).",
    )


class WorkerStatus(BaseModel):
    """The in-process worker's health: whether it can record what it does."""

    healthy: bool
    problem: str | None = Field(description="Why not (a full disk, a lost database).")
    since: float | None = Field(description="Unix time it became unhealthy.")


class Health(BaseModel):
    """Liveness and the queue at a glance."""

    status: Literal["ok", "degraded"] = Field(
        description="`degraded` while the in-process worker cannot record what it does."
    )
    database: str
    batches: dict[str, int]
    worker: WorkerStatus | None = Field(
        None, description="The in-process worker (`pbdag serve`); null when workers run apart."
    )


class VerificationItem(BaseModel):
    """A track waiting for (or with) a coarse-stage verdict."""

    track_id: str
    label: str
    state: str
    verification: str | None
    candidates: dict[str, float] = Field(
        description="Mean class similarity over the fixture's evidence."
    )
    batch_votes: dict[str, float] = Field(description="Share of supporting batches per top class.")
    best_frame: str | None = Field(description="The frame that showed most of it: crop this one.")
    requested_seq: int | None = Field(description="Seq of the verification request.")


class VerificationList(BaseModel):
    """Verification queue."""

    verifications: list[VerificationItem]


class CommandResult(BaseModel):
    """Events a command appended."""

    scene_id: str
    track_id: str | None
    state: str | None
    events: list[EventOut]


class BaselineSummary(BaseModel):
    """One frozen baseline of a scene."""

    version: int
    seq: int = Field(description="Seq of the freeze event.")
    sha256: str = Field(description="sha256 of the canonical JSON package.")
    fixture_count: int


class BaselineList(BaseModel):
    """Every baseline of a scene."""

    baselines: list[BaselineSummary]


class BaselinePackage(BaseModel):
    """An immutable, versioned package of confirmed fixtures."""

    scene_id: str
    version: int
    seq: int
    sha256: str
    package: dict[str, Any] = Field(
        description="The canonical package (its JSON bytes hash to sha256)."
    )


class Delta(BaseModel):
    """The runtime delta: the events after a baseline was frozen."""

    scene_id: str
    baseline: BaselineSummary
    events: list[EventOut]
    next_after: int | None


class ProblemField(BaseModel):
    """One offending field of a request and why."""

    field: str | None = Field(description="A path such as `frames[0].pose`, or null.")
    reason: str


class Problem(BaseModel):
    """An RFC 9457 problem document: every error of the API (`application/problem+json`)."""

    type: str = Field(description="A URI reference naming the problem (`/problems/...`).")
    title: str
    status: int
    detail: str = Field(description="What went wrong, in one sentence.")
    field: str | None = Field(description="The offending request field, or null.")
    errors: list[ProblemField] = Field(description="Every offending field.")
