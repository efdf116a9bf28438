"""The report's table: mean ± sample std per method, event recall and false absence pooled."""

from __future__ import annotations

from evaluation.report import table, write_report


def run(method, idf1, recalled, absent, eligible):
    return {
        "scenario": "s",
        "scenario_file": "s.yaml",
        "scenario_sha256": "0" * 64,
        "seed": 7,
        "method": method,
        "idf1": idf1,
        "id_presence_f1": idf1,
        "id_switches": 0,
        "events_recalled": recalled,
        "events_total": 4,
        "false_absent_checkpoints": absent,
        "eligible_checkpoints": eligible,
    }


def test_pooled_columns_and_sample_std(tmp_path):
    rows = [run("A", 0.8, 3, 1, 10), run("A", 1.0, 4, 0, 30), run("B", 0.5, 1, 5, 0)]
    text = table("dynamic", rows)
    # A: idf1 mean .9, sample std .141; events 7/8; false absence pooled 1/40 = .025. B: nothing eligible.
    assert "| A | .900±.141 | .900±.141 | .000±.000 | 7/8 | .025 |" in text
    assert "| B | .500±.000 | .500±.000 | .000±.000 | 1/4 | .000 |" in text
    written = write_report("dynamic", rows, tmp_path, [7])
    assert [p.name for p in written] == [
        "results.json",
        "table.md",
        "idf1_event_recall.png",
        "false_absence.png",
    ]
    assert all(p.stat().st_size > 0 for p in written)
