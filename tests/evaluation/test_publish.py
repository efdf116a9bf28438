"""The published tables come from the runs' results.json, into the README's marked block only."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from evaluation.publish import END, START, main


def fixture_run(scenario: str, f1: float) -> dict[str, Any]:
    return {
        "scenario": scenario,
        "seed": 7,
        "method": "PBD-AG (extended)",
        "precision": 1.0,
        "recall": f1,
        "f1": f1,
        "center_error": 0.05,
        "count_mae": 0.0,
    }


def dynamic_run(scenario: str, strict: bool) -> dict[str, Any]:
    """A dynamic run's row; `strict`: written since the strict readings (else the keys an older
    results.json holds)."""
    row = {
        "scenario": scenario,
        "seed": 7,
        "method": "PBD-AG (extended)",
        "idf1": 0.8,
        "id_presence_f1": 0.8,
        "id_switches": 0,
        "events_recalled": 4,
        "events_total": 4,
        "false_absent_checkpoints": 0,
        "eligible_checkpoints": 10,
        "false_absent_checkpoints_identity": 1,
        "eligible_checkpoints_identity": 10,
    }
    if strict:
        row |= {"id_switches_any_class": 2, "events_recalled_identity": 1}
        row |= {
            "carries_recalled_identity": 1,
            "carries_total": 2,
            "removals_seen_empty_recalled": 1,
            "removals_seen_empty": 1,
        }
    return row


def write(folder: Path, runs: list[dict[str, Any]], worlds: dict[str, Any] | None) -> None:
    folder.mkdir(parents=True)
    document = {"code_version": "abc", "seeds": [7], "generated_worlds": worlds, "runs": runs}
    (folder / "results.json").write_text(json.dumps(document))
    (folder / "table.md").write_text("# Coarse fixtures\n\nthe run's own report\n")


def test_publish_writes_test_and_development_tables_between_the_markers(tmp_path: Path) -> None:
    worlds = {"split": "test", "count": 3, "world_seeds": [1, 2, 3]}
    test_runs = [fixture_run(f"gen-{k}", f1) for k, f1 in enumerate([0.6, 0.8, 1.0])]
    write(tmp_path / "test" / "fixtures", test_runs, worlds)
    write(tmp_path / "dev" / "fixtures", [fixture_run("office", 0.9)], None)
    readme = tmp_path / "README.md"
    readme.write_text(f"# Title\n\nbefore\n{START}\nold figures\n{END}\nafter\n")
    page = tmp_path / "RESULTS.md"
    args = ["--test", str(tmp_path / "test"), "--dev", str(tmp_path / "dev")]
    assert main([*args, "--readme", str(readme), "--page", str(page)]) == 0
    text = readme.read_text()
    assert text.startswith("# Title\n\nbefore\n") and text.endswith(f"{END}\nafter\n")
    assert "old figures" not in text
    assert "**Test split** (3 generated test-split worlds, stream seed 7, code abc)" in text
    assert "| PBD-AG (extended) | 1.000 [1.000, 1.000] | .800 [" in text
    assert "**Development** (1 shipped worlds" in text
    assert "Test split: not run yet." in text  # the dynamic and active runs are absent
    assert "- PBD-AG: .951 / .802 / .868 / .320 / .356" in text
    assert "the run's own report" in page.read_text()


def test_publish_refuses_without_runs_or_without_markers(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    readme = tmp_path / "README.md"
    readme.write_text("no markers\n")
    args = ["--test", str(tmp_path / "t"), "--dev", str(tmp_path / "d"), "--readme", str(readme)]
    assert main([*args, "--page", str(tmp_path / "R.md")]) == 2
    assert "no results.json" in capsys.readouterr().err
    write(tmp_path / "d" / "fixtures", [fixture_run("office", 0.9)], None)
    assert main([*args, "--page", str(tmp_path / "R.md")]) == 2
    assert "no <!-- results:start --> ... <!-- results:end --> block" in capsys.readouterr().err
    assert readme.read_text() == "no markers\n"


def test_publish_reads_the_strict_headlines_and_names_what_an_older_run_lacks(
    tmp_path: Path,
) -> None:
    worlds = {"split": "test", "count": 2, "world_seeds": [1, 2]}
    write(tmp_path / "test" / "dynamic", [dynamic_run(f"gen-{k}", True) for k in (0, 1)], worlds)
    write(tmp_path / "dev" / "dynamic", [dynamic_run("office", False)], None)
    readme = tmp_path / "README.md"
    readme.write_text(f"{START}\n{END}\n")
    args = ["--test", str(tmp_path / "test"), "--dev", str(tmp_path / "dev")]
    assert main([*args, "--readme", str(readme), "--page", str(tmp_path / "R.md")]) == 0
    text = readme.read_text()
    test_part, dev_part = text.split("**Development**")
    # Test split: IDS 2 (class-agnostic) before the class-aware 0, Event R. 1/4 before the
    # lenient 4/4, moves and transfers 1/2, removals where the place showed empty 1/1, False
    # abs. identity-conditioned .100 before the agnostic .000.
    assert (
        "| PBD-AG (extended) | .800 [.800, .800] | .800 [.800, .800] | 2.000 [2.000, 2.000] "
        "| .000 [.000, .000] | .250 [.250, .250] | 1.000 [1.000, 1.000] | .500 [.500, .500] "
        "| 1.000 [1.000, 1.000] | .100 [.100, .100] | .000 [.000, .000] |" in test_part
    )
    assert "shown as -" not in test_part
    # The older development run: its strict IDS and Event R. are dashes, and named.
    assert "| .800 [.800, .800] | - | .000 [.000, .000] | - | 1.000 [1.000, 1.000] |" in dev_part
    assert "`id_switches_any_class`, `events_recalled_identity`, `carries_recalled_identity`" in (
        dev_part
    )


def test_publish_gives_each_extension_s_effect_and_table3_the_paper_s_profile(
    tmp_path: Path,
) -> None:
    worlds = {"split": "test", "count": 3, "world_seeds": [1, 2, 3]}
    ours = [dynamic_run(f"gen-{k}", True) for k in range(3)]
    # Without the fragment rule IDF1 falls by .1 in every world; the other rows equal ours.
    without = [{**row, "method": "PBD-AG (extended) - fragment_rule", "idf1": 0.7} for row in ours]
    same = [{**row, "method": "PBD-AG (extended) - logodds_clamp"} for row in ours]
    write(tmp_path / "test" / "ablation", ours + without + same, worlds)
    active = {"coarse": {"f1": 0.9}, "fine": {"f1": 0.5}, "fine_f1_after_inspections": [0.3, 0.4]}
    rollout = {"scenario": "gen-0", "seed": 7, "order": "pbdag", **active}
    folder = tmp_path / "test" / "active"
    write(folder, [rollout, {**rollout, "order": "fifo"}], worlds)
    document = json.loads((folder / "results.json").read_text()) | {"budgets": [2]}
    (folder / "results.json").write_text(json.dumps(document))
    paper = tmp_path / "test" / "active-paper"
    write(paper, [{**rollout, "fine": {"f1": 0.25}}], worlds)
    (paper / "results.json").write_text(
        json.dumps(json.loads((paper / "results.json").read_text()) | {"budgets": [2]})
    )
    readme = tmp_path / "README.md"
    readme.write_text(f"{START}\n{END}\n")
    args = ["--test", str(tmp_path / "test"), "--dev", str(tmp_path / "dev")]
    assert main([*args, "--readme", str(readme), "--page", str(tmp_path / "R.md")]) == 0
    text = readme.read_text()
    fragment = next(line for line in text.splitlines() if line.startswith("| fragment_rule |"))
    assert "| +.100 [+.100, +.100] |" in fragment and fragment.endswith("| better IDF1 |")
    clamp = next(line for line in text.splitlines() if line.startswith("| logodds_clamp |"))
    assert clamp.endswith("| none measurable |")
    assert "| paper's gate vs none |" not in text and "Not in these runs: " in text
    assert "| pbdag | .900 [.900, .900] | .500 [.500, .500] |" in text
    assert "| pbdag, PBD-AG (paper) | .900 [.900, .900] | .250 [.250, .250] |" in text
    assert "Our protocol on our worlds" in text
