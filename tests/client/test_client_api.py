"""Every route through the typed client, sync and async, against a real uvicorn server."""

from __future__ import annotations

import asyncio
import io

import pytest
from PIL import Image

from api_schema import BaselineRef, BatchIn, InspectionIn, RobotPose, VerdictIn
from pbdag_client import (
    AsyncClient,
    Client,
    Conflict,
    Forbidden,
    InvalidRequest,
    ResourceNotFound,
)
from tests.client.conftest import FilledScene, Service


def test_posting_waiting_and_reading_the_memory(service: Service, filled: FilledScene) -> None:
    assert {status.status for status in filled.posted} == {"queued"}
    assert all(status.status == "done" for status in filled.done)
    first, last = filled.done[0], filled.done[-1]
    assert first.first_seq is not None and last.last_seq is not None
    with Client(service.url) as client:
        assert client.health().status == "ok"
        scene = client.scene(filled.scene_id)
        assert scene.name == "client-demo" and scene.head_seq == last.last_seq
        assert filled.scene_id in [s.id for s in client.scenes()]
        assert client.batch(filled.scene_id, last.batch_id) == last

        graph = client.graph(filled.scene_id)
        assert graph.seq == scene.head_seq
        kinds = {node.kind for node in graph.nodes}
        assert kinds == {"fixture", "object"}
        # Time travel: the graph right after the first batch is older and smaller.
        early = client.graph(filled.scene_id, as_of=first.last_seq)
        assert early.seq == first.last_seq and len(early.nodes) < len(graph.nodes)
        everything = client.graph(filled.scene_id, include="all")
        assert len(everything.nodes) >= len(graph.nodes)
        fixture = next(node for node in graph.nodes if node.kind == "fixture")
        on_it = client.graph(filled.scene_id, parent=fixture.id)
        assert all(node.parent == fixture.id for node in on_it.nodes)

        tracks = client.tracks(filled.scene_id)
        assert {t.track_id for t in tracks} >= {node.id for node in graph.nodes}
        confirmed = client.tracks(filled.scene_id, state="confirmed")
        assert confirmed and all(t.state == "confirmed" for t in confirmed)
        belief = client.track(filled.scene_id, fixture.id)
        assert belief.track_id == fixture.id and belief.seq == scene.head_seq
        before = client.track(filled.scene_id, fixture.id, as_of=last.first_seq)
        assert before.seq == last.first_seq

        explanation = client.explain(filled.scene_id, fixture.id, events=True)
        assert explanation.track_id == fixture.id and explanation.summary
        assert explanation.events and all(e.track_id == fixture.id for e in explanation.events)
        assert client.explain(filled.scene_id, fixture.id).events is None  # only when asked

        occupancy = client.occupancy(filled.scene_id)
        assert occupancy.seq == scene.head_seq and occupancy.counts["free"] > 0
        png = client.occupancy_png(filled.scene_id, as_of=last.last_seq)
        with Image.open(io.BytesIO(png)) as image:
            assert image.format == "PNG" and image.size == (occupancy.shape[1], occupancy.shape[0])

        preview = client.preview_plan(filled.scene_id, 1.0, 1.0, 0.0)
        assert preview.decision in ("inspect", "explore", "done") and preview.event_seq is None
        assert client.scene(filled.scene_id).head_seq == scene.head_seq  # nothing was locked
        assert client.preview_plan(filled.scene_id, 1.0, 1.0, as_of=first.last_seq).seq == (
            first.last_seq
        )


def test_the_event_iterator_follows_every_page(service: Service, filled: FilledScene) -> None:
    with Client(service.url) as client:
        one_page = client.events_page(filled.scene_id, limit=1000)
        assert one_page.next_after is None and len(one_page.events) > 30
        paged = list(client.events(filled.scene_id, page_size=7))
        assert paged == one_page.events
        # A window of the log, as a batch's events are read: after first_seq - 1 up to last_seq.
        status = filled.done[3]
        assert status.first_seq is not None and status.last_seq is not None
        window = list(
            client.events(
                filled.scene_id, after=status.first_seq - 1, up_to=status.last_seq, page_size=2
            )
        )
        assert [e.seq for e in window] == list(range(status.first_seq, status.last_seq + 1))
        assert {e.batch_id for e in window} == {status.batch_id}
        confirms = list(client.events(filled.scene_id, type="confirm", page_size=1))
        assert confirms and all(e.type == "confirm" for e in confirms)


def test_a_repost_is_idempotent_and_new_content_under_its_id_a_conflict(
    service: Service, filled: FilledScene, demo_batches: list[BatchIn]
) -> None:
    original = demo_batches[0]
    with Client(service.url) as client:
        again = client.post_batch(filled.scene_id, original)
        assert again == filled.done[0]  # the original's status, done, nothing appended twice
        resubmitted = client.submit_batch(filled.scene_id, original)
        assert not resubmitted.new and resubmitted.status == filled.done[0]
        fresh = original.model_copy(update={"batch_id": "client-fresh"})
        submitted = client.submit_batch(filled.scene_id, fresh)
        assert submitted.new and submitted.status.batch_id == "client-fresh"
        changed = original.model_copy(update={"frames": original.frames[:1]})
        with pytest.raises(Conflict) as raised:
            client.post_batch(filled.scene_id, changed)
    assert raised.value.status == 409 and raised.value.type == "/problems/batch-conflict"
    assert raised.value.field == "batch_id"


def test_verdicts_baselines_inspections_and_the_plan(
    service: Service, demo_batches: list[BatchIn]
) -> None:
    with Client(service.url) as client:
        scene = client.create_scene(
            "client-commands", params={"fixtures": {"mask_pixel_stride": 4}}
        )
        assert scene.params["fixtures"]["mask_pixel_stride"] == 4
        for batch in demo_batches:
            client.post_batch(scene.id, batch)
        client.wait_for_batch(scene.id, demo_batches[-1].batch_id, timeout=300)

        pending = client.verifications(scene.id)
        assert pending and all(item.verification == "pending" for item in pending)
        item = pending[0]
        verdict = VerdictIn(verdict="confirm", source="operator", frame_id=item.best_frame)
        result = client.post_verdict(scene.id, item.track_id, verdict)
        assert result.track_id == item.track_id and result.events
        assert item.track_id not in [v.track_id for v in client.verifications(scene.id)]
        answered = client.verifications(scene.id, status="all")
        assert item.track_id in [v.track_id for v in answered]
        with pytest.raises(Conflict):  # a second verdict must name a new frame
            client.post_verdict(scene.id, item.track_id, verdict)

        queue = client.inspection_queue(scene.id)
        assert queue and queue[0].status == "queued"
        plan = client.plan(scene.id, RobotPose(x=1.0, y=1.0, yaw=0.0))
        assert plan.decision == "inspect" and plan.target is not None and plan.lock == "new"
        assert plan.event_seq is not None
        target = plan.target.fixture_id
        capture = InspectionIn(
            fixture_id=target, frames=demo_batches[-1].frames[:1], capture_id="cap-1"
        )
        inspection = client.post_inspection(scene.id, capture)
        assert inspection.capture_id == "cap-1" and inspection.fixture_id == target
        assert [i.capture_id for i in client.inspections(scene.id)] == ["cap-1"]

        package = client.freeze_baseline(scene.id)
        assert package.version == 1 and package.package["fixtures"]
        assert [b.version for b in client.baselines(scene.id)] == [1]
        assert client.baseline(scene.id, 1) == package
        delta = client.delta(scene.id, 1)
        assert delta.baseline.version == 1 and delta.events == []
        later = client.create_scene(
            "client-later", baseline=BaselineRef(scene_id=scene.id, version=1)
        )
        pinned = client.graph(later.id).nodes
        assert pinned and all(node.pinned for node in pinned)


def test_errors_of_the_real_service_are_typed(service: Service, filled: FilledScene) -> None:
    with Client(service.url) as client:
        with pytest.raises(ResourceNotFound) as missing:
            client.scene("no-such-scene")
        assert missing.value.status == 404 and missing.value.field == "scene_id"
        with pytest.raises(ResourceNotFound):
            client.explain(filled.scene_id, "trk-999999")
        with pytest.raises(InvalidRequest) as bad_query:
            client.graph(filled.scene_id, as_of=-5)
        assert bad_query.value.status == 422 and bad_query.value.field == "as_of"
        with pytest.raises(InvalidRequest) as bad_params:
            client.create_scene("bad", params={"visibility": {"no_such_parameter": 1}})
        assert bad_params.value.type == "/problems/invalid-params"
        assert bad_params.value.field is not None
        assert "no_such_parameter" in bad_params.value.field
        with pytest.raises(Forbidden) as not_admin:  # loopback access is never admin
            client.requeue_batch(filled.scene_id, filled.done[0].batch_id)
        assert not_admin.value.status == 403


def test_a_bad_observation_names_its_field(service: Service, demo_batches: list[BatchIn]) -> None:
    frame = demo_batches[0].frames[0]
    skewed = [list(row) for row in frame.pose]
    skewed[3] = [0.0, 0.0, 0.5, 1.0]
    batch = BatchIn(batch_id="bad-pose", frames=[frame.model_copy(update={"pose": skewed})])
    with Client(service.url) as client:
        paper = client.create_scene("client-paper", profile="paper")
        assert paper.params["existence"]["logodds_max"] == 30.0  # unclamped, as the paper
        assert client.create_scene("client-ours").params["existence"]["logodds_max"] == 1.5
        scene = client.create_scene("client-bad")
        with pytest.raises(InvalidRequest) as raised:
            client.post_batch(scene.id, batch)
        with pytest.raises(ResourceNotFound):  # nothing was stored
            client.batch(scene.id, "bad-pose")
    assert raised.value.field == "frames[0].pose"
    assert raised.value.fields == ["frames[0].pose"]
    assert "last row" in raised.value.detail


def test_the_async_client_reads_what_the_sync_one_does(
    service: Service, filled: FilledScene, demo_batches: list[BatchIn]
) -> None:
    async def session() -> None:
        async with AsyncClient(service.url) as client:
            assert (await client.health()).status == "ok"
            scene = await client.create_scene("client-async")
            assert scene.id in [s.id for s in await client.scenes()]
            assert (await client.scene(scene.id)).head_seq == 0
            for batch in demo_batches[:4]:
                assert (await client.post_batch(scene.id, batch)).status == "queued"
            done = await client.wait_for_batch(scene.id, demo_batches[3].batch_id, timeout=300)
            assert done.status == "done" and done.last_seq is not None
            assert await client.batch(scene.id, done.batch_id) == done
            events = [e async for e in client.events(scene.id, page_size=3)]
            assert [e.seq for e in events] == list(range(done.last_seq + 1))
            page = await client.events_page(scene.id, after=0, limit=2)
            assert [e.seq for e in page.events] == [1, 2] and page.next_after == 2
            graph = await client.graph(scene.id, include="all", as_of=done.last_seq)
            assert graph.nodes
            node = graph.nodes[0]
            assert (await client.track(scene.id, node.id)).track_id == node.id
            assert (await client.explain(scene.id, node.id)).track_id == node.id
            assert {t.track_id for t in await client.tracks(scene.id)} >= {node.id}
            assert (await client.occupancy(scene.id)).seq == done.last_seq
            assert (await client.occupancy_png(scene.id)).startswith(b"\x89PNG")
            assert isinstance(await client.verifications(scene.id, status="all"), list)
            assert isinstance(await client.inspection_queue(scene.id), list)
            assert await client.inspections(scene.id) == []
            preview = await client.preview_plan(scene.id, 1.0, 1.0)
            plan = await client.plan(scene.id, RobotPose(x=1.0, y=1.0, yaw=0.0))
            assert plan.decision == preview.decision

            # The sync client's filled scene reads the same through the async one.
            with Client(service.url) as sync:
                expected = sync.graph(filled.scene_id)
                expected_events = list(sync.events(filled.scene_id))
            assert await client.graph(filled.scene_id) == expected
            assert [e async for e in client.events(filled.scene_id, page_size=9)] == (
                expected_events
            )
            pending = await client.verifications(filled.scene_id)
            assert pending
            verdict = VerdictIn(verdict="reject", source="async-test", frame_id="f-async")
            result = await client.post_verdict(filled.scene_id, pending[-1].track_id, verdict)
            assert result.events
            package = await client.freeze_baseline(filled.scene_id)
            assert [b.version for b in await client.baselines(filled.scene_id)] == [package.version]
            assert await client.baseline(filled.scene_id, package.version) == package
            assert (await client.delta(filled.scene_id, package.version)).events == []
            fixture = next(n for n in expected.nodes if n.kind == "fixture")
            capture = InspectionIn(fixture_id=fixture.id, frames=demo_batches[-1].frames[:1])
            inspection = await client.post_inspection(filled.scene_id, capture)
            assert inspection.fixture_id == fixture.id
            with pytest.raises(ResourceNotFound):
                await client.scene("no-such-scene")
            with pytest.raises(InvalidRequest) as raised:
                await client.graph(scene.id, as_of=-5)
            assert raised.value.field == "as_of"
            with pytest.raises(Forbidden):
                await client.requeue_batch(scene.id, done.batch_id)

    asyncio.run(session())
