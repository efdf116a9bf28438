"""Each benchmark's `main` run with its measurements replaced by fixed figures (nothing is
measured), so that the result file it writes has exactly the keys the benchmark writes. The
benchmarks import the simulator: callers check the eval extra first.
"""

from __future__ import annotations

import json
import signal
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from bench.perf_common import synthetic_events
from bench.records import (
    EvidenceSizes,
    Figures,
    MemoryCase,
    RenderRun,
    SnapshotStorage,
)


def write_render(mp: pytest.MonkeyPatch, results: Path) -> None:
    from bench import bench_render

    def measure_fps(n_frames: int, nthreads: int) -> RenderRun:
        fps = 34.0 if nthreads == 1 else 50.0
        return RenderRun(
            frames=n_frames, render_ms_per_frame=20.0, detect_ms_per_frame=9.0, fps=fps
        )

    mp.setattr(bench_render, "RESULTS_PATH", results / "render.json")
    mp.setattr(bench_render, "measure_fps", measure_fps)
    bench_render.main()


def write_decide(mp: pytest.MonkeyPatch) -> None:
    from bench import bench_decide

    frame = SimpleNamespace(
        detections=(None,) * 20, intrinsics=SimpleNamespace(width=640, height=480)
    )
    live = SimpleNamespace(tracks=dict.fromkeys(range(500)), arrays=None, kind="live")

    def with_hypotheses(state: Any, count: int, retire: bool, seed: int) -> Any:
        kind = "retired" if retire else "stale"
        return SimpleNamespace(tracks=dict.fromkeys(range(500 + count)), arrays=None, kind=kind)

    cost = {"live": (13.0, 3.0), "retired": (14.0, 3.0), "stale": (20.0, 3.0)}  # ms
    mp.setattr(bench_decide, "twenty_objects_frame", lambda seed: (None, frame))
    mp.setattr(bench_decide, "state_with_500_tracks", lambda frame, seed: live)
    mp.setattr(bench_decide, "with_hypotheses", with_hypotheses)
    mp.setattr(bench_decide, "timed", lambda state, batch: (*cost[state.kind], 25))
    stages = {"fixture_batch": 2.0, "associate_batch": 4.0, "occupancy_evidence": 6.0}
    mp.setattr(bench_decide, "stage_breakdown", lambda state, batch, repeats: stages)
    bench_decide.main(["--repeats", "3"])


class Voxels:
    """A voxel map of a given size."""

    def __init__(self, size: int) -> None:
        self.size = size

    def __len__(self) -> int:
        return self.size

    def clusters(self, params: Any) -> None:
        """Built once before the timings (nothing to build here)."""


def write_fixture_step(mp: pytest.MonkeyPatch) -> None:
    from bench import bench_fixture_step

    fixture, thing = SimpleNamespace(kind="fixture"), SimpleNamespace(kind="object")
    batches = [
        SimpleNamespace(frames=(SimpleNamespace(detections=(d,)),))
        for d in (fixture, fixture, fixture, thing, fixture, fixture)
    ]
    suite = SimpleNamespace(
        voxels=Voxels(10_700), params=SimpleNamespace(fixtures=None), house=False
    )

    def house_of(state: Any, copies: int) -> Any:
        return SimpleNamespace(
            voxels=Voxels(len(state.voxels) * copies), params=state.params, house=True
        )

    def timed_ms(state: Any, batch: Any, incremental: bool) -> tuple[float, float]:
        wall = {(False, True): 6.9, (False, False): 18.6, (True, True): 7.3, (True, False): 173.0}
        return wall[state.house, incremental], wall[state.house, incremental] - 0.1

    mp.setattr(bench_fixture_step, "hotel_batches", lambda frames, seed: iter(batches))
    mp.setattr(bench_fixture_step, "SceneState", lambda: suite)
    mp.setattr(bench_fixture_step, "decide", lambda state, batch: [])
    mp.setattr(bench_fixture_step, "fold", lambda state, events: state)
    mp.setattr(bench_fixture_step, "house_of", house_of)
    mp.setattr(bench_fixture_step, "timed_ms", timed_ms)
    mp.setattr(bench_fixture_step, "fold_ms", lambda state, batch: (state, 1.1))
    bench_fixture_step.main(["--warmup-batches", "1", "--batches", "5", "--repeats", "1"])


def write_plan(mp: pytest.MonkeyPatch) -> None:
    from bench import bench_plan

    state = SimpleNamespace(
        params=SimpleNamespace(occupancy=None, planner=None),
        occupancy=SimpleNamespace(shape=(400, 400)),
        tracks=dict.fromkeys(range(12)),
    )
    evidence = EvidenceSizes(
        frames=24,
        bytes_per_batch_median=1700.0,
        bytes_per_batch_max=1900,
        evidence_ms_per_frame_median=3.5,
        evidence_ms_per_frame_median_raw_depth=2.9,
    )
    mp.setattr(bench_plan, "planning_state", lambda seed: state)
    mp.setattr(bench_plan, "MapGeometry", SimpleNamespace(of=lambda params: None))
    mp.setattr(bench_plan, "robot_poses", lambda state, count, seed: list(range(count)))
    mp.setattr(bench_plan, "Navigation", lambda *args: None)
    mp.setattr(bench_plan, "plan", lambda state, pose: SimpleNamespace(decision="inspect"))
    mp.setattr(bench_plan, "evidence_sizes", lambda frames: evidence)
    mp.setattr(sys, "argv", ["bench_plan", "--decisions", "5"])
    bench_plan.main()


def write_rollout(mp: pytest.MonkeyPatch) -> None:
    from bench import bench_rollout

    scenario = SimpleNamespace(name="floor", room_size=(20.0, 15.0, 2.6))
    result = SimpleNamespace(
        plan_ms=[9.9, 13.6, 14.2, 8.0],
        seconds=320.5,
        keyframes=[None] * 366,
        captures=[None] * 11,
        path_length_m=144.0,
        stop_reason="done",
    )
    mp.setattr(bench_rollout, "load_scenario", lambda path: scenario)
    mp.setattr(bench_rollout, "InProcessMemory", lambda name: None)
    mp.setattr(bench_rollout, "rollout", lambda scenario, seed, memory: result)
    bench_rollout.main([])


class Log:
    """An event log that answers at once (a little later for the replay)."""

    def __init__(self, engine: str) -> None:
        self.engine = engine

    def scene(self, scene_id: str) -> Any:
        return SimpleNamespace(head_seq=999_999)

    def load_state(self, scene_id: str, seq: int | None = None) -> Any:
        time.sleep(0.001)
        return SimpleNamespace(to_dict=dict)

    def replay(self, scene_id: str) -> Any:
        time.sleep(0.02)
        return SimpleNamespace(to_dict=dict)


@contextmanager
def two_engines(url: str | None) -> Iterator[list[tuple[str, str]]]:
    yield [("sqlite", "sqlite"), ("postgres", "postgres")]


APPEND_RATES = {"sqlite": 40_000.0, "postgres": 18_000.0}


VERSUS_RATES = {  # events/s by backend, appender and batch size
    ("sqlite", "ours"): {1: 1_000, 20: 4_000, 500: 26_500},
    ("sqlite", "eventsourcing"): {1: 2_800, 20: 11_200, 500: 33_100},
    ("sqlite", "eventsourcing per track"): {1: 1_000, 20: 5_000, 500: 24_000},
    ("postgres", "ours"): {1: 700, 20: 2_600, 500: 10_300},
    ("postgres", "eventsourcing"): {1: 600, 20: 2_100, 500: 4_700},
    ("postgres", "eventsourcing per track"): {1: 800, 20: 2_300, 500: 7_000},
}


def write_store(mp: pytest.MonkeyPatch) -> None:
    """append, as-of and versus."""
    from bench import bench_store

    class Ours:
        name = "ours"

        def __init__(self, engine: str) -> None:
            self.engine = engine

        def durability(self) -> str:
            return "journal_mode=wal synchronous=2"

        def close(self) -> None:
            """Nothing to release."""

    class Theirs(Ours):
        def __init__(self, engine: str, folder: Path, per_track: bool = False) -> None:
            self.engine = engine
            self.name = "eventsourcing per track" if per_track else "eventsourcing"

    mp.setattr(bench_store, "engines", two_engines)
    mp.setattr(bench_store, "EventLog", Log)
    mp.setattr(bench_store, "new_scene", lambda log: SimpleNamespace(id="scn-1"))
    mp.setattr(
        bench_store,
        "append_all",
        lambda log, scene_id, events, batch, *args, **kwargs: events / APPEND_RATES[log.engine],
    )
    mp.setattr(bench_store, "database_bytes", lambda engine: 2_698_000_000)
    mp.setattr(
        bench_store,
        "snapshot_storage",
        lambda engine: SnapshotStorage(snapshots=1_999, snapshot_bytes=1_322_000_000),
    )
    mp.setattr(bench_store, "version", lambda name: "9.5.6")
    mp.setattr(bench_store, "synthetic_events", lambda count: synthetic_events(40))
    mp.setattr(bench_store, "OurAppender", Ours)
    mp.setattr(bench_store, "TheirAppender", Theirs)
    mp.setattr(
        bench_store,
        "appended_per_second",
        lambda appender, stream, batch: float(VERSUS_RATES[appender.engine, appender.name][batch]),
    )
    bench_store.main(["append", "--events", "1000", "--postgres", "URL"])
    bench_store.main(["as-of", "--events", "1000000", "--queries", "5", "--postgres", "URL"])
    bench_store.main(["versus", "--rounds", "2", "--postgres", "URL"])


def write_raw(mp: pytest.MonkeyPatch) -> None:
    """The raw format on the wire batches of the mug scene (real encoding and decide)."""
    from bench import bench_store, service_load
    from tests import wire_scenes

    def render_templates(count: int) -> list[service_load.BodyTemplate]:
        body = wire_scenes.batch(service_load.BATCH_MARK, 0)
        body["frames"][0]["frame_id"] = service_load.FRAME_MARK
        body["frames"][0]["timestamp"] = service_load.TIME_MARK
        parts, keys = service_load.split_template(json.dumps(body, separators=(",", ":")))
        return [service_load.BodyTemplate(parts, keys, 1, 0)]

    mp.setattr(service_load, "render_templates", render_templates)
    bench_store.main(["raw", "--frames", "4"])


def write_blobs(mp: pytest.MonkeyPatch) -> None:
    from bench import bench_blobs

    names = ("sqlite+folder", "postgres+folder", "postgres+table", "postgres+table-pglz")
    put = {"sqlite+folder": 11.7, "postgres+folder": 15.7, "postgres+table": 11.8}
    get = {"postgres+table": 1.06}

    @contextmanager
    def backends(url: str, folder: Path) -> Iterator[list[Any]]:
        yield [bench_blobs.Backend(name, None, None) for name in names]  # type: ignore[arg-type]

    def one_round(backend: Any, blobs: list[bytes], samples: dict[str, list[float]]) -> None:
        samples["put_enqueue_ms"] += [put.get(backend.name, 9.8)] * len(blobs)
        samples["get_ms"] += [get.get(backend.name, 0.08)] * len(blobs)

    mp.setattr(
        bench_blobs, "canonical_bodies", lambda count, frames, compact: [b"x" * 320_000] * count
    )
    mp.setattr(bench_blobs, "backends", backends)
    mp.setattr(bench_blobs, "one_round", one_round)
    mp.setattr(bench_blobs, "stored_bytes", lambda backend, folder: 330_000 * 6)
    bench_blobs.main(["--postgres", "URL", "--rounds", "2", "--batches", "3"])


def write_memory(mp: pytest.MonkeyPatch) -> None:
    from bench import bench_memory

    def run_case(name: str, make: Any, root: Path, params: Any = None) -> MemoryCase:
        worker = 287.0 if name == "most fixture masks over noise depth" else 150.0
        return MemoryCase(
            body_mb=24.0,
            frames=1,
            detections=8,
            api_peak_mb=120.0,
            worker_peak_mb=worker,
            accept_seconds=1.0,
            work_seconds=2.0,
            batch_status="done",
        )

    mp.setattr(bench_memory, "run_case", run_case)
    bench_memory.main([])


def write_service(mp: pytest.MonkeyPatch, argv: list[str] | None = None) -> None:
    from bench import bench_service

    done_per_s = {"a": 10.7, "b": 10.4, "c": 13.7, "d": 8.2}

    def run_config(
        config: Any, templates: Any, *, rate: float, seconds: float, **_: Any
    ) -> Figures:
        if "@" in config.key:  # a ramp step: one worker keeps up to 8/s
            kept = rate <= 8
            throughput, backlog, p99 = (rate, 0, 180.0) if kept else (9.0, 40, 4_000.0)
        else:
            throughput = done_per_s[config.key]
            backlog, p99 = 300, 19_000.0
        batches = round(rate * seconds) * config.scenes
        return Figures(
            config.key,
            config.title,
            rate,
            config.scenes,
            config.workers,
            seconds,
            batches=batches,
            accepted=batches,
            done=batches,
            throughput=throughput,
            done_p99_ms=p99,
            backlog_at_end=backlog,
            cpu_seconds={"api": 0.028 * batches, "worker-1": 0.09 * batches},
        )

    template = SimpleNamespace(objects=20, fixtures=3, body=lambda batch_id, time: b"{}")
    mp.setattr(bench_service, "render_templates", lambda count: [template])
    mp.setattr(bench_service, "stage_breakdown", lambda templates, count, rate: {"decide": 35.0})
    mp.setattr(bench_service, "run_config", run_config)
    mp.setattr(signal, "signal", lambda *args: None)
    bench_service.main(
        argv
        or [
            "--postgres",
            "URL",
            "--ramp",
            "6,8,10,12",
            "--seconds",
            "2",
            "--name",
            "service-20261130-1",
        ]
    )


def write_stream(mp: pytest.MonkeyPatch) -> None:
    from bench import bench_stream

    frame = SimpleNamespace()
    mp.setattr(
        bench_stream,
        "hotel_batches",
        lambda frames, seed: [SimpleNamespace(frames=(frame, frame))] * 4,
    )
    mp.setattr(
        bench_stream,
        "with_extra_tracks",
        lambda state, count, seed: SimpleNamespace(tracks=dict.fromkeys(range(count)), extra=True),
    )
    mp.setattr(bench_stream, "SceneState", lambda: SimpleNamespace(tracks={}, extra=False))

    def step(state: Any, batch: Any) -> tuple[Any, float]:
        return state, 12.5 if state.extra else 8.0  # ms a frame

    mp.setattr(bench_stream, "step", step)
    bench_stream.main(["--frames", "8"])


def write_all(mp: pytest.MonkeyPatch, results: Path) -> None:
    write_render(mp, results)
    write_decide(mp)
    write_stream(mp)
    write_fixture_step(mp)
    write_plan(mp)
    write_rollout(mp)
    write_store(mp)
    write_raw(mp)
    write_blobs(mp)
    write_memory(mp)
    write_service(mp)
