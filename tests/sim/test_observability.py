"""How many batches of the latency bound showed a removed object's empty place: the count the
removal recall is judged by (sim.observability.empty_place_batches)."""

from __future__ import annotations

from pathlib import Path

from sim.observability import _place_in_view, empty_place_batches
from sim.scenario import load_scenario
from sim.stream import simulate
from sim.timeline import Timeline

DEMO = Path(__file__).resolve().parents[2] / "sim" / "scenarios" / "demo.yaml"


def test_the_empty_place_is_counted_once_per_batch_that_showed_it_within_the_bound() -> None:
    scenario = load_scenario(DEMO, frames=90)
    run = simulate(scenario, seed=7)
    poses = [frame.pose for frame in run.frames]
    camera = run.frames[0].camera
    counts = empty_place_batches(
        scenario, run.events, run.observable_frames, camera, poses, frames_per_batch=2
    )
    (position,) = (i for i, e in enumerate(run.events) if e.type == "disappear")
    assert all(n is None for i, n in enumerate(counts) if i != position)
    first = run.observable_frames[position]
    assert first is not None
    # Frame by frame: the batches (two frames each) of the bound in which the place showed.
    timeline, event = Timeline(scenario), run.events[position]
    stop = min(len(poses), (first // 2 + scenario.event_latency_batches + 1) * 2)
    shown = {
        frame // 2
        for frame in range(first, stop)
        if _place_in_view(
            scenario, timeline, camera, poses, None, event.object_id, frame, frame + 1
        )
        is not None
    }
    assert counts[position] == len(shown) >= 1
    assert first // 2 in shown  # the batch it became observable in counts
