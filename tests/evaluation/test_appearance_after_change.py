"""What appearance says about a carried object (evaluation/appearance_after_change.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from evaluation.appearance_after_change import Case, cases_of, main, margin


def entry(frame: int, kind: str, obj: str, before: str | None) -> dict[str, object]:
    return {"frame": frame, "type": kind, "object": obj, "identity_before": before}


def test_a_swap_pairs_each_object_with_its_partner_s_track_and_a_carry_stands_alone() -> None:
    trace = [
        entry(10, "transfer", "book_1", "trk-1"),
        entry(10, "transfer", "book_2", "trk-2"),
        entry(20, "transfer", "mug_1", "trk-3"),
        entry(30, "move", "cup_1", None),  # no identity before: nothing to keep
        entry(40, "disappear", "vase_1", "trk-4"),
    ]
    assert cases_of(trace) == [
        Case("book_1", 10, "trk-1", "trk-2"),
        Case("book_2", 10, "trk-2", "trk-1"),
        Case("mug_1", 20, "trk-3"),
    ]


def test_the_margin_is_own_minus_the_best_other_averaged_over_the_detections() -> None:
    own, other, third = np.eye(3)
    detections = [np.array([2.0, 0.0, 0.0]), np.array([1.0, 1.0, 0.0])]  # normalized inside
    # First: 1 - 0; second: 0.707 - 0.707 (the best other).
    assert margin(detections, own, [other, third]) == pytest.approx(0.5)
    assert margin([np.array([0.0, 0.0, 1.0])], own, [other, third]) == pytest.approx(-1.0)
    assert margin([], own, [other]) is None
    assert margin(detections, own, []) is None


def test_only_a_development_evaluation_is_traced(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    results = tmp_path / "results.json"
    results.write_text(json.dumps({"generated_worlds": {"split": "test"}, "runs": []}))
    assert main([str(results)]) == 2
    assert "only dev worlds are traced" in capsys.readouterr().err
    assert main([str(tmp_path / "missing.json")]) == 2
