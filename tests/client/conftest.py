"""A real service for the client: uvicorn on a free loopback port in a thread, with its worker,
on a temporary SQLite store; and a scene the simulated robot's stream has filled."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import pytest

from api_schema import BatchIn, BatchStatus
from pbdag_client import Client
from service.app import create_app
from service.bootstrap import Container, build_container
from service.settings import Settings
from tests.eval_extra import require_eval_extra
from tests.live_server import served

# 40 frames of the demo room: fixtures confirmed, objects on them, verdicts waited for.
STREAM_FRAMES = 40


@dataclass(frozen=True)
class Service:
    """A running service: its URL and its store."""

    url: str
    container: Container


@contextmanager
def serving(settings: Settings) -> Iterator[Service]:
    """The API and its worker served by uvicorn on 127.0.0.1 (a free port) until the block ends."""
    container = build_container(settings)
    try:
        with served(create_app(container, run_worker=True)) as url:
            yield Service(url, container)
    finally:
        container.engine.dispose()


def open_settings(data_dir: Path) -> Settings:
    """Loopback clients need no token; no rate limit (the tests poll fast)."""
    return Settings(data_dir=data_dir, allow_anonymous_local=True, rate_limit_per_minute=0)


@pytest.fixture(scope="session")
def demo_batches() -> list[BatchIn]:
    """The demo room's stream, two frames a batch, as the robot posts it (rendered by the
    simulator: the tests using it skip, saying so, in an install without the eval extra)."""
    require_eval_extra()
    from sim import DEMO_SCENARIO
    from sim.scenario import load_scenario
    from sim.stream import simulate, wire_batches

    run = simulate(load_scenario(DEMO_SCENARIO, frames=STREAM_FRAMES), seed=7)
    return [BatchIn.model_validate(body) for _, body in wire_batches(run, 2)]


@pytest.fixture(scope="module")
def service(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Service]:
    """A service open to loopback clients."""
    with serving(open_settings(tmp_path_factory.mktemp("client-service"))) as running:
        yield running


@dataclass(frozen=True)
class FilledScene:
    """A scene of the service with the demo stream applied, and the answers of its batches."""

    scene_id: str
    posted: list[BatchStatus]
    done: list[BatchStatus]


@pytest.fixture(scope="module")
def filled(service: Service, demo_batches: list[BatchIn]) -> FilledScene:
    """The demo stream posted through the client, every batch waited for."""
    with Client(service.url) as client:
        scene = client.create_scene("client-demo")
        posted = [client.post_batch(scene.id, batch) for batch in demo_batches]
        done = [client.wait_for_batch(scene.id, b.batch_id, timeout=300) for b in demo_batches]
    return FilledScene(scene.id, posted, done)
