"""The report's table: mean ± sample std per method, event recall and false absence pooled;
the parameter set the methods ran on."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from evaluation.ablation import main as ablation_main
from evaluation.cli import loadable
from evaluation.report import write_report
from evaluation.tables import table
from service.cli import main
from sim import SCENARIOS_DIR


def run(
    method: str,
    idf1: float,
    recalled: int,
    absent: int,
    eligible: int,
    scenario: str = "s",
    latencies: tuple[int | None, ...] = (0, 2, None, 1),
    lenient_latencies: tuple[int | None, ...] | None = None,
) -> dict[str, Any]:
    """A run's row: the strict readings one event fewer, and twice the absences, than the
    lenient ones; `latencies` are the strict reading's, `lenient_latencies` (default the same)
    the lenient one's."""
    loose = latencies if lenient_latencies is None else lenient_latencies
    return {
        "scenario": scenario,
        "scenario_file": "s.yaml",
        "scenario_sha256": "0" * 64,
        "seed": 7,
        "method": method,
        "idf1": idf1,
        "id_presence_f1": idf1,
        "id_switches": 0,
        "id_switches_any_class": 1 if method == "A" else 2,
        "events_recalled_identity": recalled - 1,
        "events_recalled": recalled,
        "events_total": 4,
        "false_absent_checkpoints": absent,
        "eligible_checkpoints": eligible,
        "false_absence_by_object": {"mug": absent} if absent else {},
        "false_absent_checkpoints_identity": 2 * absent,
        "eligible_checkpoints_identity": eligible,
        "false_absence_identity_by_object": {"mug": 2 * absent} if absent else {},
        "event_latency_bound_batches": 10,
        "event_trace": [
            {
                "frame": 10 * k,
                "type": "move",
                "object": "mug",
                "observable_frame": 10 * k,
                "track": "t1",
                "identity_before": "t1",
                "recalled_frame_identity": None if latency is None else 10 * k + 2 * latency,
                "latency_batches_identity": latency,
                "recalled_identity": latency is not None,
                "recalled_frame": None if lenient is None else 10 * k + 2 * lenient,
                "latency_batches": lenient,
                "recalled": lenient is not None,
                "track_story": ["12:miss"],
            }
            for k, (latency, lenient) in enumerate(zip(latencies, loose, strict=True))
        ],
    }


def test_pooled_columns_and_sample_std(tmp_path: Path) -> None:
    rows = [run("A", 0.8, 3, 1, 10), run("A", 1.0, 4, 0, 30), run("B", 0.5, 1, 5, 0)]
    text = table("dynamic", rows)
    # A: idf1 mean .9, sample std .141; switches class-agnostic (the headline) 1 per run, the
    # class-aware (lenient) 0; events strict 2 + 3 = 5/8, lenient 7/8; false absence pooled,
    # identity-conditioned (the headline) 2/40 = .050, identity-agnostic (lenient) 1/40 = .025;
    # latencies 0, 2, 1, 0, 2, 1 -> median 1, max 2. B: 2 switches, nothing eligible.
    header = text.splitlines()[0]
    assert "| IDS↓ | IDS class-aware (lenient)↓ | Event R.↑ (≤10 b) | Event R. lenient↑ |" in header
    assert "| False abs.↓ | False abs. identity-agnostic (lenient)↓ |" in header
    assert (
        "| A | .900±.141 | .900±.141 | 1.000±.000 | .000±.000 | 5/8 | 7/8 | .050 | .025 | 1/2 |"
        in text
    )
    assert (
        "| B | .500±.000 | .500±.000 | 2.000±.000 | .000±.000 | 0/4 | 1/4 | .000 | .000 | 1/2 |"
        in text
    )
    assert text.splitlines()[1] == "|---|" + "---|" * 9
    written = write_report("dynamic", rows, tmp_path, [7])
    assert [p.name for p in written] == [
        "results.json",
        "table.md",
        "idf1_event_recall.png",
        "false_absence.png",
    ]
    assert all(p.stat().st_size > 0 for p in written)
    readings = json.loads((tmp_path / "results.json").read_text())["readings"]
    assert {name: (r["headline"], r["lenient"]) for name, r in readings.items()} == {
        "IDS": ("id_switches_any_class", "id_switches"),
        "Event R.": ("events_recalled_identity", "events_recalled"),
        "False abs.": ("false_absence_identity", "false_absence"),
    }
    assert "- Event R.: a move or transfer counts only when" in (tmp_path / "table.md").read_text()


def test_the_headline_is_the_hotel_suite_alone_and_shortfalls_carry_their_trace(
    tmp_path: Path,
) -> None:
    rows = [
        run("PBD-AG (extended)", 0.9, 3, 2, 10, scenario="hotel-suite"),
        run("PBD-AG (extended)", 0.5, 1, 0, 10, scenario="office", latencies=(None, None, 0, 0),
            lenient_latencies=(4, None, 0, 0)),
        {"scenario": "hotel-suite", "seed": 7, "method": "X", "unavailable": "no rule yet",
         "scenario_file": "h.yaml", "scenario_sha256": "0" * 64},
    ]  # fmt: skip
    write_report("dynamic", rows, tmp_path, [7])
    text = (tmp_path / "table.md").read_text()
    headline = text.split("## Table 2: hotel-suite alone, as the paper")[1].split("## Pooled")[0]
    assert "| PBD-AG (extended) | .900±.000 |" in headline and "| 2/4 | 3/4 |" in headline
    pooled_table = text.split("## Pooled over every scenario")[1].split("## Event latency")[0]
    assert "| PBD-AG (extended) | .700±.283 |" in pooled_table and "| 2/8 | 4/8 |" in pooled_table
    # Strict latencies pooled: 0, 2, 1 (hotel) and 0, 0 (office); three events never reflected.
    assert "| PBD-AG (extended) | 0 (x3), 1, 2 | 3 |" in text
    # The office's first move: missed strictly, counted leniently (after 4 batches); its second
    # missed by both.
    assert (
        "office seed 7: move of mug at frame 0 (observable from frame 0), track t1, identity "
        "before it t1, never reflected (the lenient reading counts it)" in text
    )
    assert "move of mug at frame 10 (observable from frame 10)" in text
    assert "never reflected (the lenient reading does not count it either)" in text
    assert "track from then on: 12:miss" in text
    assert (
        "hotel-suite seed 7: mug was present, acquired, and its PBD-AG (extended) track not published at 4 "
        "checkpoints" in text
    )
    assert "- X: not run (no rule yet)." in text


def test_eval_runs_every_method_on_one_given_parameter_set_and_records_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    common = ["eval", "dynamic", "--seeds", "7", "--frames", "20", "--quiet"]
    common += ["--scenario", str(SCENARIOS_DIR / "hotel-suite.yaml"), "--out", str(tmp_path)]
    bad = '{"visibility": {"min_expected_image_fraction": 2}}'
    assert main([*common, "--methods", "PBD-AG (extended)", "--params", bad]) == 2
    assert "params.visibility.min_expected_image_fraction" in capsys.readouterr().err
    assert not (tmp_path / "results.json").exists()
    good = {"visibility": {"min_expected_image_fraction": 0.002}}
    assert main([*common, "--methods", "PBD-AG (extended)", "--params", json.dumps(good)]) == 0
    assert json.loads((tmp_path / "results.json").read_text())["params"] == good
    assert '"min_expected_image_fraction": 0.002' in (tmp_path / "table.md").read_text()


def test_eval_ablation_writes_what_each_extension_adds(tmp_path: Path) -> None:
    common = ["eval", "ablation", "--seeds", "7", "17", "--frames", "40", "--quiet"]
    common += ["--scenario", str(SCENARIOS_DIR / "hotel-suite.yaml"), "--out", str(tmp_path)]
    methods = ["PBD-AG (extended)", "PBD-AG (extended) - logodds_clamp"]
    assert main([*common, "--methods", *methods]) == 0
    document = json.loads((tmp_path / "results.json").read_text())
    assert {r["method"] for r in document["runs"]} == set(methods)
    clamp = document["effects"]["logodds_clamp"]
    assert clamp["without"] == methods[1] and clamp["idf1"]["worlds"] == 2
    assert set(document["effects"]) == {"logodds_clamp"}  # only the pairs that ran
    table = (tmp_path / "table.md").read_text()
    assert "## What each extension adds" in table and "| logodds_clamp |" in table
    # A run written before the effects were: they are added from its rows, once.
    older = tmp_path / "older"
    older.mkdir()
    runs_only = {key: value for key, value in document.items() if key != "effects"}
    (older / "results.json").write_text(json.dumps(runs_only))
    (older / "table.md").write_text("# Dynamic memory\n")
    assert ablation_main([str(older)]) == 0
    assert json.loads((older / "results.json").read_text())["effects"] == document["effects"]
    assert ablation_main([str(older)]) == 2  # not twice


def test_a_shipped_world_whose_recording_is_absent_is_left_out_and_a_given_one_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good = tmp_path / "good.yaml"
    good.write_text((SCENARIOS_DIR / "hotel-suite.yaml").read_text())
    missing = tmp_path / "missing.yaml"
    text = (SCENARIOS_DIR / "kitchen-real.yaml").read_text()
    missing.write_text(text.replace("../shared/data/7scenes-kitchen", "no/such/recording"))
    # As the shipped defaults: left out with a note naming the world and the field.
    assert loadable(None, [str(good), str(missing)]) == [good]
    assert "leaving out missing.yaml: background.path: no folder" in capsys.readouterr().err
    # Named by the user: an error, nothing run.
    assert loadable([good, missing], []) is None
    assert "background.path: no folder" in capsys.readouterr().err
