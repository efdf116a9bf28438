"""The paper's evaluation protocols on simulated streams: dynamic memory (Table 2), fixtures (Table 1)."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import httpx
from tqdm import tqdm

from evaluation.evaluate import MethodRun, WireBatch, run_in_process, run_via_service
from evaluation.methods import Method
from evaluation.metrics import (
    event_recall,
    false_absence,
    fixture_scores,
    global_assignment,
    identity_metrics,
    presence_f1,
)
from sim.scenario import load_scenario
from sim.stream import SimRun, simulate, wire_batches
from sim.truth import FrameTruth

FRAMES_PER_BATCH = 2  # a batch is the update step t: two frames, as the robot posts them


@dataclass(frozen=True)
class Stream:
    """One simulated stream and its batches, shared by every method."""

    scenario_path: Path
    run: SimRun
    batches: tuple[WireBatch, ...]


def make_stream(path: Path, seed: int) -> Stream:
    """Simulate a scenario once per seed; every method then reads the same batches."""
    run = simulate(load_scenario(path), seed)
    return Stream(path, run, tuple(wire_batches(run, FRAMES_PER_BATCH)))


def acquired_truth(run: SimRun, min_visible_pixels: int) -> list[FrameTruth]:
    """Ground truth a memory can be judged on: an object counts from its first sighting on.

    An object the camera has not yet seen well enough to detect cannot be in any memory; it is
    listed as not present until then (and after it disappears, as the simulator says).
    """
    seen: set[str] = set()
    frames = []
    for sim_frame in run.frames:
        objects = []
        for obj in sim_frame.truth.objects:
            if obj.present and obj.visible_pixels >= min_visible_pixels:
                seen.add(obj.object_id)
            objects.append(replace(obj, present=obj.present and obj.object_id in seen))
        frames.append(FrameTruth(sim_frame.truth.frame_index, tuple(objects)))
    return frames


def run_method(
    stream: Stream, method: Method, via_service: httpx.Client | None, bar: tqdm
) -> MethodRun:
    """One method on one stream, advancing the progress bar per batch."""
    if via_service is not None and method.name == "PBD-AG":
        return run_via_service(method, stream.batches, via_service, on_batch=lambda: bar.update(1))
    return run_in_process(method, stream.batches, on_batch=lambda: bar.update(1))


def dynamic_scores(stream: Stream, result: MethodRun) -> dict[str, Any]:
    """Table 2's metrics of one method on one stream."""
    run = stream.run
    truth = acquired_truth(run, run.scenario.detector.min_visible_pixels)
    predictions = list(result.predictions)[: len(truth)]
    identity = identity_metrics(truth, predictions)
    assignment = global_assignment(truth, predictions)
    presence = presence_f1(truth, predictions, assignment)
    fixtures = fixture_scores(run.fixtures, result.final_nodes)
    recall = event_recall(run.events, result.events, assignment, fixtures.fixture_map, len(truth))
    absence = false_absence(truth, predictions, assignment)
    return {
        "idf1": identity.idf1,
        "id_switches": identity.id_switches,
        "id_presence_f1": presence.f1,
        "events_recalled": recall.recalled,
        "events_total": recall.total,
        "event_trace": [
            {
                "frame": e.frame,
                "type": e.type,
                "object": e.object_id,
                "recalled": ok,
                "track": assignment.get(e.object_id),
            }
            for e, ok in recall.per_event
        ],
        "false_absence": absence.rate,
        "false_absent_checkpoints": absence.absent,
        "eligible_checkpoints": absence.eligible,
        "seconds": result.seconds,
    }


def fixture_table_scores(stream: Stream, result: MethodRun) -> dict[str, Any]:
    """Table 1's metrics of one method on one stream."""
    scores = fixture_scores(stream.run.fixtures, result.final_nodes)
    return {
        "precision": scores.precision,
        "recall": scores.recall,
        "f1": scores.f1,
        "center_error": scores.center_error,
        "count_mae": scores.count_mae,
        "matched": scores.matched,
        "truth": len(stream.run.fixtures),
        "predicted": sum(node.kind == "fixture" for node in result.final_nodes),
        "seconds": result.seconds,
    }


def run_protocol(
    protocol: str,
    scenario_paths: Sequence[Path],
    seeds: Sequence[int],
    methods: Sequence[Method],
    via_service: httpx.Client | None = None,
    progress: bool = True,
) -> list[dict[str, Any]]:
    """Every method on every (scenario, seed) stream; one row of metrics per run."""
    score = dynamic_scores if protocol == "dynamic" else fixture_table_scores
    rows: list[dict[str, Any]] = []
    for path in scenario_paths:
        for seed in seeds:
            stream = make_stream(path, seed)
            label = f"{stream.run.scenario.name} seed {seed}"
            with tqdm(
                total=len(methods) * len(stream.batches),
                desc=label,
                unit="batch",
                file=sys.stderr,
                disable=not progress,
            ) as bar:
                for method in methods:
                    bar.set_postfix(method=method.name, refresh=False)
                    result = run_method(stream, method, via_service, bar)
                    rows.append(
                        {
                            "scenario": stream.run.scenario.name,
                            "scenario_file": str(path),
                            "scenario_sha256": stream.run.scenario_sha256,
                            "seed": seed,
                            "method": method.name,
                            **score(stream, result),
                        }
                    )
    return rows
