"""The result of each benchmark as a typed record: what its `main` writes to bench/results/ and
what `bench.summary` reads back (validated by pydantic, so a file of another shape is reported
as unreadable rather than misread).

Field names are the JSON keys. A figure measured per backend is a field per backend, absent
(null) when that backend was not run.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from pydantic import TypeAdapter

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

LIVE_ONLY = "500 live tracks"  # the decide benchmark's reference condition
Record = TypeVar("Record")


def to_json(record: DataclassInstance, **around: Any) -> str:
    """A record as the JSON a benchmark writes (`around`: keys written before its fields)."""
    return json.dumps({**around, **dataclasses.asdict(record)}, indent=2) + "\n"


def read_record(kind: type[Record], path: Path) -> Record:
    """A result file as its record; pydantic's ValidationError (a ValueError) when the file has
    another shape."""
    return TypeAdapter(kind).validate_json(path.read_bytes())


# --- render, decide, fixture step, plan, rollout ---------------------------------------------


@dataclass(frozen=True)
class RenderRun:
    frames: int
    render_ms_per_frame: float
    detect_ms_per_frame: float
    fps: float


@dataclass(frozen=True)
class RenderResult:
    resolution: tuple[int, int]
    cpu_count: int | None
    machine: str
    one_thread: RenderRun
    all_threads: RenderRun


@dataclass(frozen=True)
class DecideCondition:
    tracks: int
    events_per_batch: int
    decide_median_ms: float
    evolve_median_ms: float
    decide_evolve_median_ms: float
    decide_evolve_p90_ms: float
    ratio_to_live_only: float


@dataclass(frozen=True)
class DecideResult:
    masks: int
    resolution: tuple[int, int]
    repeats: int
    goal_ms: float
    goal_ratio_with_hypotheses: float
    conditions: dict[str, DecideCondition]  # LIVE_ONLY and the conditions with hypotheses
    # decide's stages on the LIVE_ONLY batch (bench_decide.STAGES), median ms each.
    stages_median_ms: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class StreamCondition:
    tracks: int  # at the end of the stream
    median_ms: float  # decide + fold per frame
    p90_ms: float


@dataclass(frozen=True)
class StreamResult:
    scenario: str
    seed: int
    frames: int
    goal_ms: float
    conditions: dict[str, StreamCondition]  # the stream's own tracks, and with extra tracks
    stages_median_ms_per_frame: dict[str, float]


@dataclass(frozen=True)
class Timings:
    median_ms: float
    p90_ms: float
    max_ms: float


@dataclass(frozen=True)
class FixtureStepCondition:
    voxels: tuple[int, int]  # the smallest and largest map of the timed batches
    incremental: Timings
    full: Timings
    incremental_cpu: Timings
    full_cpu: Timings
    fold_of_the_batch: Timings
    median_ratio_full_to_incremental: float
    goal_met_wall: bool
    goal_met_cpu: bool


@dataclass(frozen=True)
class FixtureStepResult:
    scenario: str
    house_copies: int
    warmup_batches: int
    timed_batches: int
    repeats: int
    goal_ms: float
    conditions: dict[str, FixtureStepCondition]  # "suite" and "house"


@dataclass(frozen=True)
class EvidenceSizes:
    frames: int
    bytes_per_batch_median: float
    bytes_per_batch_max: int
    evidence_ms_per_frame_median: float
    evidence_ms_per_frame_median_raw_depth: float


@dataclass(frozen=True)
class PlanResult:
    map_cells: tuple[int, int]
    resolution_m: float
    fixtures: int
    decisions: int
    ms_per_decision_median: float
    ms_per_decision_p90: float
    ms_per_decision_max: float
    navigation_ms_median: float
    outcomes: dict[str, int]
    goal_ms: float
    evidence: EvidenceSizes


@dataclass(frozen=True)
class RolloutBenchResult:
    scenario: str
    area_m2: float
    seed: int
    rollout_s: float
    goal_rollout_s: float
    keyframes: int
    inspections: int
    path_m: float
    decisions: int
    planner_ms_median: float
    planner_ms_p90: float
    planner_ms_max: float
    goal_planner_ms: float
    stop_reason: str


# --- the store: append, as_of, versus, raw batches; blobs; memory ----------------------------


@dataclass(frozen=True)
class AppendRate:
    seconds: float
    events_per_s: float


@dataclass(frozen=True)
class AppendResult:
    events: int
    batch: int
    goal_events_per_s: float
    sqlite: AppendRate | None = None
    postgres: AppendRate | None = None


@dataclass(frozen=True)
class SnapshotStorage:
    snapshots: int
    snapshot_bytes: int


@dataclass(frozen=True)
class AsOfBackend:
    head_seq: int
    as_of_median_ms: float
    as_of_p90_ms: float
    full_replay_ms: float
    speedup: float
    database_bytes: int
    snapshots: int
    snapshot_bytes: int
    build_seconds: float


@dataclass(frozen=True)
class AsOfResult:
    events: int
    snapshot_interval: int
    sqlite: AsOfBackend | None = None
    postgres: AsOfBackend | None = None


@dataclass(frozen=True)
class VersusRow:
    ours_events_per_s: float
    eventsourcing_events_per_s: float
    ratio: float
    eventsourcing_per_track_events_per_s: float
    ratio_per_track: float
    samples: dict[str, list[float]]  # by appender, one per round


@dataclass(frozen=True)
class VersusResult:
    rounds: int
    events_per_measurement: dict[int, int]  # by batch size
    event_json_bytes_mean: float
    peer: str
    sqlite: dict[str, VersusRow] | None = None  # by batch size
    postgres: dict[str, VersusRow] | None = None


@dataclass(frozen=True)
class RawResult:
    frames: int
    zstd_level: int
    json_base64_bytes_per_frame: float
    compact_bytes_per_frame: float
    compact_max_bytes_per_frame: int
    ratio: float
    encode_ms_median: float
    decode_ms_median: float
    events_per_frame_steady: float
    compact_raw_bytes_per_event: float
    json_base64_raw_bytes_per_event: float
    event_details_bytes_mean: float
    goal_bytes_per_frame: int


@dataclass(frozen=True)
class BlobBackendFigures:
    put_enqueue_ms_median: float
    put_enqueue_ms_p90: float
    get_ms_median: float
    get_ms_p90: float
    disk_bytes_per_blob: int
    put_enqueue_vs_folder: float | None = None  # PostgreSQL's table against the folder
    get_vs_folder: float | None = None


@dataclass(frozen=True)
class BlobBody:
    mean_blob_bytes: int
    backends: dict[str, BlobBackendFigures]


@dataclass(frozen=True)
class BlobsResult:
    rounds: int
    batches_per_round: int
    bodies: dict[str, BlobBody]


@dataclass(frozen=True)
class MemoryCase:
    body_mb: float
    frames: int
    detections: int
    api_peak_mb: float
    worker_peak_mb: float
    accept_seconds: float
    work_seconds: float
    batch_status: str


@dataclass(frozen=True)
class MemoryResult:
    budget_mb: float
    cases: dict[str, MemoryCase]


# --- the service end to end ------------------------------------------------------------------


@dataclass
class Figures:
    """What one configuration of the end-to-end benchmark measured."""

    config: str
    title: str
    rate_per_scene: float
    scenes: int
    workers: int
    seconds: float
    batches: int = 0
    accepted: int = 0
    done: int = 0
    send_lag_p99_ms: float = 0.0
    throughput: float = 0.0
    post_p50_ms: float = 0.0
    post_p99_ms: float = 0.0
    done_p50_ms: float = 0.0
    done_p99_ms: float = 0.0
    done_max_ms: float = 0.0
    backlog_at_end: int = 0
    drain_seconds: float = 0.0
    decide_mean_ms: float | None = None
    append_mean_ms: float | None = None
    cpu_seconds: dict[str, float] = field(default_factory=dict)
    machine_busy_cores: float = 0.0
    load_generator_cpu_seconds: float = 0.0
    errors: list[str] = field(default_factory=list)

    @property
    def offered(self) -> float:
        return self.rate_per_scene * self.scenes


@dataclass(frozen=True)
class Sustained:
    rates_tried: list[float]
    highest_sustained: float | None
    done_p50_ms: float | None
    done_p99_ms: float | None


@dataclass(frozen=True)
class AtRate:
    config: str
    rate: float
    goal: str
    keeps_up: bool
    done_p99_ms: float
    met: bool


@dataclass(frozen=True)
class Scaling:
    goal: str
    ratio: float
    one_worker_saturated: bool
    met: bool


@dataclass(frozen=True)
class CpuBound:
    worker_cpu_ms_per_batch: float
    api_cpu_ms_per_batch: float
    cores: int
    one_worker_max_per_s: float
    two_workers_max_per_s: float
    two_worker_ratio_max: float
    # One worker also waits (PostgreSQL, the claim, the idle poll), so it does less than its
    # CPU bound; against what it did, two workers could gain more.
    two_workers_max_over_measured_one: float | None


@dataclass(frozen=True)
class Capacity:
    value: float
    bound: str


@dataclass(frozen=True)
class ServiceGoals:
    one_worker_sustains_per_s: Sustained | None = None
    one_worker_at_rate: AtRate | None = None
    two_workers_scaling: Scaling | None = None
    cpu_bound: CpuBound | None = None
    one_worker_capacity_per_s: Capacity | None = None


@dataclass(frozen=True)
class ServiceResult:
    benchmark: str
    rate_per_scene: float
    seconds: float
    body_bytes_mean: int
    object_masks: int
    fixture_masks: list[int]
    clock: str
    service_settings: dict[str, str]
    load_average_at_start: list[float]
    stage_breakdown_ms: dict[str, float]
    configs: dict[str, Figures]
    goals: ServiceGoals
