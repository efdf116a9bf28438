"""The end-to-end benchmark's figures: one configuration's measurements, the printed table, the
CPU bound of this machine, and the verdicts against the goals."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from bench.records import (
    AtRate,
    Capacity,
    CpuBound,
    Figures,
    Scaling,
    ServiceGoals,
    Sustained,
)

GOAL_RATE = 30.0  # frames per second of one robot
GOAL_P99_MS = 200.0
GOAL_SCALING = 1.8


def percentile(values: Sequence[float], q: float) -> float:
    return float(np.percentile(np.asarray(values), q)) if values else float("nan")


def table(rows: Sequence[Figures]) -> str:
    """The figures of every configuration, one line each."""
    header = (
        f"{'':6} {'offered/s':>9} {'done/s':>7} {'done':>9} {'POST p50/p99 ms':>16} "
        f"{'done p50/p99 ms':>16} {'backlog':>7} {'decide ms':>9} {'append ms':>9} "
        f"{'worker CPU s':>12} {'API CPU s':>9} {'machine cores':>13}"
    )
    lines = [header]
    for f in rows:
        worker_cpu = sum(v for k, v in f.cpu_seconds.items() if k.startswith("worker"))
        lines.append(
            f"{f.config:6} {f.offered:9.1f} {f.throughput:7.1f} {f'{f.done}/{f.batches}':>9} "
            f"{f'{f.post_p50_ms:.0f}/{f.post_p99_ms:.0f}':>16} "
            f"{f'{f.done_p50_ms:.0f}/{f.done_p99_ms:.0f}':>16} {f.backlog_at_end:7d} "
            f"{f.decide_mean_ms or float('nan'):9.1f} {f.append_mean_ms or float('nan'):9.1f} "
            f"{worker_cpu if f.workers else float('nan'):12.1f} "
            f"{f.cpu_seconds.get('api', float('nan')):9.1f} {f.machine_busy_cores:13.2f}"
        )
    return "\n".join(lines)


def sustained(figures: Figures) -> bool:
    """The worker kept up: every batch done, throughput near the offered rate, and at most one
    second of load still queued when the load stopped."""
    return (
        figures.done == figures.batches
        and figures.throughput >= 0.95 * figures.offered
        and figures.backlog_at_end <= max(2.0, figures.offered)
    )


def cpu_bound(rows: dict[str, Figures]) -> CpuBound | None:
    """What the CPU seconds per batch allow on this machine's cores, even if nothing else ran:
    one worker uses at most one core; API and workers together at most all of them (PostgreSQL's
    own share is not counted, so these are upper bounds)."""
    measured = [rows[key] for key in ("b", "c", "d") if key in rows and rows[key].done]
    if not measured:
        return None
    worker = sum(
        v for f in measured for k, v in f.cpu_seconds.items() if k.startswith("worker")
    ) / sum(f.done for f in measured)
    api = sum(f.cpu_seconds.get("api", 0.0) for f in measured) / sum(f.done for f in measured)
    cores = os.cpu_count() or 1
    one = min(1.0 / worker, cores / (worker + api))
    two = min(2.0 / worker, cores / (worker + api))
    return CpuBound(
        worker_cpu_ms_per_batch=round(1e3 * worker, 1),
        api_cpu_ms_per_batch=round(1e3 * api, 1),
        cores=cores,
        one_worker_max_per_s=round(one, 1),
        two_workers_max_per_s=round(two, 1),
        two_worker_ratio_max=round(two / one, 2),
        two_workers_max_over_measured_one=round(two / rows["d"].throughput, 2)
        if "d" in rows and rows["d"].throughput
        else None,
    )


def verdicts(rows: dict[str, Figures], rate: float, ramp: Sequence[float] = ()) -> ServiceGoals:
    """The issue's goals against what was measured."""
    sustains = None
    steps = [rows[key] for key in rows if "@" in key]
    if steps:
        kept = [f for f in steps if sustained(f)]
        best = max(kept, key=lambda f: f.offered) if kept else None
        sustains = Sustained(
            rates_tried=list(ramp),
            highest_sustained=None if best is None else best.offered,
            done_p50_ms=None if best is None else best.done_p50_ms,
            done_p99_ms=None if best is None else best.done_p99_ms,
        )
    at_rate = None
    one = rows.get("b") or rows.get("a")
    if one is not None:
        keeps_up = sustained(one)
        at_rate = AtRate(
            config=one.config,
            rate=rate,
            goal=f">= {GOAL_RATE:.0f}/s with done p99 < {GOAL_P99_MS:.0f} ms",
            keeps_up=keeps_up,
            done_p99_ms=one.done_p99_ms,
            met=keeps_up and rate >= GOAL_RATE and one.done_p99_ms < GOAL_P99_MS,
        )
    scaling = None
    if "c" in rows and "d" in rows and rows["d"].throughput:
        ratio = rows["c"].throughput / rows["d"].throughput
        scaling = Scaling(
            goal=f">= {GOAL_SCALING}x one worker (2 scenes each)",
            ratio=round(ratio, 2),
            one_worker_saturated=rows["d"].throughput < 0.95 * rows["d"].offered,
            met=ratio >= GOAL_SCALING,
        )
    capacity = None
    if "d" in rows:
        d = rows["d"]
        capacity = Capacity(
            value=d.throughput,
            bound="measured (the worker was saturated)"
            if d.throughput < 0.95 * d.offered
            else "at least (the worker kept up with the offered load)",
        )
    return ServiceGoals(sustains, at_rate, scaling, cpu_bound(rows), capacity)
