"""Two runs of one method side by side (evaluation.compare)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from evaluation.compare import compared, main, paired_runs


def run(world: str, method: str, idf1: float, recalled: int, total: int) -> dict[str, object]:
    return {
        "scenario": world,
        "seed": 7,
        "method": method,
        "idf1": idf1,
        "events_recalled_identity": recalled,
        "events_total": total,
    }


BEFORE = [run("a", "M", 0.5, 1, 4), run("b", "M", 0.7, 2, 4), run("c", "other", 0.1, 0, 4)]
AFTER = [run("a", "M", 0.6, 3, 4), run("b", "M", 0.9, 2, 4), run("d", "M", 0.2, 0, 4)]


def test_only_the_method_s_runs_on_worlds_both_hold_are_paired() -> None:
    pairs = paired_runs(BEFORE, AFTER, "M")
    assert [(b["scenario"], a["scenario"]) for b, a in pairs] == [("a", "a"), ("b", "b")]


def test_each_figure_both_runs_hold_is_compared_with_its_paired_difference() -> None:
    table = {title: (b, a, d) for title, b, a, d in compared(paired_runs(BEFORE, AFTER, "M"))}
    assert set(table) == {"IDF1↑", "Event R.↑"}  # the others are in neither run
    before, after, difference = table["IDF1↑"]
    assert (before.value, after.value) == pytest.approx((0.6, 0.75))
    assert difference.value == pytest.approx(0.15) and difference.low > 0  # both worlds gain
    before, after, difference = table["Event R.↑"]
    assert (before.value, after.value, difference.value) == pytest.approx((3 / 8, 5 / 8, 2 / 8))


def test_the_command_names_a_method_with_no_paired_runs(tmp_path: Path) -> None:
    paths = []
    for name, runs in (("before", BEFORE), ("after", AFTER)):
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps({"runs": runs}), encoding="utf-8")
        paths.append(str(path))
    out = tmp_path / "table.md"
    main([*paths, "--method", "M", "--out", str(out)])
    assert "| IDF1↑ | .600" in out.read_text(encoding="utf-8")
    with pytest.raises(SystemExit, match="no run of 'nobody'"):
        main([*paths, "--method", "nobody"])


def test_a_file_that_is_not_a_results_json_is_one_line_naming_it(tmp_path: Path) -> None:
    other = tmp_path / "other.json"
    other.write_text(json.dumps({"worlds": 3}), encoding="utf-8")
    with pytest.raises(SystemExit, match=r"other\.json: not a results\.json .*no 'runs' key"):
        main([str(other), str(other)])
    with pytest.raises(SystemExit, match=r"missing\.json: not a results\.json"):
        main([str(tmp_path / "missing.json"), str(other)])
