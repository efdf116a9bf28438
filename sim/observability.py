"""When each scripted change first became observable in a stream (where event latency starts).

A memory cannot reflect a change before its sensors could show it. An appearance, a move or a
transfer is observable from the first frame at or after the change in which the detector reported
the object (at its new place); a disappearance from the first frame at or after the change in
which the object, put back where it was, would have shown at least the detector's minimum mask
area (its empty place was in view and not hidden). A change never observable before the same
object's next change, or the end of the run, has no observable frame (None).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from sim.camera import CameraModel
from sim.detector import SimDetection
from sim.recorded import composite
from sim.render import render
from sim.scenario_spec import Scenario
from sim.timeline import Timeline
from sim.truth import ScheduledEvent

RealDepth = Callable[[int], np.ndarray]


class DetectedFrame(Protocol):
    """What this module reads of a simulated frame."""

    @property
    def frame_index(self) -> int: ...

    @property
    def detections(self) -> tuple[SimDetection, ...]: ...


def _detected(frames: Sequence[DetectedFrame], object_id: str, start: int, stop: int) -> int | None:
    """First frame in [start, stop) whose detections include the object."""
    for frame in frames[start:stop]:
        if any(d.kind == "object" and d.object_id == object_id for d in frame.detections):
            return frame.frame_index
    return None


def _place_in_view(
    scenario: Scenario,
    timeline: Timeline,
    camera: CameraModel,
    poses: Sequence[np.ndarray],
    real_depth: RealDepth | None,
    object_id: str,
    start: int,
    stop: int,
) -> int | None:
    """First frame in [start, stop) whose view would show the absent object well enough."""
    threshold = scenario.detector.min_visible_pixels
    for frame_index in range(start, stop):
        world = timeline.world_with(frame_index, object_id)
        view = render(world, camera, poses[frame_index])
        if real_depth is not None:
            view = composite(view, real_depth(frame_index))[0]
        index = world.object_index(object_id)
        if int((view.instance == index).sum()) >= threshold:
            return frame_index
    return None


def observable_frames(
    scenario: Scenario,
    frames: Sequence[DetectedFrame],
    events: Sequence[ScheduledEvent],
    camera: CameraModel,
    poses: Sequence[np.ndarray],
    real_depth: RealDepth | None = None,
) -> tuple[int | None, ...]:
    """Per scheduled event, the first frame at which the change could be seen (or None)."""
    timeline = Timeline(scenario)
    observable: list[int | None] = []
    for position, event in enumerate(events):
        following = [
            later.frame for later in events[position + 1 :] if later.object_id == event.object_id
        ]
        stop = min(following, default=len(frames))
        if event.type == "disappear":
            observable.append(
                _place_in_view(
                    scenario,
                    timeline,
                    camera,
                    poses,
                    real_depth,
                    event.object_id,
                    event.frame,
                    stop,
                )
            )
        else:
            observable.append(_detected(frames, event.object_id, event.frame, stop))
    return tuple(observable)


def empty_place_batches(
    scenario: Scenario,
    events: Sequence[ScheduledEvent],
    observable: Sequence[int | None],
    camera: CameraModel,
    poses: Sequence[np.ndarray],
    frames_per_batch: int,
    real_depth: RealDepth | None = None,
) -> tuple[int | None, ...]:
    """Per disappearance: in how many batches of the latency bound (from the batch it became
    observable in, `scenario.event_latency_batches` on) its empty place was in view as well as
    `_place_in_view` asks, before the object's next change. A memory removes an object after a
    number of visibility-admissible misses, one per batch at most: this is how many it could
    have had. None for other changes and for a disappearance never observable."""
    timeline = Timeline(scenario)
    counts: list[int | None] = []
    for position, (event, first) in enumerate(zip(events, observable, strict=True)):
        if event.type != "disappear" or first is None:
            counts.append(None)
            continue
        following = [
            later.frame for later in events[position + 1 :] if later.object_id == event.object_id
        ]
        start_batch = first // frames_per_batch
        stop = min(
            min(following, default=len(poses)),
            (start_batch + scenario.event_latency_batches + 1) * frames_per_batch,
            len(poses),
        )
        batches: set[int] = set()
        frame_index = first
        while frame_index < stop:
            shown = _place_in_view(
                scenario, timeline, camera, poses, real_depth, event.object_id, frame_index, stop
            )
            if shown is None:
                break
            batches.add(shown // frames_per_batch)
            frame_index = (shown // frames_per_batch + 1) * frames_per_batch  # the next batch
        counts.append(len(batches))
    return tuple(counts)
