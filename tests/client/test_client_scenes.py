"""Renaming and deleting scenes through the typed client, sync and async, against a real
uvicorn server (no simulator needed)."""

from __future__ import annotations

import asyncio

import pydantic
import pytest

from pbdag_client import AsyncClient, Client, Forbidden, InvalidRequest, ResourceNotFound
from service.auth import create_token
from tests.client.conftest import Service


def admin_token(service: Service) -> str:
    return create_token(service.container.engine, "operator", ["admin"]).token


def test_the_client_renames_and_deletes_a_scene(service: Service) -> None:
    with Client(service.url) as client, Client(service.url, admin_token(service)) as admin:
        scene = client.create_scene("sim-demo")
        renamed = client.rename_scene(scene.id, "sim-demo, first try")
        assert (renamed.id, renamed.name, renamed.head_seq) == (scene.id, "sim-demo, first try", 1)
        assert client.scene(scene.id).name == "sim-demo, first try"
        assert [e.type for e in client.events(scene.id)] == ["scene_created", "scene_renamed"]
        with pytest.raises(pydantic.ValidationError):  # checked before it is sent
            client.rename_scene(scene.id, "")
        assert client.scene(scene.id).head_seq == 1

        with pytest.raises(Forbidden):  # anonymous local access never administers
            client.delete_scene(scene.id, confirm=scene.id)
        with pytest.raises(InvalidRequest) as unconfirmed:
            admin.delete_scene(scene.id, confirm="sim-demo")
        assert unconfirmed.value.field == "confirm"
        assert client.scene(scene.id).head_seq == 1  # nothing deleted
        deleted = admin.delete_scene(scene.id, confirm=scene.id)
        assert (deleted.scene_id, deleted.events, deleted.batches) == (scene.id, 2, 0)
        with pytest.raises(ResourceNotFound):
            client.scene(scene.id)


def test_the_async_client_renames_and_deletes_a_scene(service: Service) -> None:
    token = admin_token(service)

    async def session() -> None:
        async with AsyncClient(service.url, token) as client:
            scene = await client.create_scene("kitchen")
            renamed = await client.rename_scene(scene.id, "kitchen (old)")
            assert renamed.name == "kitchen (old)" and renamed.head_seq == 1
            with pytest.raises(InvalidRequest):
                await client.delete_scene(scene.id, confirm="")
            deleted = await client.delete_scene(scene.id, confirm=scene.id)
            assert deleted.scene_id == scene.id and deleted.events == 2
            assert scene.id not in [s.id for s in await client.scenes()]

    asyncio.run(session())
