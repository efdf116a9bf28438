"""The hand-off of decoded batches from the API to the worker of the same process: bounded in
bytes, taken once, and the events the worker appends are those it appends when it decodes the
stored blob itself."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
from fastapi.testclient import TestClient

from core.masks import Mask
from core.observation import Batch, Detection, Frame, Intrinsics
from service.app import create_app
from service.bootstrap import Container
from service.handoff import Handoff, decoded_bytes
from service.worker import Worker
from tests.clients import local_client
from tests.wire_scenes import batch

BATCHES = 4


def small_batch(batch_id: str, side: int) -> Batch:
    """A batch of one side x side frame with one mask."""
    mask = Mask.from_array(np.eye(side, dtype=bool))
    frame = Frame(
        f"{batch_id}-f",
        0.0,
        Intrinsics(side, side, 10.0, 10.0, side / 2, side / 2),
        np.eye(4),
        np.ones((side, side), np.float32),
        (Detection("mug", 0.9, "object", mask),),
    )
    return Batch(batch_id, (frame,))


def test_the_handoff_keeps_at_most_its_bytes_evicts_the_oldest_and_gives_each_batch_once() -> None:
    batches = [small_batch(f"b{i}", 16) for i in range(3)]
    size = decoded_bytes(batches[0])
    assert size == 16 * 16 * 4 + batches[0].frames[0].detections[0].mask.runs.nbytes
    handoff = Handoff(2 * size)
    for row, kept in enumerate(batches):
        handoff.put((row, f"blob-{row}"), kept)
    assert handoff.held_bytes == 2 * size
    assert handoff.take((0, "blob-0")) is None  # the oldest made room for the third
    assert handoff.take((1, "blob-other")) is None  # the row's id alone is not the batch
    assert handoff.take((1, "blob-1")) is batches[1]
    assert handoff.take((1, "blob-1")) is None  # taken once
    assert handoff.held_bytes == size
    handoff.put((7, "blob-7"), small_batch("large", 64))  # larger than the bound: not kept
    assert handoff.take((7, "blob-7")) is None and handoff.held_bytes == size


def done(client: TestClient, scene_id: str, batch_id: str) -> None:
    deadline = time.monotonic() + 60
    while client.get(f"/v1/scenes/{scene_id}/batches/{batch_id}").json()["status"] != "done":
        assert time.monotonic() < deadline, f"batch {batch_id} was not processed in time"
        time.sleep(0.05)


def test_the_worker_takes_what_its_api_decoded_and_appends_the_same_events(
    container: Container,
) -> None:
    """One scene processed by `pbdag serve`'s worker with the hand-off, its twin by a worker
    that decodes every stored blob: the same events, and every batch of the first handed off."""
    with local_client(create_app(container, run_worker=True)) as client:
        handed = client.post("/v1/scenes", json={"name": "twin"}).json()["id"]
        for index in range(BATCHES):
            assert client.post(
                f"/v1/scenes/{handed}/batches", json=batch(f"b{index}", index)
            ).is_success
        done(client, handed, f"b{BATCHES - 1}")
        metrics = client.get("/metrics").text
    assert f"pbdag_batches_handed_off_total {float(BATCHES)}" in metrics
    with local_client(create_app(container)) as client:  # no worker here: nothing is kept
        decoded = client.post("/v1/scenes", json={"name": "twin"}).json()["id"]
        for index in range(BATCHES):
            assert client.post(
                f"/v1/scenes/{decoded}/batches", json=batch(f"b{index}", index)
            ).is_success
    assert Worker(container).drain() == BATCHES  # decoding each stored blob: no hand-off
    handed_off = container.metrics.registry.get_sample_value("pbdag_batches_handed_off_total")
    assert handed_off == BATCHES

    def events_of(scene_id: str) -> list[object]:
        return [stored.to_core() for stored in container.log.read(scene_id)]

    handed_events, decoded_events = events_of(handed), events_of(decoded)
    assert len(handed_events) > BATCHES
    assert handed_events == decoded_events


def test_no_handoff_without_a_worker_in_the_process_or_with_a_zero_bound(
    container: Container,
) -> None:
    assert create_app(container).state.handoff is None
    assert create_app(container, run_worker=True).state.handoff is not None
    off = dataclasses.replace(
        container, settings=container.settings.model_copy(update={"handoff_max_bytes": 0})
    )
    assert create_app(off, run_worker=True).state.handoff is None
