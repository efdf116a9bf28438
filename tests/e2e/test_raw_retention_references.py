"""Retention keeps the raw batch holding the frame a pending verification or an unresolved
inspection names, and lets it go once the verdict is in (through the HTTP API)."""

from __future__ import annotations

import orjson

from service.bootstrap import Container
from service.retention import collect
from service.store.raw_batches import decode_raw_batch
from tests.eval_extra import require_eval_extra

require_eval_extra()  # the simulator renders this test's world

from tests.e2e.fixture_api import Api, api, discovered  # noqa: E402

__all__ = ["api"]  # the fixture, used by name


def frames_of_batches(container: Container, scene_id: str) -> dict[str, set[str]]:
    """Each batch's frame ids, read from the raw bodies themselves."""
    found = {}
    for record in container.queue.of_scene(scene_id):
        body = orjson.loads(decode_raw_batch(container.blobs.get(record.blob_key)))
        found[record.batch_id] = {frame["frame_id"] for frame in body["frames"]}
    return found


def holding(frames: dict[str, set[str]], wanted: set[str]) -> set[str]:
    return {batch_id for batch_id, ids in frames.items() if ids & wanted}


def test_gc_keeps_the_batches_of_pending_verifications_and_unresolved_inspections(
    api: Api,
) -> None:
    client, _worker, container = api
    ambiguous = {"table": {"table": 0.50, "desk": 0.48}}
    scene_id = discovered(client, _worker, ambiguity=ambiguous)
    frames = frames_of_batches(container, scene_id)
    pending = client.get(f"/v1/scenes/{scene_id}/verifications").json()["verifications"]
    assert len(pending) == 1 and pending[0]["best_frame"]
    queue = client.get(f"/v1/scenes/{scene_id}/inspection-queue").json()["fixtures"]
    state = container.log.load_state(scene_id)
    inspected = {state.tracks[item["fixture_id"]].best_frame or "" for item in queue}
    needed = holding(frames, {pending[0]["best_frame"]} | inspected)
    assert needed and needed != set(frames)  # the test means something

    dry = collect(container, 0.0, dry_run=True, clock=lambda: 1e12)
    assert {r.batch_id for r in dry.kept_referenced} == needed
    assert {r.batch_id for r in dry.expired} == set(frames) - needed
    report = collect(container, 0.0, clock=lambda: 1e12)
    assert {r.batch_id for r in report.expired} == set(frames) - needed
    for record in container.queue.of_scene(scene_id):
        assert (record.blob_collected_at is None) == (record.batch_id in needed)

    # The verdict rejects the table: its frame is no longer needed (unless an inspection's is).
    response = client.post(
        f"/v1/scenes/{scene_id}/tracks/{pending[0]['track_id']}/verification",
        json={"verdict": "reject", "source": "vlm-test", "frame_id": pending[0]["best_frame"]},
    )
    assert response.status_code == 201, response.text
    still = holding(frames, inspected)
    later = collect(container, 0.0, clock=lambda: 1e12)
    assert {r.batch_id for r in later.expired} == needed - still
    assert {r.batch_id for r in later.kept_referenced} == still
