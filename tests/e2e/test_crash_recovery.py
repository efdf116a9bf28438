"""SIGKILL right after 20 accepted batches: on restart every batch is done exactly once."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.bootstrap import build_container
from service.settings import Settings
from service.worker import Worker
from tests.clients import local_client
from tests.conftest import store_backends
from tests.e2e.fault_run import free_port, wait_healthy
from tests.wire_scenes import batch

BATCHES = 20
PBDAG = [sys.executable, "-m", "service.cli"]
REPO = Path(__file__).resolve().parents[2]
# The graph's nodes, the event count of each batch, and every event's (type, track, state).
Outcome = tuple[list[dict[str, Any]], dict[str, int], list[tuple[Any, Any, Any]]]


def start(args: list[str], env: dict[str, str], log: Path) -> subprocess.Popen[bytes]:
    with log.open("ab") as handle:  # the child keeps its own descriptor
        return subprocess.Popen(
            [*PBDAG, *args], env=env, cwd=REPO, stdout=handle, stderr=subprocess.STDOUT
        )


def stream() -> list[dict[str, Any]]:
    """20 one-frame batches: the mug is seen, then taken away."""
    return [batch(f"b{i:02d}", i, mug=i < 8) for i in range(BATCHES)]


def outcome(client: httpx.Client | TestClient, scene_id: str) -> Outcome:
    """What must match an uninterrupted run: the graph and each batch's event count."""
    graph = client.get(f"/v1/scenes/{scene_id}/graph", params={"include": "all"}).json()
    nodes = [
        {k: n[k] for k in ("id", "label", "state", "p_exist", "center")} for n in graph["nodes"]
    ]
    events: list[dict[str, Any]] = []
    after: int | None = -1
    while after is not None:
        page = client.get(
            f"/v1/scenes/{scene_id}/events", params={"after": after, "limit": 1000}
        ).json()
        events += page["events"]
        after = page["next_after"]
    per_batch = Counter(e["batch_id"] for e in events if e["batch_id"])
    return nodes, dict(per_batch), [(e["type"], e["track_id"], e["state"]) for e in events]


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Outcome:
    """The uninterrupted run, in process."""
    container = build_container(
        Settings(data_dir=tmp_path_factory.mktemp("reference"), allow_anonymous_local=True)
    )
    with local_client(create_app(container)) as client:
        scene_id = client.post("/v1/scenes", json={"name": "crash"}).json()["id"]
        for body in stream():
            assert client.post(f"/v1/scenes/{scene_id}/batches", json=body).status_code == 202
        Worker(container).drain()
        return outcome(client, scene_id)


def run_with_kill(
    url: str, start_all: Callable[[Path], list[subprocess.Popen[bytes]]], log: Path
) -> Outcome:
    """Post 20 batches, SIGKILL every process right after the last 202, restart, wait for done."""
    processes = start_all(log)
    wait_healthy(url)
    with httpx.Client(base_url=url, timeout=30.0) as client:
        scene_id = client.post("/v1/scenes", json={"name": "crash"}).json()["id"]
        for body in stream():
            assert client.post(f"/v1/scenes/{scene_id}/batches", json=body).status_code == 202
        for process in processes:
            process.send_signal(signal.SIGKILL)
        for process in processes:
            process.wait()
        processes = start_all(log)
        try:
            wait_healthy(url)
            deadline = time.monotonic() + 120
            statuses: list[str] = []
            while time.monotonic() < deadline:
                statuses = [
                    client.get(f"/v1/scenes/{scene_id}/batches/b{i:02d}").json()["status"]
                    for i in range(BATCHES)
                ]
                if all(status == "done" for status in statuses):
                    break
                assert "dead" not in statuses, log.read_text()[-3000:]
                time.sleep(0.2)
            assert all(status == "done" for status in statuses), statuses
            return outcome(client, scene_id)
        finally:
            for process in processes:
                process.terminate()
            for process in processes:
                process.wait(timeout=30)


@pytest.mark.parametrize("backend", store_backends())
def test_sigkill_right_after_accepting_recovers_exactly_once(
    reference: Outcome, tmp_path: Path, backend: str, request: pytest.FixtureRequest
) -> None:
    """SQLite: `pbdag serve` with its worker. PostgreSQL: `serve --no-worker` and two `pbdag worker`."""
    port = free_port()
    env = {
        **os.environ,
        "PBDAG_DATA_DIR": str(tmp_path / "data"),
        "PBDAG_LEASE_SECONDS": "2",
        "PBDAG_ALLOW_ANONYMOUS_LOCAL": "true",  # this test's client is on 127.0.0.1
        "PBDAG_RATE_LIMIT_PER_MINUTE": "0",  # it polls 20 batch statuses five times a second
    }
    env.pop("PBDAG_DATABASE_URL", None)
    if backend == "sqlite":
        commands = [["serve", "--port", str(port)]]
    else:
        url, schema = request.getfixturevalue("postgres_schema_url")
        env["PBDAG_DATABASE_URL"] = f"{url}?options=-csearch_path%3D{schema}"
        commands = [["serve", "--port", str(port), "--no-worker"], ["worker"], ["worker"]]

    def start_all(log: Path) -> list[subprocess.Popen[bytes]]:
        return [start(command, env, log) for command in commands]

    assert (
        run_with_kill(f"http://127.0.0.1:{port}", start_all, tmp_path / "service.log") == reference
    )
