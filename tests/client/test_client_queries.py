"""The questions in the robot's terms through the typed client, sync and async, against a real
uvicorn server: objects, similar, history, and as_of_time beside every as_of."""

from __future__ import annotations

import asyncio
import math
from datetime import UTC, datetime

import pytest

from api_schema import BatchIn
from pbdag_client import AsyncClient, Client, InvalidRequest, ResourceNotFound
from tests.client.conftest import FilledScene, Service


def between(demo_batches: list[BatchIn], index: int) -> float:
    """A time on the robot's clock after batch `index` and before the next one."""
    now = max(frame.timestamp for frame in demo_batches[index].frames)
    then = min(frame.timestamp for frame in demo_batches[index + 1].frames)
    assert now < then
    return (now + then) / 2


def test_objects_similar_and_history_through_the_client(
    service: Service, filled: FilledScene
) -> None:
    with Client(service.url) as client:
        page = client.objects(filled.scene_id)
        assert page.objects and page.seq == client.scene(filled.scene_id).head_seq
        assert [o.track_id for o in page.objects] == sorted(o.track_id for o in page.objects)
        first = page.objects[0]
        near = client.objects(
            filled.scene_id, near=(first.center[0], first.center[1], first.center[2]), radius=1.0
        )
        assert near.objects[0].track_id == first.track_id and near.objects[0].distance == 0.0
        assert all(o.distance is not None and o.distance <= 1.0 for o in near.objects)
        assert all(math.dist(o.center, first.center) <= 1.0 for o in near.objects)
        one = client.objects(filled.scene_id, limit=1)
        assert one.objects == page.objects[:1]
        if len(page.objects) > 1:
            assert one.next_after == first.track_id
            rest = client.objects(filled.scene_id, after=one.next_after, as_of=one.seq)
            assert rest.objects == page.objects[1:]

        belief = client.track(filled.scene_id, first.track_id)
        assert belief.embedding is not None  # the simulated detector gives each object a look
        found = client.similar(filled.scene_id, belief.embedding, k=2)
        assert found.matches[0].track_id == first.track_id
        assert found.matches[0].score == pytest.approx(1.0)
        assert len(found.matches) == min(2, len(page.objects))

        history = client.history(filled.scene_id, first.track_id)
        assert history.spans and history.spans[-1].to_seq <= history.seq
        assert history.spans[-1].parent == first.parent and history.spans[-1].state == first.state
        with pytest.raises(ResourceNotFound):
            client.history(filled.scene_id, "trk-999999")
        with pytest.raises(InvalidRequest) as raised:  # the service knows the dimension
            client.similar(filled.scene_id, [1.0, 0.0])
        assert raised.value.fields == ["embedding"]
        with pytest.raises(ValueError, match="zero vector"):  # checked before it is sent
            client.similar(filled.scene_id, [0.0, 0.0])


def test_as_of_time_beside_every_as_of(
    service: Service, filled: FilledScene, demo_batches: list[BatchIn]
) -> None:
    after_first = filled.done[0].last_seq
    at = between(demo_batches, 0)
    moment = datetime.fromtimestamp(at, UTC)
    with Client(service.url) as client:
        sid = filled.scene_id
        for when in (at, moment, moment.isoformat()):
            assert client.graph(sid, as_of_time=when).seq == after_first
        node = client.graph(sid, as_of=after_first, include="all").nodes[0]
        assert client.track(sid, node.id, as_of_time=at).seq == after_first
        assert client.occupancy(sid, as_of_time=at).seq == after_first
        assert client.occupancy_png(sid, as_of_time=at).startswith(b"\x89PNG")
        assert client.preview_plan(sid, 1.0, 1.0, as_of_time=at).seq == after_first
        assert client.objects(sid, as_of_time=at).seq == after_first
        assert client.history(sid, node.id, as_of_time=at).seq == after_first
        changed = client.objects(sid, changed_since_time=at)
        assert {o.track_id for o in changed.objects} == {
            o.track_id for o in client.objects(sid, changed_since=after_first).objects
        }
        with pytest.raises(InvalidRequest) as raised:
            client.graph(sid, as_of=1, as_of_time=at)
        assert raised.value.fields == ["as_of_time"]
        with pytest.raises(InvalidRequest):
            client.graph(sid, as_of_time=datetime(2026, 12, 3))  # no timezone

        async def read() -> None:
            async with AsyncClient(service.url) as aclient:
                assert (await aclient.graph(sid, as_of_time=at)).seq == after_first
                assert (await aclient.track(sid, node.id, as_of_time=at)).seq == after_first
                assert (await aclient.occupancy(sid, as_of_time=at)).seq == after_first
                png = await aclient.occupancy_png(sid, as_of_time=at)
                assert png.startswith(b"\x89PNG")
                preview = await aclient.preview_plan(sid, 1.0, 1.0, as_of_time=at)
                assert preview.seq == after_first
                assert await aclient.objects(sid, as_of_time=at) == client.objects(
                    sid, as_of_time=at
                )
                assert await aclient.history(sid, node.id) == client.history(sid, node.id)
                some = client.objects(sid).objects[0]
                look = client.track(sid, some.track_id).embedding or []
                assert await aclient.similar(sid, look, k=3) == client.similar(sid, look, k=3)

        asyncio.run(read())
