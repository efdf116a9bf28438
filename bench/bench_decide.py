"""Benchmark: decide + evolve for one 640x480 frame with 20 masks against 500 live tracks, and
with 5,000 retired or stale hypotheses in memory beside them."""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

import core.decide as decide_module
from bench.perf_common import write_results
from bench.records import LIVE_ONLY, DecideCondition, DecideResult
from core.decide import decide
from core.events import Event, ObjectAdded, TrackRetired
from core.evolve import fold
from core.masks import Mask
from core.observation import Batch, Detection, Frame, Intrinsics
from core.state import SceneState
from core.values import Observation
from sim.camera import CameraModel, look_at
from sim.detector import detect
from sim.render import add_kinect_noise, render
from sim.world import Box, World, object_on

LABELS = ("mug", "book", "bowl", "bottle", "remote", "cup", "plate", "phone", "box", "can")


def table_with_twenty_objects() -> tuple[Box, tuple[Box, ...]]:
    """A long table (a fixture) and the 20 small objects on it, in two rows of ten."""
    table = Box("table", "table", (4.0, 3.0, 0.375), (2.4, 1.0, 0.75), kind="fixture")
    objects = tuple(
        object_on(
            table,
            f"obj{i}",
            LABELS[i % len(LABELS)],
            (0.1, 0.1, 0.12),
            at=(-1.0 + 0.21 * (i % 10), -0.25 + 0.5 * (i // 10)),
        )
        for i in range(20)
    )
    return table, objects


def twenty_objects_frame(seed: int) -> tuple[World, Frame]:
    """A long table carrying 20 objects, all in view, rendered and detected."""
    table, objects = table_with_twenty_objects()
    world = World(room_size=(8.0, 6.0, 2.6), fixtures=(table,), objects=objects)
    camera = CameraModel()
    pose = look_at((4.0, 1.2, 1.6), (4.0, 3.0, 0.75))
    view = render(world, camera, pose)
    rng = np.random.default_rng(seed)
    detections = detect(
        view, world, rng, min_visible_pixels=50, boundary_leak_px=1, embedding_noise=0.05
    )
    assert len(detections) == 20, f"only {len(detections)} objects detected"
    intrinsics = Intrinsics(camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy)
    frame = Frame(
        "f0",
        0.0,
        intrinsics,
        pose,
        add_kinect_noise(view.depth, rng).astype(np.float32),
        tuple(
            Detection(d.label, d.score, "object", Mask.from_array(d.mask), d.embedding)
            for d in detections
        ),
    )
    return world, frame


def sighted(track_id: str, label: str, center: np.ndarray, rng: np.random.Generator) -> Event:
    """A hypothesis seen once, with appearance, as decide writes it."""
    return ObjectAdded(
        track_id=track_id,
        state="tentative",
        frame_id="x",
        observations=(
            Observation(
                frame_id="x",
                label=label,
                score=0.9,
                center=(float(center[0]), float(center[1]), float(center[2])),
                extent=(0.1, 0.1, 0.1),
                valid_pixels=500,
                parent=None,
            ),
        ),
        embedding_sum=tuple(float(v) for v in rng.normal(size=64)),
        embedding_count=1,
        timestamp=0.0,
        existence_logodds=1.0,
        p_exist=0.73,
        batches_observed=1,
        parent_evidence={},
    )


def state_with_500_tracks(frame: Frame, seed: int) -> SceneState:
    """The 20 objects as confirmed tracks, plus 480 tracks elsewhere (some in view, most not)."""
    state = SceneState()
    for i in range(2):
        state = fold(state, decide(state, Batch(f"warm{i}", (frame,))))
    rng = np.random.default_rng(seed)
    extra = [
        sighted(
            f"trk-{state.next_track_number + k:06d}",
            LABELS[k % len(LABELS)],
            rng.uniform([0.2, 0.2, 0.1], [7.8, 5.8, 2.0]),
            rng,
        )
        for k in range(480)
    ]
    return fold(state, extra)


def with_hypotheses(state: SceneState, count: int, retire: bool, seed: int) -> SceneState:
    """`count` hypotheses seen once behind the camera (never published); retired, or not yet."""
    rng = np.random.default_rng(seed)
    events: list[Event] = []
    for k in range(count):
        track_id = f"trk-{state.next_track_number + k:06d}"
        behind = rng.uniform([0.2, 0.0, 0.1], [7.8, 1.0, 2.0])  # y < 1.2: behind the camera
        events.append(sighted(track_id, LABELS[k % len(LABELS)], behind, rng))
        if retire:
            events.append(
                TrackRetired(
                    track_id=track_id,
                    state="retired",
                    frame_id="x",
                    reason="unseen",
                    last_observed=0.0,
                )
            )
    return fold(state, events)


def timed(state: SceneState, batch: Batch) -> tuple[float, float, int]:
    """(decide ms, evolve ms, events) of one batch. The state's columns exist, as after any fold
    (which derives them from the previous state's); evolve here derives the next ones."""
    started = time.perf_counter()
    events = decide(state, batch)
    decided = time.perf_counter()
    fold(state, events)
    done = time.perf_counter()
    return 1000 * (decided - started), 1000 * (done - decided), len(events)


# decide's stages in its order (core/decide.py): where a frame's time goes.
STAGES = (
    "fixture_batch",
    "ground_frames",
    "batch_visibility",
    "associate_batch",
    "support_parents",
    "existence_updates",
    "lifecycle_decisions",
    "occupancy_evidence",
    "batch_events",
)


@contextmanager
def stage_clock(spent: dict[str, list[float]]) -> Iterator[None]:
    """Time every stage `decide` calls while inside (ms per call, appended to `spent`)."""
    originals: dict[str, Callable[..., Any]] = {
        name: getattr(decide_module, name) for name in STAGES
    }

    def clocked(name: str, stage: Callable[..., Any]) -> Callable[..., Any]:
        def run(*args: Any, **kwargs: Any) -> Any:
            started = time.perf_counter()
            try:
                return stage(*args, **kwargs)
            finally:
                spent[name].append(1000 * (time.perf_counter() - started))

        return run

    for name, stage in originals.items():
        setattr(decide_module, name, clocked(name, stage))
    try:
        yield
    finally:
        for name, stage in originals.items():
            setattr(decide_module, name, stage)


def stage_breakdown(state: SceneState, batch: Batch, repeats: int) -> dict[str, float]:
    """Median ms of each stage of `decide` on this batch, over `repeats` runs."""
    spent: dict[str, list[float]] = {name: [] for name in STAGES}
    with stage_clock(spent):
        for _ in range(repeats):
            decide(state, batch)
    return {name: statistics.median(times) for name, times in spent.items() if times}


def main(argv: list[str] | None = None) -> None:
    """Median decide + evolve of one frame, with and without 5,000 retired or stale hypotheses
    in memory (measured interleaved); writes bench/results/decide.json."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--hypotheses", type=int, default=5000)
    args = parser.parse_args(argv)
    _world, frame = twenty_objects_frame(args.seed)
    state = state_with_500_tracks(frame, args.seed)
    batch = Batch("bench", (frame,))
    states = {
        LIVE_ONLY: state,
        f"plus {args.hypotheses} retired hypotheses": with_hypotheses(
            state, args.hypotheses, True, args.seed
        ),
        f"plus {args.hypotheses} stale hypotheses": with_hypotheses(
            state, args.hypotheses, False, args.seed
        ),
    }
    for condition in states.values():
        _ = condition.arrays  # built once, as the fold before this batch would have derived them
    samples: dict[str, list[tuple[float, float, int]]] = {name: [] for name in states}
    for _ in range(args.repeats):
        for name, condition in states.items():  # interleaved: the machine's noise hits all alike
            samples[name].append(timed(condition, batch))
    base = statistics.median(d + e for d, e, _n in samples[LIVE_ONLY])
    conditions: dict[str, DecideCondition] = {}
    for name, runs in samples.items():
        total = [d + e for d, e, _n in runs]
        median = statistics.median(total)
        conditions[name] = DecideCondition(
            tracks=len(states[name].tracks),
            events_per_batch=runs[0][2],
            decide_median_ms=statistics.median(d for d, _e, _n in runs),
            evolve_median_ms=statistics.median(e for _d, e, _n in runs),
            decide_evolve_median_ms=median,
            decide_evolve_p90_ms=statistics.quantiles(total, n=10)[-1],
            ratio_to_live_only=median / base,
        )
        print(
            f"{name:>32}: decide + evolve median {median:6.2f} ms "
            f"(p90 {statistics.quantiles(total, n=10)[-1]:6.2f}), {median / base:4.2f}x; "
            f"goal < 10 ms, and <= 1.5x with the hypotheses"
        )
    stages = stage_breakdown(state, batch, min(args.repeats, 50))
    print(
        f"{'per stage (500 live tracks)':>32}: "
        + ", ".join(f"{name} {ms:.2f}" for name, ms in stages.items())
        + f" ms (sum {sum(stages.values()):.2f})"
    )
    results = DecideResult(
        masks=len(frame.detections),
        resolution=(frame.intrinsics.width, frame.intrinsics.height),
        repeats=args.repeats,
        goal_ms=10.0,
        goal_ratio_with_hypotheses=1.5,
        conditions=conditions,
        stages_median_ms=stages,
    )
    write_results("decide", results)


if __name__ == "__main__":
    main()
