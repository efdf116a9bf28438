"""Runs over generated worlds: the split's files, the intervals over worlds, side-by-side jobs."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from evaluation.confidence import mean_interval, ratio_interval, spelled
from evaluation.world_intervals import interval_table, intervals
from service.cli import main
from sim.generator import split_seeds
from sim.scenario import load_scenario


def world_row(scenario: str, method: str, idf1: float, recalled: int) -> dict[str, Any]:
    return {
        "scenario": scenario,
        "seed": 7,
        "method": method,
        "idf1": idf1,
        "id_presence_f1": idf1,
        "id_switches": 1,
        "id_switches_any_class": 3,
        "events_recalled_identity": recalled - 1,
        "events_recalled": recalled,
        "events_total": 4,
        "false_absent_checkpoints": 0,
        "eligible_checkpoints": 10,
        "false_absent_checkpoints_identity": 1,
        "eligible_checkpoints_identity": 10,
        "carries_recalled_identity": 1,
        "carries_total": 2,
        "removals_seen_empty_recalled": 0,
        "removals_seen_empty": 1,
    }


def test_a_mean_over_worlds_lies_inside_its_interval_and_a_constant_has_a_point_interval() -> None:
    spread = mean_interval([0.6, 0.7, 0.8, 0.9, 1.0])
    assert spread.value == pytest.approx(0.8)
    assert spread.low < spread.value < spread.high
    assert spread.low >= 0.6 and spread.high <= 1.0
    constant = mean_interval([1.0, 1.0, 1.0])
    assert (constant.low, constant.value, constant.high) == (1.0, 1.0, 1.0)
    assert spelled(constant) == "1.000 [1.000, 1.000]"


def test_a_pooled_ratio_resamples_whole_worlds() -> None:
    # Worlds at 1/4, 4/4 and 3/12: pooled 8/20, not the mean of the world ratios (0.5) ...
    pooled = ratio_interval([1, 4, 3], [4, 4, 12])
    assert pooled.value == pytest.approx(8 / 20)
    # ... and every resample is a ratio of sums of whole worlds, so it stays within the
    # smallest and largest world ratio.
    assert 0.25 <= pooled.low <= pooled.value <= pooled.high <= 1.0


def test_the_interval_table_has_one_row_per_method_and_every_figure() -> None:
    rows = [
        world_row(f"gen-{k}", method, idf1, recalled)
        for k, (idf1, recalled) in enumerate([(0.9, 4), (0.8, 3), (0.7, 2)])
        for method in ("PBD-AG (extended)", "B")
    ]
    table = intervals("dynamic", rows)
    assert set(table) == {"PBD-AG (extended)", "B"}
    # The strict headline and the lenient reading beside it: events 6/12 and 9/12, switches
    # 3 (class-agnostic) and 1 (class-aware) per world, false absence 1/10 and 0/10.
    figures = table["PBD-AG (extended)"]
    assert figures["event_recall_identity"].value == pytest.approx(6 / 12)
    assert figures["event_recall"].value == pytest.approx(9 / 12)
    assert (figures["id_switches_any_class"].value, figures["id_switches"].value) == (3.0, 1.0)
    assert figures["false_absence_identity"].value == pytest.approx(0.1)
    assert figures["false_absence"].value == 0.0
    # Moves and transfers 3/6, removals where the place showed empty 0/3.
    assert figures["carry_recall"].value == pytest.approx(0.5)
    assert figures["removal_recall_seen_empty"].value == 0.0
    text = interval_table("dynamic", rows)
    assert "Over 3 worlds" in text
    assert "| PBD-AG (extended) | .800 [" in text
    assert (
        "| IDS↓ (per world) | IDS class-aware (lenient)↓ | Event R.↑ | Event R. lenient↑ |" in text
    )
    assert "Headlines read strictly" in text and "shown as -" not in text


def test_runs_written_before_the_strict_readings_show_a_dash_and_name_the_missing_keys() -> None:
    old = [world_row(f"gen-{k}", "PBD-AG (extended)", 0.8, 3) for k in range(2)]
    for row in old:
        del row["events_recalled_identity"], row["id_switches_any_class"]
    table = intervals("dynamic", old)
    assert "event_recall_identity" not in table["PBD-AG (extended)"]
    assert "id_switches_any_class" not in table["PBD-AG (extended)"]
    assert table["PBD-AG (extended)"]["event_recall"].value == pytest.approx(6 / 8)
    text = interval_table("dynamic", old)
    line = next(line for line in text.splitlines() if line.startswith("| PBD-AG (extended)"))
    cells = [cell.strip() for cell in line.strip("|").split("|")]
    assert cells[3] == "-" and cells[5] == "-"  # IDS and Event R., the strict headlines
    assert cells[4].startswith("1.000") and cells[6].startswith(".750")
    assert "`id_switches_any_class`, `events_recalled_identity`" in text


OVERRIDES = {"detector": {"appearance": {"distinctiveness": 0.3}}}


@pytest.fixture(scope="module")
def generated_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("generated")
    common = ["eval", "fixtures", "--generated", "2", "--split", "test", "--frames", "16"]
    common += ["--scenario-overrides", json.dumps(OVERRIDES)]
    assert (
        main(
            [*common, "--methods", "PBD-AG (extended)", "--quiet", "--jobs", "2", "--out", str(out)]
        )
        == 0
    )
    return out


def test_eval_on_generated_test_worlds_writes_their_files_and_intervals(
    generated_run: Path,
) -> None:
    results = json.loads((generated_run / "results.json").read_text())
    seeds = list(split_seeds("test", 2))
    assert results["generated_worlds"] == {"split": "test", "count": 2, "world_seeds": seeds}
    files = sorted((generated_run / "worlds").glob("*.yaml"))
    assert len(files) == 2
    assert {load_scenario(path).name for path in files} == {r["scenario"] for r in results["runs"]}
    f1 = results["intervals"]["PBD-AG (extended)"]["f1"]
    assert f1["worlds"] == 2 and f1["low"] <= f1["value"] <= f1["high"]
    assert "Generated worlds: the test split, 2 worlds." in (generated_run / "table.md").read_text()


def test_generated_and_given_worlds_exclude_each_other(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    given = ["--scenario", "x.yaml", "--generated", "2", "--out", str(tmp_path)]
    assert main(["eval", "dynamic", *given]) == 2
    assert "--generated and --scenario exclude each other" in capsys.readouterr().err
    assert main(["eval", "dynamic", "--generated", "0", "--out", str(tmp_path)]) == 2
    assert "--generated: 0 is not a positive number" in capsys.readouterr().err
    assert main(["eval", "dynamic", "--generated", "1", "--jobs", "0", "--out", str(tmp_path)]) == 2
    assert "--jobs: 0 is not a positive number" in capsys.readouterr().err
    assert not (tmp_path / "results.json").exists()


def test_scenario_overrides_reach_every_world_in_every_worker(generated_run: Path) -> None:
    results = json.loads((generated_run / "results.json").read_text())
    assert results["scenario_overrides"] == OVERRIDES
    for run in results["runs"]:  # each stream was simulated from the overridden scenario
        world = load_scenario(run["scenario_file"], OVERRIDES, frames=16)
        plain = load_scenario(run["scenario_file"], frames=16)
        assert run["scenario_sha256"] == world.sha256 != plain.sha256


def test_a_bad_scenario_override_is_refused_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    common = ["eval", "fixtures", "--generated", "1", "--frames", "8", "--quiet"]
    common += ["--methods", "PBD-AG (extended)", "--out", str(tmp_path)]
    bad = '{"detector": {"appearance": {"distinctiveness": 7}}}'
    assert main([*common, "--scenario-overrides", bad]) == 2
    assert "detector.appearance.distinctiveness" in capsys.readouterr().err
    assert not (tmp_path / "results.json").exists()
