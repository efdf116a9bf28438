"""Run one method over one simulated stream, in process or through the HTTP API.

In process, each batch goes through the same wire encoding and the service's codec as a posted
one, so both paths see identical observations (depth quantized to millimetres, masks as RLE).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import httpx

from api_schema import BatchIn
from core.decide import decide
from core.events import Event, SceneCreated, TrackReparented
from core.evolve import evolve, fold
from core.graph import is_published
from core.params import Params
from core.state import SceneState, Track
from evaluation.methods import Method
from evaluation.predictions import FramePrediction, MethodEvent, PredictedNode
from service.codec import decode_batch

if TYPE_CHECKING:  # tests drive the service in process through Starlette's client (on httpx2)
    from fastapi.testclient import TestClient

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
    """Typed events of a method whose only output is its graph: diffs between two graphs."""
    old = {n.track_id: n for n in before}
    new = {n.track_id: n for n in after}
    events = [MethodEvent(frame, "confirm", i, {}) for i in new if i not in old]
    events += [MethodEvent(frame, "remove", i, {}) for i in old if i not in new]
    for track_id in new.keys() & old.keys():
        a, b = old[track_id], new[track_id]
        if sum((x - y) ** 2 for x, y in zip(a.center, b.center, strict=True)) >= 0.35**2:
            events.append(MethodEvent(frame, "move", track_id, {}))
        if b.parent is not None and b.parent != a.parent:
            events.append(
                MethodEvent(
                    frame, "reparent", track_id, {"old_parent": a.parent, "new_parent": b.parent}
                )
            )
    return sorted(events, key=lambda e: (e.type, e.track_id))


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
    """Core events as method events at a frame (track ids prefixed per remap epoch)."""
    stamped = []
    for event in events:
        if event.track_id is None:
            continue
        details = event.details()
        if isinstance(event, TrackReparented):
            details = {k: None if v is None else prefix + v for k, v in details.items()}
        stamped.append(MethodEvent(frame, event.type, prefix + event.track_id, details))
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
    client: httpx.Client | TestClient,
    on_batch: Callable[[], None] | None = None,
    timeout_s: float = 120.0,
) -> MethodRun:
    """PBD-AG through the HTTP API: post each batch, wait for it, read its events and the graph."""
    if method.changes_the_loop:
        raise ValueError(
            f"{method.name} changes the update rules; only parameter variants run through the API"
        )
    started = time.perf_counter()
    response = client.post(
        "/v1/scenes", json={"name": f"eval {method.name}", "params": method.params}
    )
    response.raise_for_status()
    scene_id = response.json()["id"]
    recorder = Recorder()
    for last_frame, body in batches:
        assert client.post(f"/v1/scenes/{scene_id}/batches", json=body).status_code in (200, 202)
        status = _wait_done(client, scene_id, body["batch_id"], timeout_s)
        events: list[MethodEvent] = []
        if status["first_seq"] is not None:
            page = client.get(
                f"/v1/scenes/{scene_id}/events",
                params={"after": status["first_seq"] - 1, "limit": 1000},
            ).json()["events"]
            events = [
                MethodEvent(last_frame, e["type"], e["track_id"], e["details"])
                for e in page
                if e["seq"] <= status["last_seq"] and e["track_id"] is not None
            ]
        graph = client.get(f"/v1/scenes/{scene_id}/graph").json()
        nodes = tuple(
            PredictedNode(n["id"], n["label"], tuple(n["center"]), n["parent"], n["kind"])
            for n in graph["nodes"]
        )
        recorder.batch(last_frame, nodes, events)
        if on_batch is not None:
            on_batch()
    return recorder.result(time.perf_counter() - started)


def _wait_done(
    client: httpx.Client | TestClient, scene_id: str, batch_id: str, timeout_s: float
) -> dict[str, Any]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        response = client.get(f"/v1/scenes/{scene_id}/batches/{batch_id}")
        if response.status_code == 429:  # polling faster than the service's rate limit
            time.sleep(float(response.headers.get("retry-after", "1")))
            continue
        status: dict[str, Any] = response.json()
        if status["status"] == "done":
            return status
        if status["status"] == "dead":
            raise RuntimeError(f"batch {batch_id} failed in the service: {status['error']}")
        time.sleep(0.01)
    raise TimeoutError(f"batch {batch_id} not processed within {timeout_s:.0f} s")
