"""Does a scenario show what it claims? Visible frames around events, fixture revisits, occlusion."""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections import defaultdict
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from sim.recorded import composite
from sim.render import render
from sim.scenario import Scenario, load_scenario
from sim.scenario_parts import EventSpec
from sim.stream import frame_source
from sim.timeline import Timeline

VISIT_GAP_FRAMES = 3  # a sighting interrupted this briefly is still the same visit


def _runs(frames: list[int]) -> list[tuple[int, int]]:
    """Visits: stretches of frames with gaps of at most VISIT_GAP_FRAMES, as (first, last)."""
    runs: list[tuple[int, int]] = []
    for frame in sorted(frames):
        if runs and frame <= runs[-1][1] + 1 + VISIT_GAP_FRAMES:
            runs[-1] = (runs[-1][0], frame)
        else:
            runs.append((frame, frame))
    return runs


def _counts(instance: np.ndarray, size: int) -> np.ndarray:
    """Pixels per instance index."""
    return np.bincount(instance.ravel() + 1, minlength=size + 1)[1:]


def _event_entry(
    event: EventSpec,
    scenario: Scenario,
    seen: Mapping[str, list[int]],
    place_seen: Mapping[str, list[int]],
) -> dict[str, Any]:
    """One event's line: its object's visible frames before and after, later fixture visits,
    and for a disappearance or appearance the frames its place was in view."""
    frames = seen.get(event.object, [])
    entry: dict[str, Any] = {
        "frame": event.frame,
        "type": event.type,
        "object": event.object,
        "visible_before": sum(frame < event.frame for frame in frames),
        "visible_after": sum(frame >= event.frame for frame in frames),
        "fixture_visits_after": {
            spec.id: len(_runs([f for f in seen.get(spec.id, []) if f >= event.frame]))
            for spec in scenario.fixtures
        },
    }
    place = place_seen.get(event.object, [])
    if event.type == "disappear":
        entry["place_visible_after"] = sum(f >= event.frame for f in place)
    if event.type == "appear":
        entry["place_visible_before"] = sum(f < event.frame for f in place)
    return entry


def coverage(scenario: Scenario) -> dict[str, Any]:
    """Per event: frames its object is detectable before/after; revisits; occlusion counts."""
    timeline, source = Timeline(scenario), frame_source(scenario)
    object_pixels = scenario.detector.min_visible_pixels
    fixture_pixels = (
        scenario.detector.fixtures.min_visible_pixels if scenario.detector.fixtures else 400
    )
    seen: dict[str, list[int]] = defaultdict(list)
    occluded: dict[str, list[int]] = defaultdict(list)
    place_seen: dict[str, list[int]] = defaultdict(list)
    event_objects = {event.object for event in scenario.events}
    for frame_index, pose in enumerate(source.poses):
        world = timeline.world(frame_index)
        real = source.recording.depth(frame_index) if source.recording is not None else None

        def look(candidate: Any, real: Any = real, pose: Any = pose) -> Any:
            """Render, composited over the real depth when there is one."""
            view = render(candidate, source.camera, pose)
            return composite(view, real)[0] if real is not None else view

        view = look(world)
        counts = _counts(view.instance, len(world.objects))
        for box, pixels in zip(world.objects, counts, strict=True):
            if pixels >= object_pixels:
                seen[box.id].append(frame_index)
        for box, pixels in zip(
            world.fixtures, _counts(view.fixture_instance, len(world.fixtures)), strict=True
        ):
            if pixels >= fixture_pixels:
                seen[box.id].append(frame_index)
        if world.occluders:
            bare = look(dataclasses.replace(world, occluders=()))
            for box, with_walls, without in zip(
                world.objects, counts, _counts(bare.instance, len(world.objects)), strict=True
            ):
                if without >= object_pixels > with_walls:
                    occluded[box.id].append(frame_index)
        # Where an event object is absent (before it appears, after it vanishes): would its
        # place be in view? A method can only notice the change from such frames.
        absent = [
            object_id
            for object_id, placement in timeline.placements(frame_index).items()
            if object_id in event_objects and not placement.present
        ]
        for object_id in absent:
            ghost_world = timeline.world_with(frame_index, object_id)
            ghost = look(ghost_world)
            index = ghost_world.object_index(object_id)
            if int((ghost.instance == index).sum()) >= object_pixels:
                place_seen[object_id].append(frame_index)
    events = [_event_entry(event, scenario, seen, place_seen) for event in scenario.events]
    return {
        "scenario": scenario.name,
        "frames": scenario.frames,
        "objects_visible_frames": {
            spec.id: len(seen.get(spec.id, [])) for spec in scenario.objects
        },
        "fixtures_visible_frames": {
            spec.id: len(seen.get(spec.id, [])) for spec in scenario.fixtures
        },
        "occluded_frames": {key: len(value) for key, value in occluded.items()},
        "events": events,
    }


def main(argv: list[str] | None = None) -> None:
    """Print the coverage report of scenario files as JSON."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("scenarios", type=Path, nargs="+")
    arguments = parser.parse_args(argv)
    for path in arguments.scenarios:
        print(json.dumps(coverage(load_scenario(path)), indent=1))


if __name__ == "__main__":
    main()
