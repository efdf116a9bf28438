"""Scenes of realistic perception for core tests: a mug, a bin split in two masks, relabelled
detections."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from core.decide import decide
from core.events import Event
from core.evolve import fold
from core.masks import Mask
from core.observation import Batch, Frame
from core.state import SceneState
from tests.core.scenes import (
    detection,
    paint_box,
    track_events,
    wall,
)
from tests.core.scenes import frame as analytic_frame

MUG = {"mug_1": ((0.2, 0.1, 2.0), 0.1)}


def run(state: SceneState, batch_list: list[Batch]) -> tuple[SceneState, list[list[Event]]]:
    per_batch = []
    for batch in batch_list:
        events = decide(state, batch)
        state = fold(state, events)
        per_batch.append(track_events(events))
    return state, per_batch


def with_scores(batch: Batch, label: str, scores: dict[str, float]) -> Batch:
    """The batch's detections relabelled, with an open-vocabulary detector's class scores."""
    first = batch.frames[0]
    detections = tuple(replace(d, label=label, class_scores=scores) for d in first.detections)
    return replace(batch, frames=(replace(first, detections=detections),))


def split_in_two(view: Frame, label: str, axis: int = 0) -> Frame:
    """The frame with the `label` object's mask reported as two halves: left and right (axis
    0, split across columns) or top and bottom (axis 1, across rows)."""
    detections = []
    for d in view.detections:
        if d.label != label:
            detections.append(d)
            continue
        mask = d.mask.to_array()
        lines = np.flatnonzero(mask.any(axis=axis))
        middle = int(lines[len(lines) // 2])
        first, second = mask.copy(), mask.copy()
        if axis == 0:
            first[:, middle:], second[:, :middle] = False, False
        else:
            first[middle:, :], second[:middle, :] = False, False
        detections += [replace(d, mask=Mask.from_array(half)) for half in (first, second)]
    return replace(view, detections=tuple(detections))


BIN = {"bin_1": ((0.2, 0.1, 2.0), 0.3)}  # large enough that either half of its mask grounds


def split_batch(batch_id: str) -> Batch:
    """The bin of BIN reported as two masks, its left and right halves (over-segmentation)."""
    depth = wall()
    mask = paint_box(depth, *BIN["bin_1"])
    columns = np.flatnonzero(mask.any(axis=0))
    middle = int(columns[len(columns) // 2])
    left, right = mask.copy(), mask.copy()
    left[:, middle:] = False
    right[:, :middle] = False
    pieces = (detection("bin", left), detection("bin", right))
    return Batch(batch_id, (analytic_frame(f"{batch_id}-f0", depth, pieces),))
