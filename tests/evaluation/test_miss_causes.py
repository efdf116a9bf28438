"""The causes of the misses the visibility gate counted (evaluation/miss_causes.py)."""

from __future__ import annotations

from collections import Counter

import pytest

from evaluation.miss_causes import main, miss_cause, table
from sim.truth import FrameTruth, TruthObject


def mug(pixels: int, present: bool = True, at: float = 0.0) -> TruthObject:
    return TruthObject("mug_1", "mug", (at, 0.0, 0.8), present, "table_1", pixels)


def frames(*objects: TruthObject) -> list[FrameTruth]:
    return [FrameTruth(i, (obj,)) for i, obj in enumerate(objects)]


@pytest.mark.parametrize(
    ("truths", "detected", "cause"),
    [
        (frames(mug(500), mug(500, present=False)), set(), "no object there"),
        (frames(mug(500), mug(500, at=0.7)), set(), "no object there"),  # moved 0.7 m away
        (frames(mug(0), mug(500)), {"mug_1"}, "detected"),
        (frames(mug(0), mug(0)), set(), "hidden"),
        (frames(mug(0), mug(90)), set(), "too small"),
        (frames(mug(90), mug(400)), set(), "in plain view"),
    ],
)
def test_each_miss_gets_the_cause_the_truth_shows(
    truths: list[FrameTruth], detected: set[str], cause: str
) -> None:
    assert miss_cause(truths, detected, 150, "mug", (0.0, 0.0, 0.8)) == cause
    # Another label standing there is not the object the track stood for.
    assert miss_cause(truths, detected, 150, "cup", (0.0, 0.0, 0.8)) == "no object there"


def test_the_table_gives_each_cause_its_share_of_misses_against_present_objects() -> None:
    counts = {"A": Counter({"no object there": 5, "hidden": 1, "in plain view": 3})}
    text = table(counts)
    assert "| A | 5 | 0 (0%) | 1 (25%) | 0 (0%) | 3 (75%) | 4 |" in text


def test_the_test_split_is_not_traced(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--split", "test"]) == 2
    assert "only dev worlds are traced" in capsys.readouterr().err
