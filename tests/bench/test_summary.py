"""`python -m bench.summary` without any result (a service-only install runs these): every
benchmark reads "not run", and the README's table keeps its hand-written rows."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from bench.summary import (
    BENCHES,
    END_MARKER,
    START_MARKER,
    invocation,
    main,
    rewrite_table,
    split_row,
    summary,
)
from bench.summary_readers import GOALS, Goal

README = Path(__file__).resolve().parents[2] / "docs" / "benchmarks.md"


def test_missing_results_read_not_run(tmp_path: Path) -> None:
    rows = summary(tmp_path / "nothing-here")
    assert [row.benchmark for row in rows] == [bench.key for bench in BENCHES]
    assert {(row.status, row.verdict) for row in rows} == {("not run", "not run")}
    goals = {row.benchmark: row.goal for row in rows}
    assert goals["fixture_step"] == "median <= 10 ms per batch at 100k voxels"
    assert goals["store-raw"] == "<= 0.300 MB per frame"
    assert goals["blobs"] == "-"


def test_without_results_the_readme_is_left_as_it_is(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    readme = tmp_path / "README.md"
    readme.write_text(README.read_text())
    main(["--results", str(tmp_path / "results"), "--write-docs", "--doc", str(readme)])
    assert readme.read_text() == README.read_text()
    assert "unchanged:" in capsys.readouterr().out
    saved = json.loads((tmp_path / "results" / "summary.json").read_text())
    assert len(saved["rows"]) == len(BENCHES)


def test_every_benchmark_has_a_row_in_the_doc_table() -> None:
    text = README.read_text()
    block = text[text.index(START_MARKER) + len(START_MARKER) : text.index(END_MARKER)]
    commands = [split_row(line)[1] for line in block.strip().splitlines()[2:]]
    assert sorted(invocation(command) or "" for command in commands) == sorted(
        bench.invocation for bench in BENCHES
    )


def test_a_readme_without_markers_is_refused() -> None:
    with pytest.raises(ValueError, match="bench-table"):
        rewrite_table("# no table\n", summary(Path("/nonexistent")))


def test_goal_verdicts() -> None:
    below = Goal("< 10 ms", "<", 10.0, " ms")
    assert below.verdict(9.99) == "met"
    assert below.verdict(10.0) == "missed: at the bound, 10.0 ms"
    assert below.verdict(13.6) == "missed by 3.6 ms (36%)"
    at_least = GOALS["service_two_workers"]
    assert at_least.verdict(1.8) == "met"
    assert at_least.verdict(1.27) == "missed by 0.53x (29%)"
    assert GOALS["append"].verdict(20_000) == "missed: at the bound, 20,000 events/s"
