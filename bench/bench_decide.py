"""Benchmark: decide + evolve for one 640x480 frame with 20 masks against 500 live tracks."""

from __future__ import annotations

import argparse
import statistics
import time
from dataclasses import replace

import numpy as np

from bench.perf_common import write_results
from core.decide import decide
from core.events import ObjectAdded, Observation
from core.evolve import fold
from core.masks import Mask
from core.observation import Batch, Detection, Frame, Intrinsics
from core.state import SceneState
from sim.camera import CameraModel, look_at
from sim.detector import detect
from sim.render import add_kinect_noise, render
from sim.world import Box, World, object_on

LABELS = ("mug", "book", "bowl", "bottle", "remote", "cup", "plate", "phone", "box", "can")


def twenty_objects_frame(seed: int) -> tuple[World, Frame]:
    """A long table carrying 20 objects, all in view, rendered and detected."""
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


def state_with_500_tracks(frame: Frame, seed: int) -> SceneState:
    """The 20 objects as confirmed tracks, plus 480 tracks elsewhere (some in view, most not)."""
    state = SceneState()
    for i in range(2):
        state = fold(state, decide(state, Batch(f"warm{i}", (frame,))))
    rng = np.random.default_rng(seed)
    extra = []
    for k in range(480):
        center = rng.uniform([0.2, 0.2, 0.1], [7.8, 5.8, 2.0])
        extra.append(
            ObjectAdded(
                track_id=f"trk-{state.next_track_number + k:06d}",
                state="tentative",
                frame_id="x",
                observations=(
                    Observation(
                        frame_id="x",
                        label=LABELS[k % len(LABELS)],
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
        )
    return fold(state, extra)


def main(argv: list[str] | None = None) -> None:
    """Print the median time of decide + evolve and write bench/results/decide.json."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    _world, frame = twenty_objects_frame(args.seed)
    state = state_with_500_tracks(frame, args.seed)
    batch = Batch("bench", (frame,))
    decide_ms, evolve_ms, total_ms = [], [], []
    events = []
    for _ in range(args.repeats):
        fresh = replace(
            state
        )  # a new state object: its column cache is rebuilt, as after every batch
        started = time.perf_counter()
        events = decide(fresh, batch)
        decided = time.perf_counter()
        fold(fresh, events)
        done = time.perf_counter()
        decide_ms.append(1000 * (decided - started))
        evolve_ms.append(1000 * (done - decided))
        total_ms.append(1000 * (done - started))
    results = {
        "tracks": len(state.tracks),
        "masks": len(frame.detections),
        "resolution": [frame.intrinsics.width, frame.intrinsics.height],
        "events_per_batch": len(events),
        "repeats": args.repeats,
        "decide_median_ms": statistics.median(decide_ms),
        "evolve_median_ms": statistics.median(evolve_ms),
        "decide_evolve_median_ms": statistics.median(total_ms),
        "decide_evolve_p90_ms": statistics.quantiles(total_ms, n=10)[-1],
        "goal_ms": 10.0,
    }
    print(
        f"decide + evolve, {results['masks']} masks at {frame.intrinsics.width}x{frame.intrinsics.height} "
        f"against {results['tracks']} tracks ({results['events_per_batch']} events): "
        f"median {results['decide_evolve_median_ms']:.2f} ms (decide {results['decide_median_ms']:.2f}, "
        f"evolve {results['evolve_median_ms']:.2f}), p90 {results['decide_evolve_p90_ms']:.2f} ms; goal < 10 ms"
    )
    write_results("decide", results)


if __name__ == "__main__":
    main()
