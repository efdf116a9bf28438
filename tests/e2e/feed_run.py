"""The change feed across a fleet: three API processes (`pbdag serve --no-worker`) and one worker
on one PostgreSQL database; one consumer per API process, reading the feed through the typed
client; batches posted round-robin while one API process is SIGKILLed and restarted; and one
consumer that connects and then reads nothing.

A consumer whose connection is lost resumes with Last-Event-ID on the next live API process.
Once every batch is done and every consumer has reached the head, the scene is quarantined:
each stream ends with `end`, and each consumer's iterator with it. Each process has its own data
directory (the blobs are in the database): nothing is shared but the database.
"""

from __future__ import annotations

import os
import socket
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import sqlalchemy as sa

from pbdag_client import Client, ServerError
from tests.e2e.fault_run import Fleet, bodies, free_port, wait_healthy

WRITE_TIMEOUT_S = 2.0  # PBDAG_STREAM_WRITE_TIMEOUT_SECONDS of the run
KILLED = "api-0"
EMBEDDING_LENGTH = 1024


@dataclass
class Consumer:
    """What one consumer received, and how often it had to resume on another process."""

    first_url: str
    seqs: list[int] = field(default_factory=list)
    switches: int = 0
    error: str | None = None

    @property
    def last(self) -> int:
        return self.seqs[-1] if self.seqs else -1


@dataclass
class FeedReport:
    """What the run did and found."""

    batches: int = 0
    kills: int = 0
    head: int = -1
    consumers: list[Consumer] = field(default_factory=list)
    stalled_ids: list[int] = field(default_factory=list)  # what the reader of nothing got
    stalled_closed: bool = False  # the server closed its connection
    stalled_bytes: int = 0
    stalled_dropped: bool = False  # its last message was `dropped`
    seconds: float = 0.0


def consume(
    scene_id: str, urls: list[str], start: int, into: Consumer, stop: threading.Event
) -> None:
    """Read the feed until it ends, resuming on the next process when one is gone."""
    index = start
    while not stop.is_set():
        try:
            with Client(urls[index], timeout=10) as client:
                for event in client.stream_events(scene_id, after=into.last, max_failures=3):
                    into.seqs.append(event.seq)
            return  # the stream ended: the scene was quarantined
        except (httpx.TransportError, ServerError):
            index = (index + 1) % len(urls)  # resumed with Last-Event-ID there
            into.switches += 1
        except Exception as error:  # reported, not swallowed
            into.error = repr(error)
            return


def stalled_reader(url: str, scene_id: str) -> socket.socket:
    """A connection that asks for the feed and will read nothing (a small receive buffer, so
    the server's writes block soon)."""
    host, port = url.removeprefix("http://").split(":")
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect((host, int(port)))
    request = f"GET /v1/scenes/{scene_id}/events/stream HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n"
    sock.sendall(request.encode())
    return sock


def drain(sock: socket.socket, timeout_s: float) -> tuple[bytes, bool]:
    """Everything the server sent, and whether it closed the connection within the timeout."""
    sock.settimeout(0.5)
    received = bytearray()
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            chunk = sock.recv(65536)
        except TimeoutError:
            continue
        if not chunk:
            return bytes(received), True
        received += chunk
    return bytes(received), False


def heavy_bodies(count: int) -> list[dict[str, Any]]:
    """One-frame batches (the mug in front of a wall) whose mug carries a 1024-value appearance
    embedding: the events are a few kB each, so that the feed outgrows the socket buffers of a
    consumer that reads nothing (Linux lets a loopback socket buffer grow to 4 MB) within the run."""
    embedding = [round(1.0 / 16.0 + 1e-9 * i, 12) for i in range(EMBEDDING_LENGTH)]
    templates = bodies(count)
    for body in templates:
        for detection in body["frames"][0]["detections"]:
            detection["embedding"] = embedding
    return templates


def post_all(urls: list[str], scene_id: str, count: int, fleet: Fleet, report: FeedReport) -> None:
    """`count` batches round-robin over the APIs (skipping one that is down); SIGKILL and
    restart KILLED at a third and two thirds of the way."""
    templates = heavy_bodies(6)
    kill_at = {count // 3, 2 * count // 3}
    clients = [httpx.Client(base_url=url, timeout=10) for url in urls]
    try:
        for number in range(count):
            if number in kill_at:
                fleet.kill(KILLED)
                report.kills += 1
                fleet.start(KILLED)  # back in a few seconds; the consumers resume elsewhere
            body: dict[str, Any] = {**templates[number % 6], "batch_id": f"feed-{number:04d}"}
            attempt = number
            while True:
                http = clients[attempt % len(clients)]
                try:
                    answer = http.post(f"/v1/scenes/{scene_id}/batches", json=body)
                except httpx.TransportError:
                    answer = None
                if answer is not None and answer.status_code in (200, 202):
                    break
                if answer is not None and answer.status_code not in (429, 500, 503):
                    raise RuntimeError(f"{answer.status_code} {answer.text}")
                attempt += 1
                time.sleep(0.05)
            report.batches += 1
    finally:
        for http in clients:
            http.close()


def head_when_settled(engine: sa.Engine, scene_id: str, timeout_s: float) -> int:
    """The scene's head once no batch of it is queued or running."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with engine.connect() as connection:
            waiting = connection.execute(
                sa.text(
                    "SELECT count(*) FROM batches WHERE scene_id = :s AND status NOT IN "
                    "('done', 'dead')"
                ),
                {"s": scene_id},
            ).scalar_one()
            head = connection.execute(
                sa.text("SELECT head_seq FROM scenes WHERE id = :s"), {"s": scene_id}
            ).scalar_one()
        if waiting == 0:
            return int(head)
        time.sleep(0.2)
    raise RuntimeError(f"the queue did not settle within {timeout_s} s")


def run_feed_fleet(database_url: str, data_dir: Path, batches: int = 500) -> FeedReport:
    """Run the fleet (see the module doc) and report what each consumer received."""
    started = time.monotonic()
    ports = [free_port() for _ in range(3)]
    urls = [f"http://127.0.0.1:{port}" for port in ports]
    base_env = {
        **os.environ,
        "PBDAG_DATABASE_URL": database_url,
        "PBDAG_ALLOW_ANONYMOUS_LOCAL": "true",
        "PBDAG_RATE_LIMIT_PER_MINUTE": "0",
        "PBDAG_STREAM_POLL_SECONDS": "0.05",
        "PBDAG_STREAM_HEARTBEAT_SECONDS": "1",
        "PBDAG_STREAM_WRITE_TIMEOUT_SECONDS": str(WRITE_TIMEOUT_S),
        "PBDAG_WORKER_POLL_SECONDS": "0.02",
        "PBDAG_LEASE_SECONDS": "5",
        "PBDAG_MAX_QUEUED_BATCHES_PER_SCENE": "1000",
    }
    commands = {
        f"api-{i}": ["serve", "--port", str(port), "--no-worker"] for i, port in enumerate(ports)
    }
    commands["worker"] = ["worker"]
    envs = {name: {**base_env, "PBDAG_DATA_DIR": str(data_dir / name)} for name in commands}
    data_dir.mkdir(parents=True, exist_ok=True)
    fleet = Fleet(commands, envs, data_dir / "feed-run.log")
    engine = sa.create_engine(database_url)
    report = FeedReport()
    stop = threading.Event()
    threads: list[threading.Thread] = []
    stalled: socket.socket | None = None
    try:
        for url in urls:
            wait_healthy(url)
        with httpx.Client(base_url=urls[1], timeout=10) as setup:
            scene_id = setup.post("/v1/scenes", json={"name": "feed"}).json()["id"]
        stalled = stalled_reader(urls[2], scene_id)
        for index, url in enumerate(urls):
            consumer = Consumer(url)
            report.consumers.append(consumer)
            thread = threading.Thread(target=consume, args=(scene_id, urls, index, consumer, stop))
            threads.append(thread)
            thread.start()
        post_all(urls, scene_id, batches, fleet, report)
        report.head = head_when_settled(engine, scene_id, 120)
        deadline = time.monotonic() + 30
        while any(c.last < report.head and c.error is None for c in report.consumers):
            if time.monotonic() > deadline:
                break
            time.sleep(0.1)
        with engine.begin() as connection:  # every stream ends with `end`
            connection.execute(
                sa.text("UPDATE scenes SET quarantined = 'end of the run' WHERE id = :s"),
                {"s": scene_id},
            )
        for thread in threads:
            thread.join(timeout=30)
        received, report.stalled_closed = drain(stalled, 10)
        report.stalled_bytes = len(received)
        report.stalled_dropped = b"event: dropped" in received[-1000:]
        report.stalled_ids = [
            int(line[4:])
            for line in received.decode(errors="replace").split("\n")
            if line.startswith("id: ")
        ]
    finally:
        stop.set()
        if stalled is not None:
            stalled.close()
        fleet.stop()
        engine.dispose()
    report.seconds = time.monotonic() - started
    return report
