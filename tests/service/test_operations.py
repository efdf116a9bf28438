"""Operations: /metrics in the Prometheus text format, JSON logs with scene and batch ids, and
`pbdag serve --help` naming every default and variable."""

from __future__ import annotations

import json
import logging
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from prometheus_client.parser import text_string_to_metric_families

from core.decide import decide as real_decide
from core.events import Event
from core.observation import Batch
from core.state import SceneState
from service.app import create_app
from service.auth import create_token
from service.bootstrap import Container, build_container
from service.cli import main
from service.logs import StderrHandler, configure_logging
from service.settings import Settings
from service.worker import Worker
from tests.clients import LOCAL_BASE_URL, local_client
from tests.wire_scenes import batch

Samples = dict[tuple[str, tuple[tuple[str, str], ...]], float]


def scrape(client: TestClient, **headers: str) -> Samples:
    """Every sample of /metrics, parsed by the Prometheus text parser."""
    response = client.get("/metrics", headers=headers)
    assert response.status_code == 200, response.text
    assert response.headers["content-type"].startswith("text/plain")
    return {
        (sample.name, tuple(sorted(sample.labels.items()))): sample.value
        for family in text_string_to_metric_families(response.text)
        for sample in family.samples
    }


def test_metrics_count_batches_events_latencies_and_dead_letters(
    container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    now = [1000.0]
    monkeypatch.setattr(container.queue, "clock", lambda: now[0])
    monkeypatch.setattr(container.metrics.queue_collector, "clock", lambda: now[0])

    def poisoned(state: SceneState, observed: Batch) -> list[Event]:
        if observed.batch_id == "poison":
            raise RuntimeError("a bug in deciding")
        return real_decide(state, observed)

    monkeypatch.setattr("service.worker.decide", poisoned)
    with local_client(create_app(container)) as client:
        scene_id = client.post("/v1/scenes", json={"name": "ops"}).json()["id"]
        before = scrape(client)
        assert before[("pbdag_events_appended_total", ())] == 0
        assert before[("pbdag_queue_oldest_age_seconds", ())] == 0
        for batch_id, index in (("b0", 0), ("b1", 1), ("poison", 2), ("b3", 3)):
            posted = client.post(f"/v1/scenes/{scene_id}/batches", json=batch(batch_id, index))
            assert posted.status_code == 202
        now[0] = 1042.0
        waiting = scrape(client)
        assert waiting[("pbdag_batches", (("status", "queued"),))] == 4
        assert waiting[("pbdag_queue_oldest_age_seconds", ())] == 42.0
        assert Worker(container).drain() == 4
        after = scrape(client)
    head = container.log.scene(scene_id).head_seq
    assert after[("pbdag_batches", (("status", "done"),))] == 3
    assert after[("pbdag_batches", (("status", "dead"),))] == 1
    assert after[("pbdag_batches", (("status", "queued"),))] == 0
    assert after[("pbdag_queue_oldest_age_seconds", ())] == 0
    assert after[("pbdag_dead_letters_total", ())] == 1
    assert after[("pbdag_batches_processed_total", (("outcome", "done"),))] == 3
    assert after[("pbdag_batches_processed_total", (("outcome", "dead"),))] == 1
    # Every event after scene_created (seq 0) was appended by this process (the gap included).
    assert after[("pbdag_events_appended_total", ())] == head
    assert after[("pbdag_decide_seconds_count", ())] == 4  # the poisoned batch was timed too
    assert after[("pbdag_append_seconds_count", ())] == 3
    assert after[("pbdag_decide_seconds_sum", ())] > 0
    assert after[("pbdag_decide_seconds_bucket", (("le", "+Inf"),))] == 4


def test_metrics_need_the_read_scope_off_loopback(container: Container) -> None:
    container.settings.allow_anonymous_local = False
    app = create_app(container)
    with TestClient(app, base_url=LOCAL_BASE_URL, client=("192.168.1.50", 40000)) as lan:
        refused = lan.get("/metrics")
        assert refused.status_code == 401
        assert refused.headers["content-type"] == "application/problem+json"
        token = create_token(container.engine, "prometheus", ["read"]).token
        samples = scrape(lan, Authorization=f"Bearer {token}")
    assert ("pbdag_batches", (("status", "queued"),)) in samples


@pytest.fixture
def json_logs() -> Iterator[None]:
    """JSON log lines on standard error for the test; the logging set-up restored after it."""
    root = logging.getLogger()
    level = root.level
    configure_logging("json")
    try:
        yield
    finally:
        for handler in [h for h in root.handlers if isinstance(h, StderrHandler)]:
            root.removeHandler(handler)
        root.setLevel(level)


def test_worker_and_api_log_json_lines_with_scene_and_batch_ids(
    container: Container, json_logs: None, capsys: pytest.CaptureFixture[str]
) -> None:
    with local_client(create_app(container)) as client:
        scene_id = client.post("/v1/scenes", json={"name": "logs"}).json()["id"]
        assert client.post(f"/v1/scenes/{scene_id}/batches", json=batch("b0", 0)).status_code == 202
        Worker(container).drain()
    records = [json.loads(line) for line in capsys.readouterr().err.splitlines() if line]
    assert records and all({"time", "level", "logger", "message"} <= set(r) for r in records)
    done = [r for r in records if r["logger"] == "pbdag.worker" and "done" in r["message"]]
    assert len(done) == 1
    assert (done[0]["scene_id"], done[0]["batch_id"], done[0]["level"]) == (scene_id, "b0", "INFO")
    queued = [r for r in records if r["logger"] == "pbdag.api" and "queued" in r["message"]]
    assert [(r["scene_id"], r["batch_id"]) for r in queued] == [(scene_id, "b0")]
    access = [r for r in records if r["message"].startswith("POST /v1/scenes/")]
    assert access and access[0]["scene_id"] == scene_id and " 202 " in access[0]["message"]


def test_pbdag_worker_log_format_json_from_the_command_line(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    json_logs: None,
) -> None:
    monkeypatch.setenv("PBDAG_DATA_DIR", str(tmp_path))
    monkeypatch.delenv("PBDAG_DATABASE_URL", raising=False)
    container = build_container(Settings(allow_anonymous_local=True))
    with local_client(create_app(container)) as client:
        scene_id = client.post("/v1/scenes", json={"name": "cli"}).json()["id"]
        assert client.post(f"/v1/scenes/{scene_id}/batches", json=batch("b7", 7)).status_code == 202
    capsys.readouterr()
    assert main(["worker", "--drain", "--log-format", "json"]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().err.splitlines() if line]
    assert any(r.get("batch_id") == "b7" and r.get("scene_id") == scene_id for r in lines)
    assert any(r["message"] == f"database sqlite:///{tmp_path / 'pbdag.db'}" for r in lines)


def test_serve_help_names_every_default_and_variable(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exited:
        main(["serve", "--help"])
    assert exited.value.code == 0
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps lines
    for option in (
        "--host HOST address to listen on (default: 127.0.0.1; env PBDAG_HOST)",
        "--port PORT port to listen on (default: 8000; env PBDAG_PORT)",
        "--no-worker API only, no worker in this process; run `pbdag worker` separately "
        "(env PBDAG_RUN_WORKER=false; default: a worker runs in the API process)",
        "(default: text; env PBDAG_LOG_FORMAT)",
        "(default: INFO; env PBDAG_LOG_LEVEL)",
    ):
        assert option in text
    for field in Settings.model_fields:
        assert f"PBDAG_{field.upper()}=" in text
    assert "PBDAG_LEASE_SECONDS=60.0" in text
    assert "PBDAG_ALLOWED_HOSTS=localhost,127.0.0.1,::1" in text
    assert "PBDAG_DATA_DIR=data" in text
