"""Benchmark: frames per second of render + detect at 640x480 along the demo scenario's walk."""

from __future__ import annotations

import os
import platform
import time
from pathlib import Path

import numpy as np

from bench.records import RenderResult, RenderRun, to_json
from sim import DEMO_SCENARIO
from sim.camera import CameraModel
from sim.detector import detect
from sim.render import render
from sim.scenario import load_scenario
from sim.stream import frame_source
from sim.timeline import Timeline

RESULTS_PATH = Path(__file__).resolve().parent / "results" / "render.json"
N_FRAMES = 100
SEED = 0


def measure_fps(n_frames: int, nthreads: int) -> RenderRun:
    """Time render and detect over the demo run; worlds and poses are prepared beforehand.

    Render and detect are timed apart, so this loop calls them directly; what the robot posts
    comes from `sim.stream`, which runs the same two functions.
    """
    scenario = load_scenario(DEMO_SCENARIO, frames=n_frames)
    source, timeline = frame_source(scenario), Timeline(scenario)
    camera, poses = source.camera, source.poses
    worlds = [timeline.world(frame_index) for frame_index in range(n_frames)]
    rng = np.random.default_rng(SEED)
    # One untimed frame per world so the cached raycast scenes are built outside the timing.
    for world in dict.fromkeys(worlds):
        render(world, camera, poses[0], nthreads=nthreads)
    render_seconds = detect_seconds = 0.0
    for world, pose in zip(worlds, poses, strict=True):
        started = time.perf_counter()
        view = render(world, camera, pose, nthreads=nthreads)
        rendered = time.perf_counter()
        detect(view, world, rng, recall=0.95, embedding_noise=0.05, boundary_leak_px=1)
        detect_seconds += time.perf_counter() - rendered
        render_seconds += rendered - started
    return RenderRun(
        frames=n_frames,
        render_ms_per_frame=1000.0 * render_seconds / n_frames,
        detect_ms_per_frame=1000.0 * detect_seconds / n_frames,
        fps=n_frames / (render_seconds + detect_seconds),
    )


def main() -> None:
    """Run single-thread and all-thread measurements, print them and save JSON."""
    results = RenderResult(
        resolution=(CameraModel().width, CameraModel().height),
        cpu_count=os.cpu_count(),
        machine=platform.machine(),
        one_thread=measure_fps(N_FRAMES, nthreads=1),
        all_threads=measure_fps(N_FRAMES, nthreads=0),
    )
    for name, run in (("one_thread", results.one_thread), ("all_threads", results.all_threads)):
        print(
            f"{name:>11}: {run.fps:.1f} frames/s "
            f"(render {run.render_ms_per_frame:.1f} ms + detect {run.detect_ms_per_frame:.1f} ms)"
        )
    RESULTS_PATH.parent.mkdir(parents=True, exist_ok=True)
    RESULTS_PATH.write_text(to_json(results))
    print(f"wrote {RESULTS_PATH}")


if __name__ == "__main__":
    main()
