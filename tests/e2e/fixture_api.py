"""The fixture world over the HTTP API: a client on the app, the worker a test drives, and the
helpers that feed and read the scene (the simulator renders the world: callers check the eval
extra first).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.bootstrap import Container
from service.worker import Worker
from tests.clients import local_client
from tests.e2e.fixture_world import (
    DISCOVERY,
    ROOM,
    wire_batches,
)

Api = tuple[TestClient, Worker, Container]  # a client on the app, the worker it drives, the store


@pytest.fixture
def api(container: Container) -> Iterator[Api]:
    with local_client(create_app(container)) as client:
        yield client, Worker(container), container


def feed(
    client: TestClient, worker: Worker, scene_id: str, bodies: Sequence[dict[str, Any]]
) -> None:
    for body in bodies:
        assert client.post(f"/v1/scenes/{scene_id}/batches", json=body).status_code == 202
    worker.drain()
    for body in bodies:
        assert (
            client.get(f"/v1/scenes/{scene_id}/batches/{body['batch_id']}").json()["status"]
            == "done"
        )


def nodes(client: TestClient, scene_id: str, **params: str) -> list[dict[str, Any]]:
    graph = client.get(f"/v1/scenes/{scene_id}/graph", params=params).json()
    found: list[dict[str, Any]] = graph["nodes"]
    return found


def discovered(client: TestClient, worker: Worker, **kwargs: Any) -> str:
    scene_id: str = client.post("/v1/scenes", json={"name": "house"}).json()["id"]
    feed(client, worker, scene_id, wire_batches(ROOM, DISCOVERY, "d", **kwargs))
    return scene_id


def fixture_ids(client: TestClient, scene_id: str) -> dict[str, str]:
    return {n["label"]: n["id"] for n in nodes(client, scene_id) if n["kind"] == "fixture"}
