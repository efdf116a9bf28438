"""`python -m bench.summary` on result files written by the benchmarks' own code: each
benchmark's `main` runs with its measurements replaced by fixed figures (nothing is measured),
so the file has exactly the keys the benchmark writes and a renamed key breaks these tests."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench import perf_common
from bench.records import (
    DecideCondition,
    DecideResult,
    to_json,
)
from bench.summary import BENCHES, END_MARKER, START_MARKER, Row, main, rewrite_table, summary
from tests.bench.written_results import (
    write_all,
    write_fixture_step,
    write_plan,
    write_rollout,
    write_service,
    write_store,
)
from tests.eval_extra import require_eval_extra

require_eval_extra()  # the benchmarks import the simulator

README = Path(__file__).resolve().parents[2] / "docs" / "benchmarks.md"


@pytest.fixture
def results(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """bench/results/ redirected to a temporary folder."""
    folder = tmp_path / "results"
    monkeypatch.setattr(perf_common, "RESULTS_DIR", folder)
    return folder


# --- the tests -------------------------------------------------------------------------------


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
    main(["--results", str(results), "--doc", str(readme)])
    printed = capsys.readouterr().out
    for label in ("planner decision", "autonomous rollout", "store-versus", "service"):
        assert label in printed
    assert printed.count("not run") >= 2 * 10  # figure and verdict of the ten others
    saved = json.loads((results / "summary.json").read_text())["rows"]
    assert [row["benchmark"] for row in saved][:3] == ["render", "decide", "fixture_step"]
    plan = next(row for row in saved if row["benchmark"] == "plan")
    assert (plan["status"], plan["source"], plan["verdict"]) == ("run", "bench_plan.json", "met")
    assert not readme.exists()  # only --write-docs touches a README


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
    once = rewrite_table(text, rows)
    assert rewrite_table(once, rows) == once
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
