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


def rollout(
    world: str, order: str, coarse_f1: float, fine: tuple[float, float, float]
) -> dict[str, object]:
    precision, recall, f1 = fine
    return {
        "scenario": world,
        "seed": 7,
        "order": order,
        "coarse": {"f1": coarse_f1},
        "fine": {"precision": precision, "recall": recall, "f1": f1},
    }


def test_two_active_runs_compare_one_order_s_table_3_figures(tmp_path: Path) -> None:
    before = [
        rollout("a", "pbdag", 0.9, (0.8, 0.5, 0.6)),
        rollout("b", "pbdag", 0.8, (1, 0.5, 0.7)),
    ]
    after = [rollout("a", "pbdag", 0.9, (0.8, 0.7, 0.75)), rollout("b", "nearest", 0.1, (0, 0, 0))]
    after.append(rollout("b", "pbdag", 0.8, (1.0, 0.6, 0.8)))
    paths = []
    for name, runs in (("before", before), ("after", after)):
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps({"protocol": "active", "runs": runs}), encoding="utf-8")
        paths.append(str(path))
    out = tmp_path / "table.md"
    main([*paths, "--out", str(out)])  # the pbdag order by default
    text = out.read_text(encoding="utf-8")
    assert "| fine F1↑ | .650" in text and "| +.125" in text
    assert "| coarse F1↑ | .850" in text and "IDF1" not in text
    with pytest.raises(SystemExit, match="no run of 'nearest'"):  # an order only one ran
        main([*paths, "--method", "nearest"])
    dynamic = tmp_path / "dynamic.json"
    dynamic.write_text(json.dumps({"protocol": "dynamic", "runs": BEFORE}), encoding="utf-8")
    with pytest.raises(SystemExit, match="one file is of `pbdag eval active`"):
        main([paths[0], str(dynamic)])
