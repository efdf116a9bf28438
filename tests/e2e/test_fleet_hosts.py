"""A fleet on several hosts: `pbdag serve --no-worker` and two `pbdag worker`s, each with its own
data directory, sharing only the PostgreSQL URL. 50 batches; one worker is SIGKILLed while it
holds a batch; every batch is done, its events appended once, and `pbdag rebuild` finds no
difference."""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from pathlib import Path

import httpx
import pytest
import sqlalchemy as sa

from tests.conftest import store_backends
from tests.e2e.fault_run import PBDAG, REPO, FaultReport, check_log, free_port, wait_healthy
from tests.wire_scenes import batch

BATCHES = 50
SCENES = 2

pytestmark = [
    pytest.mark.slow,
    pytest.mark.postgres,
    pytest.mark.skipif("postgres" not in store_backends(), reason="needs PostgreSQL"),
]


def start(args: list[str], env: dict[str, str], log: Path) -> subprocess.Popen[bytes]:
    with log.open("ab") as handle:  # the child keeps its own descriptor
        return subprocess.Popen(
            [*PBDAG, *args], env=env, cwd=REPO, stdout=handle, stderr=subprocess.STDOUT
        )


def test_api_and_two_workers_on_three_hosts_share_only_postgres(
    tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    url, schema = request.getfixturevalue("postgres_schema_url")
    database_url = f"{url}?options=-csearch_path%3D{schema}"
    port = free_port()
    base = {key: value for key, value in os.environ.items() if not key.startswith("PBDAG_")}
    shared = {
        "PBDAG_DATABASE_URL": database_url,  # the only thing the three processes share
        "PBDAG_LEASE_SECONDS": "2",
        "PBDAG_RETRY_BASE_SECONDS": "0.2",
        "PBDAG_RETRY_MAX_SECONDS": "1",
        "PBDAG_ALLOW_ANONYMOUS_LOCAL": "true",
        "PBDAG_RATE_LIMIT_PER_MINUTE": "0",
    }
    hosts = {name: tmp_path / name for name in ("api-host", "worker-host-1", "worker-host-2")}
    env = {name: {**base, **shared, "PBDAG_DATA_DIR": str(path)} for name, path in hosts.items()}
    log = tmp_path / "fleet.log"
    api = start(["serve", "--port", str(port), "--no-worker"], env["api-host"], log)
    victim = start(["worker"], env["worker-host-1"], log)
    survivor = start(["worker"], env["worker-host-2"], log)
    processes = [api, victim, survivor]
    engine = sa.create_engine(url, connect_args={"options": f"-csearch_path={schema}"})
    try:
        base_url = f"http://127.0.0.1:{port}"
        wait_healthy(base_url)
        with httpx.Client(base_url=base_url, timeout=30.0) as http:
            scenes = [
                http.post("/v1/scenes", json={"name": f"host-{i}"}).json()["id"]
                for i in range(SCENES)
            ]
            posted: dict[str, set[str]] = {scene: set() for scene in scenes}
            answers: list[httpx.Response] = []

            def post_all() -> None:
                with httpx.Client(base_url=base_url, timeout=30.0) as poster:
                    for i in range(BATCHES):
                        scene = scenes[i % SCENES]
                        body = batch(f"b{i:02d}", i // SCENES, mug=(i // SCENES) % 10 < 6)
                        answers.append(poster.post(f"/v1/scenes/{scene}/batches", json=body))
                        posted[scene].add(body["batch_id"])

            # Post while watching: the workers may drain the queue as fast as it fills. SIGKILL
            # the victim while it holds a batch: its lease must expire and the batch be done by
            # the survivor, once.
            poster = threading.Thread(target=post_all)
            poster.start()
            try:
                held = wait_for_batch_held_by(engine, victim.pid, timeout=60)
                victim.send_signal(signal.SIGKILL)
                victim.wait()
            finally:
                poster.join()
            assert [r.status_code for r in answers] == [202] * BATCHES, answers[-1].text
            statuses = wait_until_settled(http, posted, timeout=120, log=log)
            assert set(statuses.values()) == {"done"}, statuses
            report = FaultReport(backend="postgres")
            for scene in scenes:
                check_log(http, scene, statuses, report)
            assert (report.gaps, report.duplicates) == (0, 0), report
            assert report.events >= BATCHES
            with engine.connect() as connection:
                attempts = connection.execute(
                    sa.text("SELECT attempts FROM batches WHERE id = :id"), {"id": held}
                ).scalar()
                stored_blobs = connection.execute(sa.text("SELECT count(*) FROM blobs")).scalar()
            assert attempts is not None and attempts >= 2  # the victim's attempt, then another
            assert stored_blobs == BATCHES  # the raw batches are in the database...
        assert "raw batches in the database (PBDAG_BLOB_BACKEND=auto)" in log.read_text()
        for path in hosts.values():  # ...and no process wrote a blob to its own disk
            assert not (path / "blobs").exists(), sorted(path.rglob("*"))
    finally:
        for process in processes:
            if process.poll() is None:
                process.terminate()
        for process in processes:
            process.wait(timeout=30)
        engine.dispose()
    rebuild = subprocess.run(
        [*PBDAG, "rebuild"],
        env=env["worker-host-2"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert rebuild.returncode == 0, rebuild.stdout + rebuild.stderr
    assert "rebuild: no difference" in rebuild.stdout


def wait_for_batch_held_by(engine: sa.Engine, pid: int, timeout: float) -> int:
    """The row id of a batch running under the worker process `pid` (its name is host:pid:...)."""
    deadline = time.monotonic() + timeout
    query = sa.text(
        "SELECT id FROM batches WHERE status = 'running' AND lease_owner LIKE :owner LIMIT 1"
    )
    with engine.connect() as connection:
        while time.monotonic() < deadline:
            held = connection.execute(query, {"owner": f"%:{pid}:%"}).scalar()
            connection.rollback()
            if held is not None:
                return int(held)
            time.sleep(0.005)
    raise AssertionError(f"worker {pid} never held a batch within {timeout} s")


def wait_until_settled(
    http: httpx.Client, posted: dict[str, set[str]], timeout: float, log: Path
) -> dict[tuple[str, str], str]:
    """Every batch's status once none is queued, running or failed (or at the timeout)."""
    deadline = time.monotonic() + timeout
    statuses: dict[tuple[str, str], str] = {}
    while time.monotonic() < deadline:
        statuses = {
            (scene, batch_id): http.get(f"/v1/scenes/{scene}/batches/{batch_id}").json()["status"]
            for scene, batch_ids in posted.items()
            for batch_id in sorted(batch_ids)
        }
        assert "dead" not in statuses.values(), log.read_text()[-3000:]
        if all(status == "done" for status in statuses.values()):
            break
        time.sleep(0.3)
    return statuses
