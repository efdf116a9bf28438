"""PostgreSQL connections terminated at random while clients post and read: every answer is a
success, a 429 or a 503 with Retry-After (never a 500), the API and the worker reconnect, and
after the clients retry what was refused no event is lost or duplicated."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest
import sqlalchemy as sa

from service.app import create_app
from service.bootstrap import build_container
from service.settings import Settings
from service.store.engine import make_engine
from service.worker import Worker
from tests.clients import local_client
from tests.conftest import POSTGRES_URL, store_backends
from tests.service.invariants import blobs_agree_with_rows, projections_equal_a_replay
from tests.wire_scenes import batch

pytestmark = [
    pytest.mark.postgres,
    pytest.mark.skipif("postgres" not in store_backends(), reason="needs PostgreSQL"),
]
VICTIM = "pbdag-connection-loss"
ROUNDS = 40


def terminate_until(stop: threading.Event, admin: sa.Engine, killed: list[int]) -> None:
    """Terminate the service's connections every 50 ms (mid-request, for many of them)."""
    query = sa.text(
        "SELECT count(pg_terminate_backend(pid)) FROM pg_stat_activity "
        "WHERE application_name = :name"
    )
    with admin.connect() as connection:
        while not stop.is_set():
            killed.append(int(connection.execute(query, {"name": VICTIM}).scalar() or 0))
            time.sleep(0.05)


def test_terminated_connections_answer_503_with_retry_after_and_lose_nothing(
    request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    url, schema = request.getfixturevalue("postgres_schema_url")
    engine = make_engine(
        url, connect_args={"options": f"-csearch_path={schema}", "application_name": VICTIM}
    )
    settings = Settings(
        data_dir=tmp_path / "data", allow_anonymous_local=True, rate_limit_per_minute=0
    )
    container = build_container(settings, engine=engine)
    admin = sa.create_engine(POSTGRES_URL, isolation_level="AUTOCOMMIT")
    stop, killed = threading.Event(), list[int]()
    answers: dict[int, int] = {}
    try:
        with local_client(create_app(container)) as client:
            scene_id = client.post("/v1/scenes", json={"name": "cut"}).json()["id"]
            killer = threading.Thread(target=terminate_until, args=(stop, admin, killed))
            killer.start()
            for index in range(ROUNDS):
                for response in (
                    client.post(f"/v1/scenes/{scene_id}/batches", json=batch(f"b{index}", index)),
                    client.get(f"/v1/scenes/{scene_id}/graph"),
                ):
                    answers[response.status_code] = answers.get(response.status_code, 0) + 1
                    if response.status_code == 503:
                        assert response.headers["retry-after"].isdigit()
                        assert response.headers["content-type"] == "application/problem+json"
            stop.set()
            killer.join()
            assert 500 not in answers, answers
            assert sum(killed) > 0 and answers.get(503, 0) > 0, (killed, answers)
            for index in range(ROUNDS):  # the clients retry; a batch stored already is a 200
                response = client.post(
                    f"/v1/scenes/{scene_id}/batches", json=batch(f"b{index}", index)
                )
                assert response.status_code in (200, 202), response.text[:300]
        assert Worker(container).drain() >= 0
        counts = container.queue.counts(scene_id)
        assert counts == {"done": ROUNDS}, counts
        records = sorted(container.queue.of_scene(scene_id), key=lambda r: r.first_seq or 0)
        seqs = [
            seq
            for r in records
            if r.first_seq is not None and r.last_seq is not None
            for seq in range(r.first_seq, r.last_seq + 1)
        ]
        logged = [event.seq for event in container.log.read(scene_id) if event.batch_id]
        assert seqs == logged, "an event lost, duplicated or outside its batch"
        assert len(blobs_agree_with_rows(container, scene_id)) == ROUNDS
        projections_equal_a_replay(container, scene_id)
    finally:
        stop.set()
        engine.dispose()
        admin.dispose()
