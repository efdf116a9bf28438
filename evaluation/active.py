"""The autonomous construction protocol (section 3.4; the paper's Table 3) and the paired
acquisition experiment: closed-loop rollouts (`sim.rollout`) from an empty memory, scored on
coarse fixtures and fine objects, for PBD-AG's uncertainty-guided order and three other orders.

Each order is a parameter set of the same planner (equation (5)'s weights and its tie-break),
never a branch in the code:

- `pbdag`: 0.8 u_i + 0.2 Prox(i), Prox clipped at 8 m (the paper);
- `nearest`: Prox alone over 100 m (the parameter's bound), i.e. nearest fixture centre first;
- `fifo`: no score, ties by track id: the order fixtures were first hypothesised (the queue
  before equation (5));
- `random`: no score, ties by a hash of the run's seed and the track id.

Each row records the rollout's settings (`sim.rollout.RolloutSettings`: whether keyframes carry
fine detections, the simulated verifier and its error rate), every coarse-stage verdict, and
for each inspection the parent verification and equation (4)'s six terms at the plan that chose
the target.
"""

from __future__ import annotations

import dataclasses
import math
import multiprocessing
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import numpy as np

from core.params import deep_merge
from evaluation.metrics import fixture_scores, harmonic_f1, ratio
from evaluation.predictions import PredictedNode
from pbdag_client import Client
from sim.memories import InProcessMemory, Memory, Node, Ranked, ServiceMemory
from sim.rollout import Capture, RolloutResult, RolloutSettings, rollout
from sim.scenario import load_scenario

ORDERS: dict[str, Callable[[int], dict[str, Any]]] = {
    "pbdag": lambda seed: {},
    "nearest": lambda seed: {
        "planner": {"uncertainty_weight": 0.0, "proximity_weight": 1.0, "proximity_range_m": 100.0}
    },
    "fifo": lambda seed: {"planner": {"uncertainty_weight": 0.0, "proximity_weight": 0.0}},
    "random": lambda seed: {
        "planner": {"uncertainty_weight": 0.0, "proximity_weight": 0.0, "tie_break_seed": seed}
    },
}
COARSE_MATCH_M = 1.0  # same-class greedy matching within 1.0 m (section 3.4's protocol)
FINE_MATCH_M = 0.5  # a fine match also needs the correct fixture parent


@dataclass(frozen=True)
class FineScores:
    precision: float
    recall: float
    f1: float
    matched: int
    predicted: int
    truth: int
    center_error: float | None


@dataclass(frozen=True)
class TruthObject:
    object_id: str
    label: str
    center: tuple[float, float, float]
    parent: str  # the true supporting fixture


def fine_scores(
    truth: Sequence[TruthObject],
    predicted: Sequence[PredictedNode],
    fixture_map: Mapping[str, str],
    max_distance: float = FINE_MATCH_M,
) -> FineScores:
    """Same-class greedy matching of published objects to true fine objects.

    A pair needs equal labels, a centre distance below `max_distance`, and the object's
    published parent equal to the track the coarse matching assigned to its true fixture
    (`fixture_map`: truth fixture id -> track id); pairs are taken in ascending distance (ties
    by ids), each side at most once. P = matched / published objects, R = matched / truth.
    """
    objects = [node for node in predicted if node.kind == "object"]
    pairs = sorted(
        (math.dist(t.center, n.center), t.object_id, n.track_id)
        for t in truth
        for n in objects
        if t.label == n.label
        and math.dist(t.center, n.center) < max_distance
        and n.parent is not None
        and fixture_map.get(t.parent) == n.parent
    )
    used_truth: set[str] = set()
    used_tracks: set[str] = set()
    distances: list[float] = []
    for distance, object_id, track_id in pairs:
        if object_id in used_truth or track_id in used_tracks:
            continue
        used_truth.add(object_id)
        used_tracks.add(track_id)
        distances.append(distance)
    matched = len(distances)
    precision, recall = ratio(matched, len(objects)), ratio(matched, len(truth))
    return FineScores(
        precision,
        recall,
        harmonic_f1(precision, recall),
        matched,
        len(objects),
        len(truth),
        sum(distances) / matched if matched else None,
    )


def fine_shortfalls(result: RolloutResult) -> list[str]:
    """Why each true fine object is not matched, and what each unmatched published object is,
    from the memory's tracks (published or not) near the object."""
    predicted = nodes(result.final_graph)
    coarse = fixture_scores(result.truth_fixtures, predicted, COARSE_MATCH_M)
    inspected = {c.fixture_id for c in result.captures if c.completed}
    objects = [t for t in result.final_tracks if t.kind == "object"]
    matched_tracks: set[str] = set()
    lines: list[str] = []
    for truth in truth_objects(result):
        fixture = coarse.fixture_map.get(truth.parent)
        near = sorted(
            (math.dist(t.center, truth.center), t)
            for t in objects
            if math.dist(t.center, truth.center) < FINE_MATCH_M
        )
        good = [
            t
            for _, t in near
            if t.label == truth.label
            and t.state == "confirmed"
            and t.parent == fixture
            and fixture is not None
        ]
        if good:
            matched_tracks.add(good[0].track_id)
            continue
        where = (
            f"its fixture {truth.parent} not found"
            if fixture is None
            else f"its fixture {truth.parent} = {fixture} "
            + ("inspected" if fixture in inspected else "never inspected")
        )
        same = [t for _, t in near if t.label == truth.label]
        if same:
            t = same[0]
            if t.state != "confirmed":
                why = (
                    f"{t.track_id} {t.state} after {t.visible_misses} visibility-admissible misses"
                )
            else:
                why = f"{t.track_id} published on {t.parent}, not on {fixture}"
        elif near:
            t = near[0][1]
            why = f"seen as {t.label} ({t.track_id}, {t.state})"
        else:
            why = "never grounded within 0.5 m"
        lines.append(f"missed {truth.object_id} ({truth.label}): {why}; {where}")
    for node in predicted:
        if node.kind != "object" or node.track_id in matched_tracks:
            continue
        twin = [
            t
            for t in truth_objects(result)
            if t.label == node.label and math.dist(t.center, node.center) < FINE_MATCH_M
        ]
        kind = (
            f"a duplicate of {twin[0].object_id}"
            if twin
            else "no true object of its class within 0.5 m"
        )
        lines.append(f"false positive {node.track_id} ({node.label}, on {node.parent}): {kind}")
    return lines


def coarse_shortfalls(result: RolloutResult) -> list[str]:
    """Every true fixture the final graph missed and every published fixture no true one
    matched, with the nearest counterpart and the track's state (the coarse traces)."""
    predicted = [n for n in nodes(result.final_graph) if n.kind == "fixture"]
    coarse = fixture_scores(result.truth_fixtures, predicted, COARSE_MATCH_M)
    stands_for = {track: truth for truth, track in coarse.fixture_map.items()}
    tracks = {t.track_id: t for t in result.final_tracks if t.kind == "fixture"}
    lines: list[str] = []
    for truth in result.truth_fixtures:
        if truth.fixture_id in coarse.fixture_map:
            continue
        same = sorted(
            (math.dist(t.center[:2], truth.center[:2]), t.track_id, t.state)
            for t in tracks.values()
            if t.label == truth.label
        )
        near = (
            f"nearest {truth.label} track {same[0][1]} ({same[0][2]}) {same[0][0]:.2f} m away"
            if same
            else f"no {truth.label} track"
        )
        lines.append(f"missed fixture {truth.fixture_id} ({truth.label}): {near}")
    for node in predicted:
        if node.track_id in stands_for:
            continue
        nearest = min(
            result.truth_fixtures,
            key=lambda truth: math.dist(truth.center[:2], node.center[:2]),
            default=None,
        )
        where = ""
        if nearest is not None:
            twin = coarse.fixture_map.get(nearest.fixture_id)
            where = (
                f"; nearest true fixture {nearest.fixture_id} ({nearest.label}) "
                f"{math.dist(nearest.center[:2], node.center[:2]):.2f} m away"
                + (f", which {twin} stands for" if twin else ", unmatched")
            )
        centre = ", ".join(f"{c:.2f}" for c in node.center)
        lines.append(f"false positive fixture {node.track_id} ({node.label}) at ({centre}){where}")
    return lines


def nodes(graph: Sequence[Node]) -> list[PredictedNode]:
    return [PredictedNode(n.track_id, n.label, n.center, n.parent, n.kind) for n in graph]


def truth_objects(result: RolloutResult) -> list[TruthObject]:
    return [TruthObject(i, label, c, parent) for i, label, c, parent in result.truth_objects]


def score_graph(result: RolloutResult, graph: Sequence[Node]) -> dict[str, Any]:
    """Coarse and fine scores of one graph against the rollout's world."""
    predicted = nodes(graph)
    coarse = fixture_scores(result.truth_fixtures, predicted, COARSE_MATCH_M)
    fine = fine_scores(truth_objects(result), predicted, coarse.fixture_map)
    return {
        "coarse": {
            "precision": coarse.precision,
            "recall": coarse.recall,
            "f1": coarse.f1,
            "center_error": coarse.center_error,
            "matched": coarse.matched,
            "truth": len(result.truth_fixtures),
        },
        "fine": {
            "precision": fine.precision,
            "recall": fine.recall,
            "f1": fine.f1,
            "center_error": fine.center_error,
            "matched": fine.matched,
            "predicted": fine.predicted,
            "truth": fine.truth,
        },
    }


def _capture_line(capture: Capture) -> dict[str, Any]:
    """One capture for results.json: the fixture, outcome, view, parent verification, and the
    terms of equations (4) and (5) when the plan chose it."""
    target: Ranked | None = capture.target
    return {
        "fixture_id": capture.fixture_id,
        "outcome": capture.outcome.text,
        "view": list(capture.view),
        "fixture_verified": capture.fixture_verified,
        "uncertainty": None if target is None else target.uncertainty,
        "terms": None if target is None else dict(target.terms),
        "proximity": None if target is None else target.proximity,
        "score": None if target is None else target.score,
    }


def run_row(
    path: Path,
    seed: int,
    order: str,
    *,
    params: Mapping[str, Any] | None = None,
    client: Client | None = None,
    settings: RolloutSettings | None = None,
) -> tuple[dict[str, Any], RolloutResult]:
    """One rollout of one order on one world and seed, scored."""
    scenario = load_scenario(path)
    overrides = deep_merge(dict(params or {}), ORDERS[order](seed))
    name = f"active {scenario.name} s{seed} {order}"
    memory: Memory = (
        InProcessMemory(name, overrides)
        if client is None
        else ServiceMemory(client, name, overrides)
    )
    settings = settings or RolloutSettings()
    result = rollout(scenario, seed, memory, settings, order=order, via_service=client is not None)
    scores = score_graph(result, result.final_graph)
    budget_curve = [score_graph(result, c.graph_after)["fine"]["f1"] for c in result.captures]
    row = {
        "scenario": scenario.name,
        "scenario_file": str(path),
        "scenario_sha256": scenario.sha256,
        "seed": seed,
        "order": order,
        "via_service": client is not None,
        "settings": dataclasses.asdict(settings),
        **scores,
        "fine_f1_after_inspections": budget_curve,
        "inspections": [_capture_line(c) for c in result.captures],
        # Captures the memory refused (nothing recorded): no inspection, not in the budget.
        "refused_captures": [_capture_line(c) for c in result.refused],
        "verdicts": [
            {
                "track_id": v.track_id,
                "asked_label": v.asked_label,
                "verdict": v.verdict,
                "label": v.label,
                "truth_id": v.truth_id,
                "wrong": v.wrong,
                "outcome": v.outcome.text,
            }
            for v in result.verdicts
        ],
        "fine_shortfalls": fine_shortfalls(result),
        "coarse_shortfalls": coarse_shortfalls(result),
        "keyframes": len(result.keyframes),
        "path_length_m": result.path_length_m,
        "travel_at_keyframe": [k[2] for k in result.keyframes],
        "stop_reason": result.stop_reason,
        "unresolved_at_end": result.final_queue,
        "deferred_at_end": result.decisions[-1]["deferred"] if result.decisions else [],
        "planner_ms": {
            "median": float(np.median(result.plan_ms)) if result.plan_ms else None,
            "max": max(result.plan_ms) if result.plan_ms else None,
            "decisions": len(result.plan_ms),
        },
        "seconds": result.seconds,
    }
    return row, result


def _summary(row: Mapping[str, Any]) -> str:
    return (
        f"{row['scenario']} s{row['seed']} {row['order']}: coarse F1 {row['coarse']['f1']:.3f}, "
        f"fine F1 {row['fine']['f1']:.3f}, {row['keyframes']} keyframes, "
        f"{len(row['inspections'])} inspections, {row['seconds']:.0f} s"
    )


def run_rows(
    work: Sequence[tuple[Path, int, str]],
    *,
    params: Mapping[str, Any] | None = None,
    client: Client | None = None,
    settings: RolloutSettings | None = None,
    jobs: int = 1,
    progress: bool = True,
) -> list[tuple[dict[str, Any], RolloutResult]]:
    """`run_row` for every (world, seed, order), in that order; with `jobs` > 1 in that many
    worker processes (in-process memories only). One line per finished rollout."""
    if jobs <= 1 or len(work) <= 1:
        runs = []
        for path, seed, order in work:
            runs.append(run_row(path, seed, order, params=params, client=client, settings=settings))
            if progress:
                print(_summary(runs[-1][0]), flush=True)
        return runs
    if client is not None:
        raise ValueError("jobs: rollouts through a service run one at a time (use jobs=1)")
    done: dict[int, tuple[dict[str, Any], RolloutResult]] = {}
    # spawn, not fork: the parent may hold open3d's threads, which a fork would copy half-way.
    with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = {
            pool.submit(run_row, path, seed, order, params=params, settings=settings): index
            for index, (path, seed, order) in enumerate(work)
        }
        for future in as_completed(futures):
            done[futures[future]] = future.result()
            if progress:
                print(
                    f"[{len(done)}/{len(work)}] " + _summary(done[futures[future]][0]), flush=True
                )
    return [done[index] for index in range(len(work))]
