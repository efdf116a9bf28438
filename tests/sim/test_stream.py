"""The stream's truth matches its renders, batches validate, and detector mistakes hit their rates."""

from __future__ import annotations

import base64
import io
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from api_schema import BatchIn
from sim.render import render
from sim.scenario import REPO_ROOT, load_scenario
from sim.spurious import FALSE_POSITIVE_PREFIX
from sim.stream import frame_source, load_run, save_run, simulate, wire_batches
from sim.timeline import Timeline

HOTEL = REPO_ROOT / "sim" / "scenarios" / "hotel-suite.yaml"
OFFICE = REPO_ROOT / "sim" / "scenarios" / "office.yaml"
# Every error mode of the detector at its kind value: the oracle detector of old.
ORACLE = {
    "recall": 1.0,
    "masks": {"boundary_leak_px": 0, "partial_rate": 0, "split_rate": 0, "support_bleed_rate": 0},
    "labels": {"flicker": 0, "confusion": 0},
    "false_positives_per_frame": 0.0,
    "phantoms": [],
}


def test_truth_visible_pixels_match_the_instance_map_and_exact_masks() -> None:
    # Perfect detector: every visible object is detected with its exact instance mask.
    scenario = load_scenario(OFFICE, {"detector": ORACLE}, frames=10)
    run = simulate(scenario, seed=3)
    timeline, source = Timeline(scenario), frame_source(scenario)
    checked = 0
    for frame in run.frames:
        world = timeline.world(frame.frame_index)
        view = render(world, source.camera, source.poses[frame.frame_index])
        counts = np.bincount(view.instance.ravel() + 1, minlength=len(world.objects) + 1)[1:]
        expected = {box.id: int(count) for box, count in zip(world.objects, counts, strict=True)}
        masks = {d.object_id: d.mask for d in frame.detections if d.kind == "object"}
        for truth in frame.truth.objects:
            assert truth.visible_pixels == expected.get(truth.object_id, 0)
            if truth.visible_pixels >= scenario.detector.min_visible_pixels:
                assert int(masks[truth.object_id].sum()) == truth.visible_pixels
                checked += 1
            else:
                assert truth.object_id not in masks
    assert checked >= 10  # the office shows several objects per frame


def test_wire_batches_validate_and_group_consecutive_frames() -> None:
    run = simulate(load_scenario(HOTEL, frames=5), seed=2)
    batches = wire_batches(run, frames_per_batch=2)
    assert [last for last, _ in batches] == [1, 3, 4]
    assert [batch["batch_id"] for _, batch in batches] == [
        "hotel-suite-s2-b00000",
        "hotel-suite-s2-b00001",
        "hotel-suite-s2-b00002",
    ]
    frame_ids = []
    for _, batch in batches:
        parsed = BatchIn.model_validate(batch)
        frame_ids += [frame.frame_id for frame in parsed.frames]
    assert frame_ids == [f"hotel-suite-s2-f{index:05d}" for index in range(5)]
    third = batches[1][1]["frames"][1]  # frame 3
    png = base64.b64decode(third["depth"]["data"])
    millimetres = np.asarray(Image.open(io.BytesIO(png)), dtype=np.float64)
    assert millimetres / 1000.0 == pytest.approx(run.frames[3].depth, abs=0.0006)
    assert len(third["detections"]) == len(run.frames[3].detections)
    with pytest.raises(ValueError):
        wire_batches(run, frames_per_batch=0)


def test_false_positives_and_label_confusion_appear_at_their_rates() -> None:
    noisy = {**ORACLE, "false_positives_per_frame": 3.0, "labels": {"flicker": 0, "confusion": 0.3}}
    scenario = load_scenario(OFFICE, {"detector": noisy}, frames=30)
    run = simulate(scenario, seed=5)
    false_positives, true_objects, confused = [], 0, 0
    for frame in run.frames:
        labels = {truth.object_id: truth.label for truth in frame.truth.objects}
        for detection in frame.detections:
            if detection.object_id.startswith(FALSE_POSITIVE_PREFIX):
                false_positives.append(detection)
            elif detection.kind == "object":
                true_objects += 1
                confused += detection.label != labels[detection.object_id]
    # Poisson(3) over 30 frames: mean 90, standard deviation 9.5.
    assert 60 <= len(false_positives) <= 120
    assert true_objects >= 60
    assert 0.15 <= confused / true_objects <= 0.45
    assert {d.label for d in false_positives} <= set(scenario.object_labels)
    areas = np.array([d.mask.sum() for d in false_positives])
    assert areas.max() <= 850 and np.median(areas) >= 200
    assert all(d.embedding is not None and d.embedding.shape == (64,) for d in false_positives)


def test_a_saved_run_loads_back_equal(tmp_path: Path) -> None:
    run = simulate(load_scenario(HOTEL, frames=4), seed=1)
    save_run(run, tmp_path / "cache")
    loaded = load_run(tmp_path / "cache")
    assert loaded.scenario == run.scenario and loaded.scenario_sha256 == run.scenario_sha256
    assert loaded.fixtures == run.fixtures and loaded.events == run.events
    assert loaded.observable_frames == run.observable_frames
    for first, second in zip(run.frames, loaded.frames, strict=True):
        assert np.array_equal(first.depth, second.depth) and np.array_equal(first.pose, second.pose)
        assert first.truth == second.truth and first.camera == second.camera
        assert len(first.detections) == len(second.detections)
        for left, right in zip(first.detections, second.detections, strict=True):
            assert np.array_equal(left.mask, right.mask) and left.label == right.label
            assert left.class_scores == right.class_scores
            assert (left.embedding is None) == (right.embedding is None)
            if left.embedding is not None:
                assert right.embedding is not None
                assert np.array_equal(left.embedding, right.embedding)
