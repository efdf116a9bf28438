"""The figures each benchmark wrote, read from its JSON: one reader per result file, with the
goals they are judged against (`bench.summary` prints them as one table).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

from bench.records import (
    LIVE_ONLY,
    AppendResult,
    AsOfResult,
    BlobsResult,
    DecideResult,
    FixtureStepResult,
    MemoryResult,
    PlanResult,
    RawResult,
    RenderResult,
    RolloutBenchResult,
    ServiceResult,
    StreamResult,
    VersusResult,
)

T = TypeVar("T")


@dataclass(frozen=True)
class Goal:
    """A bound on one figure: `value <op> bound`, in `unit`."""

    text: str
    op: str  # "<", "<=", ">" or ">="
    bound: float
    unit: str

    def holds(self, value: float) -> bool:
        """Whether `value` meets the goal."""
        return {
            "<": value < self.bound,
            "<=": value <= self.bound,
            ">": value > self.bound,
            ">=": value >= self.bound,
        }[self.op]

    def verdict(self, value: float) -> str:
        """'met', or 'missed by' the distance to the bound, in the unit and in percent."""
        if self.holds(value):
            return "met"
        gap = abs(value - self.bound)
        if gap == 0:
            return f"missed: at the bound, {number(value)}{self.unit}"
        return f"missed by {number(gap)}{self.unit} ({gap / self.bound:.0%})"


# The goals, in one place: issue 11 ("Real time end to end, ahead of the reference event store,
# and bounded storage": fixture step, appending against `eventsourcing`, as_of, raw batches, the
# service end to end) and the goals the benchmark table (docs/benchmarks.md) already held (render, decide,
# append, planner, rollout, memory budget).
GOALS: dict[str, Goal] = {
    "render": Goal(">= 30 frames/s", ">=", 30.0, " frames/s"),
    "decide": Goal("< 10 ms", "<", 10.0, " ms"),
    "decide_hypotheses": Goal("<= 1.5x the live tracks alone", "<=", 1.5, "x"),
    "stream": Goal("median <= 10 ms a frame, 500 more tracks in play", "<=", 10.0, " ms"),
    "fixture_step": Goal("median <= 10 ms per batch at 100k voxels", "<=", 10.0, " ms"),
    "plan": Goal("median < 50 ms per decision", "<", 50.0, " ms"),
    "rollout": Goal("< 5 min", "<", 300.0, " s"),
    "rollout_planner": Goal("median < 50 ms per decision", "<", 50.0, " ms"),
    "append": Goal("> 20,000 events/s", ">", 20_000.0, " events/s"),
    "as_of": Goal("median < 20 ms at 1,000,000 events", "<", 20.0, " ms"),
    "versus": Goal("ours/theirs >= 1 (ahead at every batch size)", ">=", 1.0, ""),
    "raw": Goal("<= 0.300 MB per frame", "<=", 0.3, " MB"),
    "memory": Goal("peak <= 1 GB (1,024 MB)", "<=", 1024.0, " MB"),
    "service_one_worker": Goal(
        "one worker keeps up with 30 frames/s, POST-to-done p99 < 200 ms", ">=", 30.0, "/s"
    ),
    "service_p99": Goal("p99 < 200 ms", "<", 200.0, " ms"),
    "service_two_workers": Goal(">= 1.8x one worker (2 scenes each)", ">=", 1.8, "x"),
}
AS_OF_EVENTS = 1_000_000  # the scene size the as_of goal is stated at
FIXTURE_VOXELS = 100_000  # the map size the fixture step's goal is stated at


def number(value: float) -> str:
    """A figure with as many digits as it deserves: 20,000 / 173 / 7.3 / 0.32."""
    size = abs(value)
    if size >= 1000:
        return f"{value:,.0f}"
    if size >= 100:
        return f"{value:.0f}"
    if size >= 1:
        return f"{value:.1f}"
    if size >= 0.1:
        return f"{value:.2f}"
    return f"{value:.3f}"


@dataclass
class Figure:
    """One line of the table, as a benchmark's reader produces it."""

    label: str
    figure: str
    peer: str = ""
    goal: str | None = None  # a key of GOALS
    value: float | None = None  # what the goal bounds
    verdict: str | None = None  # a reader's own verdict (goals that bound several figures)
    met: bool | None = None


# --- the readers: one per result file, each reading the record its benchmark writes -------


def read_render(data: RenderResult) -> list[Figure]:
    one, every = data.one_thread.fps, data.all_threads.fps
    return [
        Figure(
            "render + detect, 640x480",
            f"{number(one)} frames/s on one thread, {number(every)} on all",
            goal="render",
            value=one,
        )
    ]


def read_decide(data: DecideResult) -> list[Figure]:
    live = data.conditions[LIVE_ONLY]
    base = live.decide_evolve_median_ms
    figures = [
        Figure(
            "decide + evolve, 20 masks, 500 live tracks",
            f"median {number(base)} ms, p90 {number(live.decide_evolve_p90_ms)} ms "
            f"(decide {number(live.decide_median_ms)}, "
            f"evolve {number(live.evolve_median_ms)})",
            goal="decide",
            value=base,
        )
    ]
    others = {name: row for name, row in data.conditions.items() if name != LIVE_ONLY}
    if others:
        worst = max(row.ratio_to_live_only for row in others.values())
        figures.append(
            Figure(
                "decide + evolve with retired or stale hypotheses in memory",
                ", ".join(
                    f"{name}: {number(row.decide_evolve_median_ms)} ms "
                    f"({row.ratio_to_live_only:.2f}x)"
                    for name, row in others.items()
                ),
                peer=f"500 live tracks alone: {number(base)} ms",
                goal="decide_hypotheses",
                value=worst,
            )
        )
    if data.stages_median_ms:
        ranked = sorted(data.stages_median_ms.items(), key=lambda item: -item[1])
        figures.append(
            Figure(
                "decide per stage, 500 live tracks (the largest first)",
                ", ".join(f"{name} {number(ms)} ms" for name, ms in ranked),
            )
        )
    return figures


def read_stream(data: StreamResult) -> list[Figure]:
    own, *more = data.conditions.values()
    loaded = more[-1] if more else own
    ranked = sorted(data.stages_median_ms_per_frame.items(), key=lambda item: -item[1])
    return [
        Figure(
            f"decide + fold per frame, {data.scenario} stream ({data.frames} frames)",
            f"median {number(loaded.median_ms)} ms, p90 {number(loaded.p90_ms)} ms with "
            f"{loaded.tracks} tracks in play",
            peer=f"its own {own.tracks} tracks: median {number(own.median_ms)} ms",
            goal="stream",
            value=loaded.median_ms,
        ),
        Figure(
            f"decide per stage per frame, {data.scenario} stream (the largest first)",
            ", ".join(f"{name} {number(ms)} ms" for name, ms in ranked),
        ),
    ]


def read_fixture_step(data: FixtureStepResult) -> list[Figure]:
    figures = []
    for name, goal in (("house", "fixture_step"), ("suite", None)):
        row = data.conditions.get(name)
        if row is None:
            continue
        kept, cpu = row.incremental, row.incremental_cpu
        low, high = row.voxels
        figure = Figure(
            f"fixture step per batch, {name} ({number(low)}-{number(high)} voxels)",
            f"median {kept.median_ms:.1f} ms, p90 {kept.p90_ms:.1f}, max "
            f"{kept.max_ms:.1f} (CPU median {cpu.median_ms:.1f})",
            peer=f"full re-clustering {number(row.full.median_ms)} ms "
            f"({row.median_ratio_full_to_incremental:.1f}x)",
            goal=goal,
            value=kept.median_ms,
        )
        if goal and low < FIXTURE_VOXELS:
            figure.verdict = f"not judged: {number(low)} voxels, the goal is at 100k"
        figures.append(figure)
    return figures


def read_plan(data: PlanResult) -> list[Figure]:
    evidence = data.evidence
    return [
        Figure(
            "planner decision, 20 m x 20 m at 5 cm",
            f"median {number(data.ms_per_decision_median)} ms, p90 "
            f"{number(data.ms_per_decision_p90)}, max {number(data.ms_per_decision_max)}; "
            f"occupancy evidence {evidence.bytes_per_batch_median / 1000:.1f} KB per frame, "
            f"{number(evidence.evidence_ms_per_frame_median)} ms "
            f"({number(evidence.evidence_ms_per_frame_median_raw_depth)} without the depth "
            "median)",
            goal="plan",
            value=data.ms_per_decision_median,
        )
    ]


def read_rollout(data: RolloutBenchResult) -> list[Figure]:
    return [
        Figure(
            f"autonomous rollout, {data.scenario} ({number(data.area_m2)} m², seed {data.seed})",
            f"{number(data.rollout_s)} s: {data.keyframes} keyframes, "
            f"{data.inspections} inspections, {number(data.path_m)} m "
            f"({data.stop_reason})",
            goal="rollout",
            value=data.rollout_s,
        ),
        Figure(
            "planner per decision during the rollout",
            f"median {number(data.planner_ms_median)} ms, p90 "
            f"{number(data.planner_ms_p90)}, max {number(data.planner_ms_max)} over "
            f"{data.decisions} decisions",
            goal="rollout_planner",
            value=data.planner_ms_median,
        ),
    ]


BACKENDS = {"sqlite": "SQLite", "postgres": "PostgreSQL"}


def per_backend(sqlite: T | None, postgres: T | None) -> list[tuple[str, T]]:
    """The backends that were run, with their figures, SQLite first."""
    return [(name, row) for name, row in (("sqlite", sqlite), ("postgres", postgres)) if row]


def read_append(data: AppendResult) -> list[Figure]:
    return [
        Figure(
            f"append, {BACKENDS[name]}, batches of {data.batch}",
            f"{number(row.events_per_s)} events/s",
            goal="append",
            value=row.events_per_s,
        )
        for name, row in per_backend(data.sqlite, data.postgres)
    ]


def read_as_of(data: AsOfResult) -> list[Figure]:
    figures = []
    for name, row in per_backend(data.sqlite, data.postgres):
        figure = Figure(
            f"as_of, {BACKENDS[name]}, {number(row.head_seq)} events",
            f"median {number(row.as_of_median_ms)} ms, p90 {number(row.as_of_p90_ms)}; "
            f"snapshots {number(row.snapshot_bytes / row.head_seq)} bytes per event",
            peer=f"full replay {number(row.full_replay_ms / 1000)} s ({number(row.speedup)}x)",
            goal="as_of",
            value=row.as_of_median_ms,
        )
        if data.events < AS_OF_EVENTS:
            figure.verdict = f"not judged: {number(data.events)} events, the goal is at 1M"
        figures.append(figure)
    return figures


def read_versus(data: VersusResult) -> list[Figure]:
    figures = []
    for name, rows in per_backend(data.sqlite, data.postgres):
        for batch, row in rows.items():
            figures.append(
                Figure(
                    f"append vs {data.peer}, {BACKENDS[name]}, batches of {batch}",
                    f"ours {number(row.ours_events_per_s)} events/s: {row.ratio:.2f} "
                    f"(per track {row.ratio_per_track:.2f})",
                    peer=f"{number(row.eventsourcing_events_per_s)}/s one aggregate, "
                    f"{number(row.eventsourcing_per_track_events_per_s)}/s one per track",
                    goal="versus",
                    value=row.ratio,
                )
            )
    return figures


def read_raw(data: RawResult) -> list[Figure]:
    compact = data.compact_bytes_per_frame / 1e6
    return [
        Figure(
            "raw batch kept per 640x480 frame",
            f"{compact:.3f} MB compact (max {data.compact_max_bytes_per_frame / 1e6:.3f}); "
            f"{data.compact_raw_bytes_per_event / 1000:.1f} kB per event; encode "
            f"{number(data.encode_ms_median)} ms, decode {number(data.decode_ms_median)} ms",
            peer=f"JSON with base64 depth {data.json_base64_bytes_per_frame / 1e6:.3f} MB "
            f"(x{data.ratio:.2f})",
            goal="raw",
            value=round(compact, 3),
        )
    ]


def read_blobs(data: BlobsResult) -> list[Figure]:
    figures = []
    for body, row in data.bodies.items():
        table, folder = row.backends["postgres+table"], row.backends["postgres+folder"]
        figures.append(
            Figure(
                f"raw batch storage, PostgreSQL table, {body} ({row.mean_blob_bytes / 1e6:.2f} MB)",
                f"put + enqueue {number(table.put_enqueue_ms_median)} ms, "
                f"get {table.get_ms_median:.2f} ms",
                peer=f"folder {number(folder.put_enqueue_ms_median)} / "
                f"{folder.get_ms_median:.2f} ms (table/folder "
                f"{table.put_enqueue_vs_folder:.2f} / {table.get_vs_folder:.1f})",
            )
        )
    return figures


def read_memory(data: MemoryResult) -> list[Figure]:
    cases = data.cases
    worst = max(cases, key=lambda name: max(cases[name].api_peak_mb, cases[name].worker_peak_mb))
    api = max(case.api_peak_mb for case in cases.values())
    worker = max(case.worker_peak_mb for case in cases.values())
    return [
        Figure(
            "peak memory of the largest accepted batches",
            f"at most {number(max(api, worker))} MB (API {number(api)}, worker "
            f"{number(worker)}; largest: {worst})",
            goal="memory",
            value=max(api, worker),
        )
    ]


def read_service(data: ServiceResult) -> list[Figure]:
    return [one_worker_figure(data), two_workers_figure(data)]


def one_worker_figure(data: ServiceResult) -> Figure:
    """One worker on one scene at the goal's rate, and the highest rate of the ramp it kept up
    with."""
    label = "service end to end, one worker, one scene"
    at_rate, ramp = data.goals.one_worker_at_rate, data.goals.one_worker_sustains_per_s
    if at_rate is None:
        return Figure(label, "not measured in this run", goal="service_one_worker")
    one = data.configs[at_rate.config]
    text = (
        f"({at_rate.config}) at {at_rate.rate:g}/s: {number(one.throughput)} "
        f"done/s, p99 {number(one.done_p99_ms)} ms"
    )
    sustained = ramp.highest_sustained if ramp else None
    if ramp:
        text += (
            "; sustains none of " + ", ".join(f"{r:g}" for r in ramp.rates_tried) + "/s"
            if sustained is None
            else f"; sustains {sustained:g}/s, p99 {number(ramp.done_p99_ms or 0.0)} ms"
        )
    if at_rate.met:
        verdict = "met"
    else:
        # The highest rate of the ramp it kept up with, else what it did at the goal's rate.
        kept = sustained if sustained is not None else one.throughput
        shown = f"{sustained:g}" if sustained is not None else number(kept)
        goal = GOALS["service_one_worker"]
        verdict = f"missed: {shown}/s ({(goal.bound - kept) / goal.bound:.0%} short)"
        if at_rate.done_p99_ms >= GOALS["service_p99"].bound:
            verdict += f", p99 {number(at_rate.done_p99_ms)} ms at {at_rate.rate:g}/s"
    return Figure(label, text, goal="service_one_worker", verdict=verdict, met=at_rate.met)


def two_workers_figure(data: ServiceResult) -> Figure:
    """Two workers on two scenes against one worker on two scenes, and the CPU bound."""
    label = "service end to end, two workers on two scenes"
    scaling, bound = data.goals.two_workers_scaling, data.goals.cpu_bound
    if scaling is None:
        return Figure(
            label, "not measured in this run (needs --postgres)", goal="service_two_workers"
        )
    text = f"(c) {number(data.configs['c'].throughput)} done/s: {scaling.ratio:.2f}x"
    if bound:
        text += (
            f"; the CPU bound allows {bound.two_worker_ratio_max:.2f}x "
            f"({number(bound.worker_cpu_ms_per_batch)} ms of worker CPU and "
            f"{number(bound.api_cpu_ms_per_batch)} ms of API CPU per batch, "
            f"{bound.cores} cores)"
        )
    return Figure(
        label,
        text,
        peer=f"(d) one worker, two scenes: {number(data.configs['d'].throughput)} done/s",
        goal="service_two_workers",
        value=scaling.ratio,
    )
