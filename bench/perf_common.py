"""Shared pieces of the performance benchmarks: result files and synthetic event streams."""

from __future__ import annotations

import os
import platform
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from bench.records import to_json
from core.events import Event, ObjectAdded, ObjectObserved, VisibleMiss
from core.values import Observation

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

RESULTS_DIR = Path(__file__).resolve().parent / "results"
EMBEDDING_DIM = 64


def write_results(name: str, record: DataclassInstance) -> Path:
    """Save a benchmark's record (bench/records.py) as JSON under bench/results/ (git-ignored),
    with the machine it ran on."""
    path = RESULTS_DIR / f"{name}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(to_json(record, machine=platform.machine(), cpu_count=os.cpu_count()))
    print(f"wrote {path}")
    return path


def observation(rng: np.random.Generator, center: np.ndarray, frame_id: str) -> Observation:
    """One observation as decide writes it."""
    return Observation(
        frame_id=frame_id,
        label="mug",
        score=0.9,
        center=(float(center[0]), float(center[1]), float(center[2])),
        extent=(0.08, 0.08, 0.1),
        valid_pixels=int(rng.integers(200, 2000)),
        parent=None,
    )


def synthetic_events(n_events: int, n_tracks: int = 500, seed: int = 0) -> Iterator[Event]:
    """A realistic log: `n_tracks` adds, then observed updates (with 64-d appearance) and misses."""
    rng = np.random.default_rng(seed)
    centers = rng.uniform([0, 0, 0.5], [8, 6, 1.2], size=(n_tracks, 3))
    logodds = np.zeros(n_tracks)
    misses = np.zeros(n_tracks, dtype=int)
    batches = np.zeros(n_tracks, dtype=int)
    for index in range(n_events):
        frame_id = f"f{index:07d}"
        if index < n_tracks:
            logodds[index], batches[index] = 1.0, 1
            yield ObjectAdded(
                track_id=f"trk-{index + 1:06d}",
                state="tentative",
                frame_id=frame_id,
                observations=(observation(rng, centers[index], frame_id),),
                embedding_sum=tuple(float(v) for v in rng.normal(size=EMBEDDING_DIM)),
                embedding_count=1,
                timestamp=float(index),
                existence_logodds=1.0,
                p_exist=0.731,
                batches_observed=1,
                parent_evidence={},
            )
            continue
        track = int(rng.integers(n_tracks))
        track_id = f"trk-{track + 1:06d}"
        if rng.random() < 0.6:
            centers[track] += rng.normal(0, 0.01, size=3)
            logodds[track] = min(4.0, logodds[track] + 1.0)
            misses[track], batches[track] = 0, batches[track] + 1
            yield ObjectObserved(
                track_id=track_id,
                state="confirmed",
                frame_id=frame_id,
                observations=(observation(rng, centers[track], frame_id),),
                embedding_sum=tuple(float(v) for v in rng.normal(size=EMBEDDING_DIM)),
                embedding_count=1,
                timestamp=float(index),
                existence_logodds=float(logodds[track]),
                p_exist=float(1 / (1 + np.exp(-logodds[track]))),
                batches_observed=int(batches[track]),
                reacquired=False,
                parent_evidence={},
            )
        else:
            logodds[track] = max(-4.0, logodds[track] - 0.7)
            misses[track] += 1
            yield VisibleMiss(
                track_id=track_id,
                state="confirmed",
                frame_id=frame_id,
                samples_passed=int(rng.integers(2, 28)),
                samples_total=27,
                existence_logodds=float(logodds[track]),
                p_exist=float(1 / (1 + np.exp(-logodds[track]))),
                visible_misses=int(misses[track]),
            )
