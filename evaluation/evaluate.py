"""Run one method over one simulated stream, in process or through the HTTP API.

In process, each batch goes through the same wire encoding and the service's codec as a posted
one, so both paths see identical observations (depth quantized to millimetres, masks as RLE).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

from api_schema import BatchIn
from codec.observations import decode_batch
from core.decide import decide
from core.event_envelope import TrackEvent
from core.event_records import event_from_record
from core.events import (
    Event,
    SceneCreated,
    TrackConfirmed,
    TrackMoved,
    TrackRemoved,
    TrackReparented,
)
from core.evolve import evolve, fold
from core.graph import is_published
from core.params import Params
from core.state import SceneState, Track
from evaluation.methods import Method
from evaluation.predictions import FramePrediction, MethodEvent, PredictedNode
from pbdag_client import Client

WireBatch = tuple[
    int, dict[str, Any]
]  # (index of the batch's last frame, batch in the wire format)


@dataclass(frozen=True)
class MethodRun:
    """What a method produced on one stream."""

    predictions: tuple[FramePrediction, ...]  # the published graph after every frame
    events: tuple[MethodEvent, ...]
    final_nodes: tuple[PredictedNode, ...]  # fixtures and objects published at the end
    seconds: float


def nodes_of(
    state: SceneState, prefix: str = "", publishable: Callable[[Track], bool] | None = None
) -> tuple[PredictedNode, ...]:
    """The published graph as prediction nodes (optionally filtered by a method's hook)."""
    nodes = []
    for track_id in sorted(state.tracks):
        track = state.tracks[track_id]
        if not is_published(track) or (publishable is not None and not publishable(track)):
            continue
        parent = None if track.parent is None else prefix + track.parent
        nodes.append(
            PredictedNode(prefix + track_id, track.label, track.center, parent, track.kind)
        )
    return tuple(nodes)


def graph_events(
    frame: int, before: Sequence[PredictedNode], after: Sequence[PredictedNode]
) -> list[MethodEvent]:
    """Typed events of a method whose only output is its graph: diffs between two graphs, each
    standing for the core event a published graph shows (a node published, unpublished, moved
    by 0.35 m or more, given a new parent)."""
    old = {n.track_id: n for n in before}
    new = {n.track_id: n for n in after}
    events = [MethodEvent(frame, i, TrackConfirmed) for i in new if i not in old]
    events += [MethodEvent(frame, i, TrackRemoved) for i in old if i not in new]
    for track_id in new.keys() & old.keys():
        a, b = old[track_id], new[track_id]
        if sum((x - y) ** 2 for x, y in zip(a.center, b.center, strict=True)) >= 0.35**2:
            events.append(MethodEvent(frame, track_id, TrackMoved))
        if b.parent is not None and b.parent != a.parent:
            events.append(
                MethodEvent(
                    frame, track_id, TrackReparented, new_parent=b.parent, old_parent=a.parent
                )
            )
    return sorted(events, key=lambda e: (e.kind.type, e.track_id))


class Recorder:
    """Turns per-batch graphs and events into per-frame predictions and stamped events."""

    def __init__(self) -> None:
        self.predictions: list[FramePrediction] = []
        self.events: list[MethodEvent] = []
        self.last: tuple[PredictedNode, ...] = ()

    def batch(
        self, last_frame: int, nodes: tuple[PredictedNode, ...], events: Sequence[MethodEvent]
    ) -> None:
        """Every frame of the batch shows the graph after the batch."""
        for frame in range(len(self.predictions), last_frame + 1):
            self.predictions.append(FramePrediction(frame, nodes))
        self.events.extend(events)
        self.last = nodes

    def result(self, seconds: float) -> MethodRun:
        """What the method produced."""
        return MethodRun(tuple(self.predictions), tuple(self.events), self.last, seconds)


def stamp(frame: int, events: Sequence[Event], prefix: str = "") -> list[MethodEvent]:
    """Core events about tracks as method events at a frame (track ids prefixed per remap
    epoch, the parents of a reparent too)."""
    stamped = []
    for event in events:
        if not isinstance(event, TrackEvent):
            continue
        if prefix:
            event = replace(event, track_id=prefix + event.track_id)
            if isinstance(event, TrackReparented):
                old = None if event.old_parent is None else prefix + event.old_parent
                event = replace(event, old_parent=old, new_parent=prefix + event.new_parent)
        stamped.append(MethodEvent.of(frame, event))
    return stamped


def run_in_process(
    method: Method, batches: Sequence[WireBatch], on_batch: Callable[[], None] | None = None
) -> MethodRun:
    """The method's rules on the shared loop: decode like the service, decide, fold, publish."""
    started = time.perf_counter()
    rules = method.rules  # raises MethodUnavailable before any work
    hooks = method.hooks() if method.hooks is not None else None
    params = Params.from_dict(method.params)
    created = SceneCreated(name=method.name, params=params.to_dict())
    fresh = evolve(SceneState(), created)
    state, epoch, epoch_start = fresh, 0, 0
    n_frames = batches[-1][0] + 1 if batches else 0
    freeze_at = (
        None
        if method.freeze_after_fraction is None
        else int(n_frames * method.freeze_after_fraction)
    )
    recorder = Recorder()
    for last_frame, body in batches:
        if method.reset_every_frames and last_frame - epoch_start >= method.reset_every_frames:
            state, epoch, epoch_start = fresh, epoch + 1, last_frame  # a remap forgets everything
            hooks = method.hooks() if method.hooks is not None else None
        prefix = f"r{epoch}-" if method.reset_every_frames else ""
        if freeze_at is not None and last_frame >= freeze_at:
            recorder.batch(last_frame, recorder.last, [])  # the static map no longer changes
            continue
        batch = decode_batch(BatchIn.model_validate(body))
        events = decide(state, batch, params, rules)
        state = fold(state, events)
        if hooks is not None:
            # The baseline's own maintenance, folded like the core's events; its graph is
            # filtered, so its typed events are the differences between published graphs.
            state = fold(state, hooks.after_batch(state, events, last_frame))
            nodes = nodes_of(state, prefix, hooks.publishable)
            recorder.batch(last_frame, nodes, graph_events(last_frame, recorder.last, nodes))
        else:
            recorder.batch(last_frame, nodes_of(state, prefix), stamp(last_frame, events, prefix))
        if on_batch is not None:
            on_batch()
    return recorder.result(time.perf_counter() - started)


def run_via_service(
    method: Method,
    batches: Sequence[WireBatch],
    client: Client,
    on_batch: Callable[[], None] | None = None,
    timeout_s: float = 120.0,
) -> MethodRun:
    """PBD-AG through the HTTP API: post each batch, wait for it, read its events and the graph."""
    if method.changes_the_loop:
        raise ValueError(
            f"{method.name} changes the update rules; only parameter variants run through the API"
        )
    started = time.perf_counter()
    scene_id = client.create_scene(f"eval {method.name}", params=method.params).id
    recorder = Recorder()
    for last_frame, body in batches:
        batch = BatchIn.model_validate(body)
        client.post_batch(scene_id, batch)
        status = client.wait_for_batch(
            scene_id, batch.batch_id, timeout=timeout_s, poll_interval=0.01
        )
        events: list[MethodEvent] = []
        if status.first_seq is not None:
            logged = client.events(scene_id, after=status.first_seq - 1, up_to=status.last_seq)
            events = stamp(last_frame, [event_from_record(e.model_dump()) for e in logged])
        nodes = tuple(
            PredictedNode(n.id, n.label, (n.center[0], n.center[1], n.center[2]), n.parent, n.kind)
            for n in client.graph(scene_id).nodes
        )
        recorder.batch(last_frame, nodes, events)
        if on_batch is not None:
            on_batch()
    return recorder.result(time.perf_counter() - started)
