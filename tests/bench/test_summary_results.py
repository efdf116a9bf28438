"""`python -m bench.summary` on result files written by the benchmarks' own code: each
benchmark's `main` runs with its measurements replaced by fixed figures (nothing is measured),
so the file has exactly the keys the benchmark writes and a renamed key breaks these tests."""

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

from bench import perf_common
from bench.perf_common import synthetic_events
from bench.records import (
    DecideCondition,
    DecideResult,
    EvidenceSizes,
    Figures,
    MemoryCase,
    RenderRun,
    SnapshotStorage,
    to_json,
)
from bench.summary import BENCHES, END_MARKER, START_MARKER, Row, main, rewrite_readme, summary
from tests.eval_extra import require_eval_extra

require_eval_extra()  # the benchmarks import the simulator

README = Path(__file__).resolve().parents[2] / "README.md"


@pytest.fixture
def results(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """bench/results/ redirected to a temporary folder."""
    folder = tmp_path / "results"
    monkeypatch.setattr(perf_common, "RESULTS_DIR", folder)
    return folder


# --- each benchmark's main, its measurements replaced ----------------------------------------


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

    def run_case(name: str, make: Any, root: Path) -> MemoryCase:
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


# --- the tests -------------------------------------------------------------------------------


def write_all(mp: pytest.MonkeyPatch, results: Path) -> None:
    write_render(mp, results)
    write_decide(mp)
    write_fixture_step(mp)
    write_plan(mp)
    write_rollout(mp)
    write_store(mp)
    write_raw(mp)
    write_blobs(mp)
    write_memory(mp)
    write_service(mp)


def by_label(rows: list[Row]) -> dict[str, Row]:
    return {row.label: row for row in rows}


def test_every_benchmark_has_its_figures_goals_peers_and_verdicts(
    results: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    write_all(monkeypatch, results)
    rows = summary(results)
    assert {row.benchmark for row in rows} == {bench.key for bench in BENCHES}
    assert all(row.status == "run" for row in rows), [r for r in rows if r.status != "run"]
    got = by_label(rows)

    render = got["render + detect, 640x480"]
    assert (render.figure, render.goal, render.verdict) == (
        "34.0 frames/s on one thread, 50.0 on all",
        ">= 30 frames/s",
        "met",
    )
    decide = got["decide + evolve, 20 masks, 500 live tracks"]
    assert decide.goal == "< 10 ms" and decide.verdict == "missed by 6.0 ms (60%)"
    assert decide.met is False
    hypotheses = got["decide + evolve with retired or stale hypotheses in memory"]
    assert hypotheses.verdict == "met" and "1.44x" in hypotheses.figure
    assert hypotheses.peer == "500 live tracks alone: 16.0 ms"

    house = got["fixture step per batch, house (107,000-107,000 voxels)"]
    assert house.figure.startswith("median 7.3 ms") and house.verdict == "met"
    assert house.peer == "full re-clustering 173 ms (23.7x)"
    assert house.goal == "median <= 10 ms per batch at 100k voxels"
    suite = got["fixture step per batch, suite (10,700-10,700 voxels)"]
    assert suite.peer == "full re-clustering 18.6 ms (2.7x)" and suite.verdict == "-"

    assert got["planner decision, 20 m x 20 m at 5 cm"].verdict == "met"
    rollout = got["autonomous rollout, floor (300 m², seed 7)"]
    assert rollout.verdict == "missed by 20.5 s (7%)" and rollout.goal == "< 5 min"
    assert got["planner per decision during the rollout"].verdict == "met"

    assert got["append, SQLite, batches of 500"].verdict == "met"
    assert got["append, PostgreSQL, batches of 500"].verdict == "missed by 2,000 events/s (10%)"

    as_of = got["as_of, SQLite, 999,999 events"]
    assert as_of.verdict == "met" and as_of.peer.startswith("full replay ")
    assert "1,322 bytes per event" in as_of.figure

    versus = got["append vs eventsourcing 9.5.6, SQLite, batches of 1"]
    assert versus.figure == "ours 1,000 events/s: 0.36 (per track 1.00)"
    assert versus.peer == "2,800/s one aggregate, 1,000/s one per track"
    assert versus.verdict == "missed by 0.64 (64%)"
    assert got["append vs eventsourcing 9.5.6, PostgreSQL, batches of 500"].verdict == "met"

    raw = got["raw batch kept per 640x480 frame"]
    assert raw.peer.startswith("JSON with base64 depth") and raw.verdict == "met"

    blobs = got["raw batch storage, PostgreSQL table, compact-1-frame (0.32 MB)"]
    assert blobs.figure == "put + enqueue 11.8 ms, get 1.06 ms"
    assert blobs.peer == "folder 15.7 / 0.08 ms (table/folder 0.75 / 13.2)"
    assert (blobs.goal, blobs.verdict) == ("-", "-")

    memory = got["peak memory of the largest accepted batches"]
    assert memory.figure.startswith("at most 287 MB") and memory.verdict == "met"

    one = got["service end to end, one worker, one scene"]
    assert one.figure == ("(b) at 30/s: 10.4 done/s, p99 19,000 ms; sustains 8/s, p99 180 ms")
    assert one.verdict == "missed: 8/s (73% short), p99 19,000 ms at 30/s"
    two = got["service end to end, two workers on two scenes"]
    assert two.figure.startswith("(c) 13.7 done/s: 1.67x; the CPU bound allows")
    assert two.peer == "(d) one worker, two scenes: 8.2 done/s"
    assert two.verdict == "missed by 0.13x (7%)"


def test_the_table_prints_every_row_and_summary_json_holds_them(
    results: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    write_plan(monkeypatch)
    write_rollout(monkeypatch)
    readme = results.parent / "README.md"
    main(["--results", str(results), "--readme", str(readme)])
    printed = capsys.readouterr().out
    for label in ("planner decision", "autonomous rollout", "store-versus", "service"):
        assert label in printed
    assert printed.count("not run") >= 2 * 10  # figure and verdict of the ten others
    saved = json.loads((results / "summary.json").read_text())["rows"]
    assert [row["benchmark"] for row in saved][:3] == ["render", "decide", "fixture_step"]
    plan = next(row for row in saved if row["benchmark"] == "plan")
    assert (plan["status"], plan["source"], plan["verdict"]) == ("run", "bench_plan.json", "met")
    assert not readme.exists()  # only --write-readme touches a README


def test_a_file_of_another_shape_is_unreadable_not_an_error(results: Path) -> None:
    results.mkdir()
    (results / "decide.json").write_text(json.dumps({"conditions": {"renamed": {}}}))
    (results / "memory.json").write_text("{not json")
    rows = {row.benchmark: row for row in summary(results)}
    assert rows["decide"].status == "unreadable"
    assert rows["decide"].verdict.startswith("unreadable: not a DecideResult (")
    assert "masks: Field required" in rows["decide"].verdict and "\n" not in rows["decide"].verdict
    assert rows["memory"].status == "unreadable" and "Invalid JSON" in rows["memory"].verdict
    assert rows["plan"].status == "not run"


def test_a_record_without_the_figure_its_goal_reads_is_unreadable(results: Path) -> None:
    row = DecideCondition(25, 20, 9.0, 2.0, 11.0, 12.0, 1.0)
    renamed = DecideResult(20, (640, 480), 3, 10.0, 1.5, {"renamed": row})
    results.mkdir()
    (results / "decide.json").write_text(to_json(renamed))
    (decide,) = [row for row in summary(results) if row.benchmark == "decide"]
    assert decide.status == "unreadable" and "KeyError '500 live tracks'" in decide.verdict


def test_the_newest_service_run_is_read(results: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    write_service(monkeypatch)
    older = results / "service-20200101-000000.json"
    older.write_text(json.dumps({"configs": {}, "goals": {}}))
    newest = results / "service-20261130-1.json"
    newest.touch()  # written after the older one
    rows = [row for row in summary(results) if row.benchmark == "service"]
    assert {row.source for row in rows} == {newest.name}
    assert rows[1].verdict == "missed by 0.13x (7%)"


def test_readme_regeneration_replaces_only_the_rows_run_and_is_idempotent(
    results: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    text = README.read_text()
    write_fixture_step(monkeypatch)
    write_store(monkeypatch)
    rows = summary(results)
    once = rewrite_readme(text, rows)
    assert rewrite_readme(once, rows) == once
    start, end = once.index(START_MARKER), once.index(END_MARKER)
    assert once[:start] == text[: text.index(START_MARKER)]
    assert once[end:] == text[text.index(END_MARKER) :]
    old = text[text.index(START_MARKER) : text.index(END_MARKER)].splitlines()
    new = once[start:end].splitlines()
    assert len(new) == len(old)  # every row kept, none added: each benchmark has its row
    changed = [(a, b) for a, b in zip(old, new, strict=True) if a != b]
    commands = sorted(b.split(" | ")[1] for _a, b in changed)
    assert commands == [
        "`python -m bench.bench_fixture_step`",
        "`python -m bench.bench_store append --postgres URL`",
        "`python -m bench.bench_store as-of --postgres URL`",
        "`python -m bench.bench_store versus --postgres URL`",
    ]
    for before, after in changed:  # the benchmark and command cells kept
        assert before.split(" | ")[:2] == after.split(" | ")[:2]
    fixture = next(b for _a, b in changed if "bench_fixture_step" in b)
    assert "full re-clustering 173 ms (23.7x)" in fixture
    assert "(goal median <= 10 ms per batch at 100k voxels: met)" in fixture
    assert "raw batch kept per 640x480 frame (png16 depth" in once  # not run: kept as written


def test_a_service_run_without_postgresql_judges_what_it_measured(
    results: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    write_service(monkeypatch, ["--seconds", "2", "--name", "service-sqlite"])
    one, two = (row for row in summary(results) if row.benchmark == "service")
    assert one.figure == "(a) at 30/s: 10.7 done/s, p99 19,000 ms"
    assert one.verdict == "missed: 10.7/s (64% short), p99 19,000 ms at 30/s"
    assert two.figure == "not measured in this run (needs --postgres)"
    assert (two.goal, two.verdict) == (">= 1.8x one worker (2 scenes each)", "not measured")
