"""The service tests' client: the app on the container under test, from a loopback address."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.bootstrap import Container
from tests.clients import local_client


@pytest.fixture
def client(container: Container) -> Iterator[TestClient]:
    """The app (no worker thread: tests drain the queue themselves) as a local client sees it."""
    with local_client(create_app(container)) as test_client:
        yield test_client


@pytest.fixture
def scene_id(client: TestClient) -> str:
    """A fresh scene of the app."""
    return str(client.post("/v1/scenes", json={"name": "hall"}).json()["id"])
