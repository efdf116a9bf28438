"""Benchmark: the memory's cost per frame on a realistic stream, stage by stage.

    python -m bench.bench_stream [--frames 300] [--seed 7] [--extra-tracks 500]

The hotel-suite stream (its realistic detector) as the worker sees it: each batch of two frames
decoded, then decided and folded, the occupancy evidence included. Two states take every batch,
interleaved: the stream's own, and the same one with `--extra-tracks` more objects in memory,
published, out of the suite (they cost what tracks in play cost, not tracks in view). A frame's
cost is its batch's decide + fold over the batch's frames. The stages are `decide`'s
(`bench_decide.STAGES`), on the stream's own state. Prints the figures and writes
bench/results/stream.json.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from bench.bench_decide import LABELS, STAGES, sighted, stage_clock
from bench.bench_fixture_step import hotel_batches
from bench.perf_common import write_results
from bench.records import StreamCondition, StreamResult
from core.decide import decide
from core.events import Event, TrackConfirmed
from core.evolve import fold
from core.observation import Batch
from core.state import SceneState

OWN = "the stream's own tracks"
GOAL_MS = 10.0  # per frame, median (issue: "a few milliseconds a frame")


def with_extra_tracks(state: SceneState, count: int, seed: int) -> SceneState:
    """`count` confirmed objects 60-90 m from the suite: in play, never in view."""
    rng = np.random.default_rng(seed)
    events: list[Event] = []
    for k in range(count):
        track_id = f"trk-{900_000 + k:06d}"
        center = rng.uniform([60.0, 60.0, 0.5], [90.0, 90.0, 1.0])
        events.append(sighted(track_id, LABELS[k % len(LABELS)], center, rng))
        events.append(
            TrackConfirmed(
                track_id=track_id,
                state="confirmed",
                frame_id="x",
                p_exist=0.8,
                center=(float(center[0]), float(center[1]), float(center[2])),
                batches_observed=2,
            )
        )
    return fold(state, events)


def step(state: SceneState, batch: Batch) -> tuple[SceneState, float]:
    """The state after the batch, and decide + fold's cost per frame of it (ms)."""
    started = time.perf_counter()
    state = fold(state, decide(state, batch))
    return state, 1000 * (time.perf_counter() - started) / len(batch.frames)


def main(argv: list[str] | None = None) -> None:
    """Per-frame cost on the stream, with and without the extra tracks; the stages' medians."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--extra-tracks", type=int, default=500)
    args = parser.parse_args(argv)
    extra = f"plus {args.extra_tracks} tracks in play"
    states = {OWN: SceneState(), extra: with_extra_tracks(SceneState(), args.extra_tracks, 1)}
    per_frame: dict[str, list[float]] = {name: [] for name in states}
    spent: dict[str, list[float]] = {name: [] for name in STAGES}
    batches = list(hotel_batches(args.frames, args.seed))
    print(f"hotel-suite, seed {args.seed}: {len(batches)} batches of {args.frames} frames")
    for batch in batches:
        for name in states:  # interleaved: the machine's noise hits both alike
            if name == OWN:
                with stage_clock(spent):
                    states[name], ms = step(states[name], batch)
            else:
                states[name], ms = step(states[name], batch)
            per_frame[name].append(ms)
    conditions = {
        name: StreamCondition(
            tracks=len(states[name].tracks),
            median_ms=statistics.median(times),
            p90_ms=statistics.quantiles(times, n=10)[-1],
        )
        for name, times in per_frame.items()
    }
    for name, row in conditions.items():
        print(
            f"{name:>28}: decide + fold per frame median {row.median_ms:6.2f} ms, "
            f"p90 {row.p90_ms:6.2f} ms ({row.tracks} tracks at the end); goal <= {GOAL_MS:g} ms"
        )
    frames_per_batch = len(batches[0].frames)
    stages = {
        name: statistics.median(times) / frames_per_batch for name, times in spent.items() if times
    }
    print(
        f"{'per stage, per frame':>28}: "
        + ", ".join(f"{name} {ms:.2f}" for name, ms in stages.items())
        + " ms"
    )
    write_results(
        "stream",
        StreamResult(
            scenario="hotel-suite",
            seed=args.seed,
            frames=args.frames,
            goal_ms=GOAL_MS,
            conditions=conditions,
            stages_median_ms_per_frame=stages,
        ),
    )


if __name__ == "__main__":
    main()
