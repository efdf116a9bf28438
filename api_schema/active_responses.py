"""Response models of the v1 API's active half (section 3.4): inspections, the occupancy map
and the planner's decision. Exported with the others by `api_schema`."""

from __future__ import annotations

from pydantic import BaseModel, Field


class Pose2D(BaseModel):
    """A planar pose: metres and radians."""

    x: float
    y: float
    yaw: float


class Inspection(BaseModel):
    """One capture of the inspection ledger."""

    seq: int
    capture_id: str
    fixture_id: str
    frames: list[str]
    primary_frame: str | None
    fixture_verified: bool | None
    outcome: str = Field(description="completed, support_not_visible or parent_rejected.")
    children: list[str]
    attempts: int = Field(description="Failed captures of this fixture so far.")
    status: str | None = Field(
        description="completed, abandoned (retries used up) or null (queued)."
    )
    view: Pose2D | None = Field(None, description="Where the robot stood for the capture.")


class InspectionList(BaseModel):
    """The capture ledger of a scene."""

    inspections: list[Inspection]


class InspectionQueueItem(BaseModel):
    """A confirmed fixture of the inspection taxonomy whose inspection is unresolved."""

    fixture_id: str
    label: str
    p_exist: float
    center: list[float]
    attempts: int
    status: str = Field(
        description="queued (in Q_t), in_progress (the locked target) or retry_cooldown."
    )
    uncertainty: float = Field(description="u_i of equation (4).")


class InspectionQueue(BaseModel):
    """Unresolved fixtures (section 3.4), most uncertain first; Q_t is those `queued`."""

    fixtures: list[InspectionQueueItem]


class Frontier(BaseModel):
    """A cluster of free cells bordering unknown ones (Yamauchi)."""

    size: int = Field(description="Cells.")
    centroid: list[float] = Field(description="World x, y of the cluster's centroid.")
    goal: list[float] | None = Field(
        None, description="The reachable 10 cm cell nearest the centroid (plans only)."
    )
    travel_m: float | None = Field(None, description="Travel distance to the goal (plans only).")


class Occupancy(BaseModel):
    """The occupancy map A_t: the known window of a grid of square cells, run-length encoded."""

    scene_id: str
    seq: int = Field(description="The seq the map is folded to.")
    resolution_m: float = Field(description="Cell size, metres.")
    origin: list[float] = Field(
        description="World x, y of the lower-left corner of cell (row 0, col 0)."
    )
    shape: list[int] = Field(description="[rows, cols]: rows grow with y, columns with x.")
    encoding: str = Field(
        description="`rle`: `cells` holds (code, count) pairs over the cells in row-major order "
        "(row 0 first); codes 0 unknown, 1 free, 2 occupied."
    )
    cells: list[int]
    counts: dict[str, int] = Field(description="Cells per state: unknown, free, occupied.")
    frontiers: list[Frontier] = Field(description="Frontier clusters, largest first.")


class Uncertainty(BaseModel):
    """u_i of equation (4) and its six terms phi_i (each in [0, 1])."""

    value: float
    terms: dict[str, float] = Field(
        description="existence, class, parent, position, age, confirmation."
    )


class QueueEntry(BaseModel):
    """One fixture of Q_t with the terms of equation (5)."""

    fixture_id: str
    label: str
    uncertainty: Uncertainty
    proximity: float = Field(description="Prox(i): 1 at the robot, 0 from 8 m.")
    score: float = Field(description="0.8 u_i + 0.2 Prox(i).")


class ViewOut(BaseModel):
    """An inspection view and its cost J, equation (6)."""

    x: float
    y: float
    yaw: float = Field(description="Heading to face the support's centre, radians.")
    pitch: float = Field(description="Camera tilt, radians (negative looks down).")
    cost: float = Field(description="J(v, i).")
    cost_terms: dict[str, float] = Field(
        description="standoff |d_foot - 0.9|, travel 0.08 D_t, clearance -0.20 min(Clr, 1), "
        "coverage 4 (1 - Cov), margin P_margin: they sum to J."
    )
    standoff_m: float
    travel_m: float
    clearance_m: float
    coverage: float


class PlanTarget(BaseModel):
    """The fixture to inspect and from where."""

    fixture_id: str
    label: str
    uncertainty: Uncertainty
    proximity: float
    score: float
    view: ViewOut


class Deferred(BaseModel):
    """A fixture passed over, and why."""

    fixture_id: str
    reason: str = Field(description="no_feasible_view or retry_cooldown.")


class PlanOut(BaseModel):
    """What the robot should do next (section 3.4)."""

    scene_id: str
    seq: int = Field(description="The seq the plan was decided on (reproducible with as_of).")
    decision: str = Field(description="inspect, explore or done.")
    reason: str
    robot_pose: Pose2D
    lock: str | None = Field(
        description="held (the locked target) or new (a new lock: `inspection_targeted`)."
    )
    event_seq: int | None = Field(
        description="Seq of the `inspection_targeted` event this request appended, if any."
    )
    replaces: str | None = Field(description="The fixture of the lock a new one replaces.")
    target: PlanTarget | None
    frontier: Frontier | None
    deferred: list[Deferred]
    queue: list[QueueEntry] = Field(description="Q_t ranked by equation (5), best first.")
