"""The service tests' client (the app on the container under test, from a loopback address), and
the golden database of logs written by older code."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.bootstrap import Container, build_container
from service.settings import Settings
from service.store.engine import write_transaction
from tests.clients import local_client
from tests.golden_logs import BEFORE_EVENT_TOPICS, insert_rows


@pytest.fixture
def client(container: Container) -> Iterator[TestClient]:
    """The app (no worker thread: tests drain the queue themselves) as a local client sees it."""
    with local_client(create_app(container)) as test_client:
        yield test_client


@pytest.fixture
def scene_id(client: TestClient) -> str:
    """A fresh scene of the app."""
    return str(client.post("/v1/scenes", json={"name": "hall"}).json()["id"])


@pytest.fixture
def old_database(
    backend: str, request: pytest.FixtureRequest, tmp_path: Path
) -> Iterator[tuple[str, Container, list[str]]]:
    """(database url, container, scene ids by number): the golden rows of tests/resources, written
    by the code before event topics, in a fresh database (scene 2 started from scene 1's
    baseline v1)."""
    if backend == "sqlite":
        url = f"sqlite:///{tmp_path / 'old.db'}"
    else:
        server, schema = request.getfixturevalue("postgres_schema_url")
        url = f"{server}?options=-csearch_path%3D{schema}"
    settings = Settings(database_url=url, data_dir=tmp_path / "data", allow_anonymous_local=True)
    container = build_container(settings)
    with write_transaction(container.engine) as connection:
        scene_ids = insert_rows(connection, BEFORE_EVENT_TOPICS)
    try:
        yield url, container, scene_ids
    finally:
        container.engine.dispose()
