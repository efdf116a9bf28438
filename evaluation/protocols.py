"""The paper's evaluation protocols on simulated streams: dynamic memory (Table 2), fixtures (Table 1)."""

from __future__ import annotations

import functools
import multiprocessing
import sys
import time
from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from tqdm import tqdm

from core.events import TrackUpdated, VisibleMiss
from evaluation.change_metrics import (
    EventRecall,
    class_false_absence,
    event_recall,
    false_absence,
    identity_before,
    lenient_event_recall,
)
from evaluation.evaluate import MethodRun, WireBatch, run_in_process, run_via_service
from evaluation.methods import OURS, Method
from evaluation.metrics import fixture_scores, global_assignment, identity_metrics, presence_f1
from evaluation.predictions import FramePrediction
from pbdag_client import Client
from sim.observability import empty_place_batches
from sim.scenario import load_scenario
from sim.stream import SimRun, frame_source, simulate, wire_batches
from sim.truth import FrameTruth

FRAMES_PER_BATCH = 2  # a batch is the update step t: two frames, as the robot posts them


@dataclass(frozen=True)
class Stream:
    """One simulated stream and its batches, shared by every method."""

    scenario_path: Path
    run: SimRun
    batches: tuple[WireBatch, ...]
    # Per scheduled change: for a disappearance, in how many batches of the latency bound its
    # empty place was in view (sim.observability.empty_place_batches); None otherwise.
    empty_place_batches: tuple[int | None, ...] = ()


def make_stream(
    path: Path,
    seed: int,
    frames: int | None = None,
    scenario_overrides: Mapping[str, Any] | None = None,
) -> Stream:
    """Simulate a scenario once per seed (optionally shortened, or with some of its fields
    overridden, such as the detector's); every method reads its batches."""
    run = simulate(load_scenario(path, scenario_overrides, frames=frames), seed)
    recording = frame_source(run.scenario).recording
    empty = empty_place_batches(
        run.scenario,
        run.events,
        run.observable_frames,
        run.frames[0].camera,
        [frame.pose for frame in run.frames],
        FRAMES_PER_BATCH,
        None if recording is None else recording.depth,
    )
    return Stream(path, run, tuple(wire_batches(run, FRAMES_PER_BATCH)), empty)


def acquired_truth(run: SimRun) -> list[FrameTruth]:
    """Ground truth a memory can be judged on: an object counts from its first detection on.

    No memory can hold an object its detector never reported, so an object is listed as not
    present until the frame of its first (true) detection, and after it disappears, as the
    simulator says. Detections of phantoms, people and false-positive blobs acquire nothing.
    """
    seen: set[str] = set()
    frames = []
    for sim_frame in run.frames:
        seen |= {d.object_id for d in sim_frame.detections if d.kind == "object"}
        objects = [
            replace(obj, present=obj.present and obj.object_id in seen)
            for obj in sim_frame.truth.objects
        ]
        frames.append(FrameTruth(sim_frame.truth.frame_index, tuple(objects)))
    return frames


def run_method(stream: Stream, method: Method, via_service: Client | None, bar: tqdm) -> MethodRun:
    """One method on one stream, advancing the progress bar per batch."""
    if via_service is not None and method.name == OURS:
        return run_via_service(method, stream.batches, via_service, on_batch=lambda: bar.update(1))
    return run_in_process(method, stream.batches, on_batch=lambda: bar.update(1))


def dynamic_scores(stream: Stream, result: MethodRun) -> dict[str, Any]:
    """Table 2's metrics of one method on one stream, with the traces that explain them."""
    run = stream.run
    truth = acquired_truth(run)
    predictions = list(result.predictions)[: len(truth)]
    identity = identity_metrics(truth, predictions)
    any_class = identity_metrics(truth, predictions, class_aware=False)
    assignment = global_assignment(truth, predictions)
    presence = presence_f1(truth, predictions, assignment)
    fixtures = fixture_scores(run.fixtures, result.final_nodes)
    changes, answers, fixture_map = run.events, result.events, fixtures.fixture_map
    timing = (run.observable_frames or None, FRAMES_PER_BATCH, run.scenario.event_latency_batches)
    recall = event_recall(changes, answers, assignment, fixture_map, truth, predictions, *timing)
    lenient = lenient_event_recall(changes, answers, assignment, fixture_map, len(truth), *timing)
    trace = _event_trace(
        result, assignment, truth, predictions, (recall, lenient), stream.empty_place_batches
    )
    absence = class_false_absence(truth, predictions)
    identity_absence = false_absence(truth, predictions, assignment)
    return {
        "idf1": identity.idf1,
        # Switches: the class-agnostic count is the headline (strict), the class-aware one
        # (`id_switches`) the lenient reading beside it; IDF1 stays class-aware.
        "id_switches": identity.id_switches,
        "idf1_any_class": any_class.idf1,
        "id_switches_any_class": any_class.id_switches,
        "id_presence_f1": presence.f1,
        # Event recall: `_identity` is the strict headline, the plain keys the lenient reading.
        "events_recalled_identity": recall.recalled,
        "events_recalled_identity_any_latency": recall.recalled_any,
        "events_recalled": lenient.recalled,
        "events_recalled_any_latency": lenient.recalled_any,
        "events_total": recall.total,
        "events_unobservable": recall.unobservable,
        "event_latency_bound_batches": recall.latency_bound_batches,
        **change_kinds(trace),
        "event_trace": trace,
        # False absence: identity-conditioned (`_identity`) is the strict headline, the
        # identity-agnostic one the lenient reading.
        "false_absence": absence.rate,
        "false_absent_checkpoints": absence.absent,
        "eligible_checkpoints": absence.eligible,
        "false_absence_by_object": absence.by_object,
        "false_absence_identity": identity_absence.rate,
        "false_absent_checkpoints_identity": identity_absence.absent,
        "eligible_checkpoints_identity": identity_absence.eligible,
        "false_absence_identity_by_object": identity_absence.by_object,
        "seconds": result.seconds,
    }


# A memory removes an object after this many visibility-admissible misses at the least
# (lifecycle.remove_min_visible_misses), one per batch: a removal is judged where it could be.
MIN_EMPTY_VIEWS = 3


def change_kinds(trace: Sequence[Mapping[str, Any]]) -> dict[str, int]:
    """Recall of two kinds of change, from the event trace, strictly read and within the bound:
    moves and transfers of an object the memory held just before (an identity to carry over)
    that were observable, reflected for that identity; and removals of objects the memory held
    just before whose empty place was in view in at least `MIN_EMPTY_VIEWS` batches of the
    bound."""
    carries = [
        row
        for row in trace
        if row["type"] in ("move", "transfer")
        and row["observable_frame"] is not None
        and row["identity_before"] is not None
    ]
    seen_empty = [
        row
        for row in trace
        if row["type"] == "disappear"
        and row["identity_before"] is not None
        and (row["empty_place_batches"] or 0) >= MIN_EMPTY_VIEWS
    ]
    return {
        "carries_total": len(carries),
        "carries_recalled_identity": sum(bool(row["recalled_identity"]) for row in carries),
        "removals_seen_empty": len(seen_empty),
        "removals_seen_empty_recalled": sum(bool(row["recalled_identity"]) for row in seen_empty),
    }


def _event_trace(
    result: MethodRun,
    assignment: Mapping[str, str],
    truth: Sequence[FrameTruth],
    predictions: Sequence[FramePrediction],
    readings: tuple[EventRecall, EventRecall],
    empty_batches: Sequence[int | None],
) -> list[dict[str, Any]]:
    """Per scheduled change: both readings (strict, lenient), the tracks they looked at, the
    track's story, and for a removal how many batches showed its empty place."""
    recall, lenient = readings
    empty = empty_batches or (None,) * len(recall.per_event)
    trace = []
    for outcome, loose, seen_empty in zip(recall.per_event, lenient.per_event, empty, strict=True):
        event = outcome.event
        track = assignment.get(event.object_id)
        before = (
            track
            if event.type == "appear"
            else identity_before(event, assignment, truth, predictions)
        )
        trace.append(
            {
                "frame": event.frame,
                "type": event.type,
                "object": event.object_id,
                "observable_frame": outcome.observable_frame,
                "empty_place_batches": seen_empty,
                "track": track,
                "identity_before": before,
                "recalled_frame_identity": outcome.recalled_frame,
                "latency_batches_identity": outcome.latency_batches,
                "recalled_identity": outcome.within_bound,
                "recalled_frame": loose.recalled_frame,
                "latency_batches": loose.latency_batches,
                "recalled": loose.within_bound,
                "track_story": _track_story(result, track, event.frame),
            }
        )
    return trace


def _track_story(result: MethodRun, track_id: str | None, since: int, limit: int = 16) -> list[str]:
    """The track's lifecycle from a frame on, as "frame:type" (visible misses as "miss").

    What a reader needs to see why a change was missed or late: was the track seen again,
    did it take misses, when was it removed or re-parented.
    """
    if track_id is None:
        return []
    story = []
    for event in result.events:
        if event.track_id != track_id or event.frame < since:
            continue
        if issubclass(event.kind, VisibleMiss):
            story.append(f"{event.frame}:miss")
        elif not issubclass(event.kind, TrackUpdated):
            story.append(f"{event.frame}:{event.kind.type}")
    return story[:limit]


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


def run_stream(
    protocol: str,
    path: Path,
    seed: int,
    methods: Sequence[Method],
    via_service: Client | None = None,
    progress: bool = True,
    frames: int | None = None,
    scenario_overrides: Mapping[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """Every method on one (scenario, seed) stream; one row of metrics per method."""
    score = dynamic_scores if protocol == "dynamic" else fixture_table_scores
    stream = make_stream(path, seed, frames, scenario_overrides)
    rows: list[dict[str, Any]] = []
    with tqdm(
        total=len(methods) * len(stream.batches),
        desc=f"{stream.run.scenario.name} seed {seed}",
        unit="batch",
        file=sys.stderr,
        disable=not progress,
    ) as bar:
        for method in methods:
            bar.set_postfix(method=method.name, refresh=False)
            head = {
                "scenario": stream.run.scenario.name,
                "scenario_file": str(path),
                "scenario_sha256": stream.run.scenario_sha256,
                "seed": seed,
                "method": method.name,
            }
            reason = method.unavailable_reason()
            if reason is not None:  # reported as not run, never replaced by another rule
                bar.update(len(stream.batches))
                rows.append({**head, "unavailable": reason})
                continue
            result = run_method(stream, method, via_service, bar)
            rows.append({**head, **score(stream, result)})
    return rows


def run_protocol(
    protocol: str,
    scenario_paths: Sequence[Path],
    seeds: Sequence[int],
    methods: Sequence[Method],
    via_service: Client | None = None,
    progress: bool = True,
    frames: int | None = None,
    jobs: int = 1,
    scenario_overrides: Mapping[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """Every method on every (scenario, seed) stream; one row of metrics per run.

    With `jobs` > 1 the streams run in that many worker processes (in-process methods only);
    each finished stream prints one line instead of a progress bar. Rows keep the order of
    (scenario, seed) whatever the order the streams finish in.
    """
    work = [(path, seed) for path in scenario_paths for seed in seeds]
    # One task for both paths, so what a stream is run with cannot differ between them.
    task = functools.partial(
        run_stream, protocol, methods=methods, frames=frames, scenario_overrides=scenario_overrides
    )
    if jobs <= 1 or len(work) <= 1:
        return [
            row
            for path, seed in work
            for row in task(path, seed, via_service=via_service, progress=progress)
        ]
    if via_service is not None:
        raise ValueError("jobs: streams through a service run one at a time (use jobs=1)")
    done: dict[tuple[Path, int], list[dict[str, Any]]] = {}
    # spawn, not fork: the parent may hold open3d's threads, which a fork would copy half-way.
    context = multiprocessing.get_context("spawn")
    started = time.monotonic()
    with ProcessPoolExecutor(max_workers=jobs, mp_context=context) as pool:
        futures = {
            pool.submit(task, path, seed, via_service=None, progress=False): (path, seed)
            for path, seed in work
        }
        for future in as_completed(futures):
            key = futures[future]
            done[key] = future.result()
            if progress:
                print(
                    f"[{len(done)}/{len(work)}] {key[0].stem} seed {key[1]} "
                    f"({time.monotonic() - started:.0f} s)",
                    file=sys.stderr,
                    flush=True,
                )
    return [row for key in work for row in done[key]]
