"""The live change feed, `GET /v1/scenes/{id}/events/stream`, served by uvicorn on each backend:
catch-up then live, Last-Event-ID, filters, heartbeats, the end of a deleted or quarantined
scene, the stream limit, a disconnect, and a consumer that takes nothing."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator, MutableMapping
from pathlib import Path
from typing import Any

import anyio
import httpx
import pytest
import sqlalchemy as sa
from fastapi import FastAPI

from core.events import Event
from core.params import Params
from pbdag_client import Client, InvalidRequest
from service.app import create_app
from service.bootstrap import Container, build_container
from service.settings import Settings
from service.store.engine import write_transaction
from service.store.errors import ConcurrencyConflict, StoreUnavailable
from service.store.notifications import EVENTS_CHANNEL
from service.store.tables import events, scenes, snapshots, tracks
from tests.conftest import engine_for
from tests.live_server import served
from tests.service.minimal_events import added

WRITE_TIMEOUT_S = 0.5
HEARTBEAT_S = 0.3


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    """Fast polls, heartbeats and write timeouts; two streams a process."""
    return Settings(
        data_dir=tmp_path / "data",
        allow_anonymous_local=True,
        rate_limit_per_minute=0,
        stream_poll_seconds=0.02,
        stream_heartbeat_seconds=HEARTBEAT_S,
        stream_write_timeout_seconds=WRITE_TIMEOUT_S,
        max_streams=2,
    )


class Scene:
    """A scene of the container, and appends to it through the unit of work."""

    def __init__(self, container: Container) -> None:
        self.container = container
        with container.uow.begin() as work:
            record, self.state = work.create_scene("hall", Params())
        self.id = record.id

    def append(self, *new: Event) -> None:
        with self.container.uow.begin() as work:
            self.state = work.append(self.id, self.state, list(new)).state

    def append_later(self, delay_s: float, *new: Event) -> threading.Thread:
        def later() -> None:
            time.sleep(delay_s)
            self.append(*new)

        thread = threading.Thread(target=later)
        thread.start()
        return thread


@pytest.fixture
def app(container: Container) -> FastAPI:
    return create_app(container)


@pytest.fixture
def url(app: FastAPI) -> Iterator[str]:
    with served(app) as base:
        yield base


def stream_path(scene_id: str) -> str:
    return f"/v1/scenes/{scene_id}/events/stream"


def raw_lines(
    url: str, scene_id: str, until: int, headers: dict[str, str] | None = None, **query: Any
) -> list[str]:
    """The first `until` lines of a stream, read with httpx (no client logic in between)."""
    lines: list[str] = []
    with httpx.stream(
        "GET", url + stream_path(scene_id), params=query, headers=headers, timeout=10
    ) as response:
        assert response.status_code == 200, response.read()
        assert response.headers["content-type"].startswith("text/event-stream")
        for line in response.iter_lines():
            lines.append(line)
            if len(lines) >= until:
                break
    return lines


def ids(lines: list[str]) -> list[int]:
    return [int(line.removeprefix("id: ")) for line in lines if line.startswith("id: ")]


def test_catch_up_then_live_through_the_client(container: Container, url: str) -> None:
    scene = Scene(container)
    scene.append(added("trk-1"), added("trk-2"))
    writer = scene.append_later(0.3, added("trk-3"))
    received = []
    with Client(url) as client:
        for event in client.stream_events(scene.id):
            received.append(event)
            if event.seq == 3:
                break
    writer.join()
    assert [e.seq for e in received] == [0, 1, 2, 3]
    listed = httpx.get(f"{url}/v1/scenes/{scene.id}/events").json()["events"]
    assert [e.model_dump(mode="json") for e in received] == listed  # the same JSON as the list


def test_each_event_is_one_message_with_its_seq_type_and_json(
    container: Container, url: str
) -> None:
    scene = Scene(container)
    scene.append(added("trk-1"))
    lines = raw_lines(url, scene.id, 8)
    assert lines[:3] == ["id: 0", "event: scene_created", lines[2]]
    assert lines[4] == "id: 1" and lines[5] == "event: add"
    assert lines[6].startswith('data: {"seq":1,"type":"add","topic":"object_added"')
    assert lines[3] == lines[7] == ""


def test_last_event_id_wins_over_after(container: Container, url: str) -> None:
    scene = Scene(container)
    scene.append(added("trk-1"), added("trk-2"), added("trk-3"))
    lines = raw_lines(url, scene.id, 4, headers={"Last-Event-ID": "2"}, after=0)
    assert ids(lines) == [3]
    assert ids(raw_lines(url, scene.id, 4, after=1)) == [2]


def test_bad_cursors_and_filters_are_422_naming_the_field(container: Container, url: str) -> None:
    scene = Scene(container)
    path = url + stream_path(scene.id)
    for params, headers, field in (
        ({"after": -2}, {}, "after"),
        ({"type": "x" * 65}, {}, "type"),
        ({"track_id": "a\x01"}, {}, "track_id"),
        ({}, {"Last-Event-ID": "seven"}, '["Last-Event-ID"]'),
        ({}, {"Last-Event-ID": str(2**53)}, '["Last-Event-ID"]'),
    ):
        answer = httpx.get(path, params=params, headers=headers)
        assert answer.status_code == 422, (params, headers)
        assert answer.json()["field"] == field
    assert httpx.get(url + stream_path("nowhere")).status_code == 404


def test_filters_are_those_of_the_listing(container: Container, url: str) -> None:
    scene = Scene(container)
    scene.append(added("trk-1"), added("trk-2"), added("trk-1", 1.0))
    writer = scene.append_later(0.2, added("trk-2", 2.0), added("trk-1", 2.0))
    with Client(url) as client:
        seen = []
        for event in client.stream_events(scene.id, track_id="trk-1", type="add"):
            seen.append((event.seq, event.track_id, event.type))
            if event.seq == 5:
                break
    writer.join()
    assert seen == [(1, "trk-1", "add"), (3, "trk-1", "add"), (5, "trk-1", "add")]


def test_an_idle_stream_sends_heartbeats(container: Container, url: str) -> None:
    scene = Scene(container)
    started = time.monotonic()
    lines = raw_lines(url, scene.id, 8)
    elapsed = time.monotonic() - started
    assert lines[4:8] == [": heartbeat", "", ": heartbeat", ""]
    assert 2 * HEARTBEAT_S * 0.9 <= elapsed < 2 * HEARTBEAT_S + 3


def delete_scene(container: Container, scene_id: str) -> None:
    with write_transaction(container.engine) as connection:
        for table in (snapshots, tracks, events):
            connection.execute(sa.delete(table).where(table.c.scene_id == scene_id))
        connection.execute(sa.delete(scenes).where(scenes.c.id == scene_id))


def test_a_deleted_scene_ends_the_stream(container: Container, url: str) -> None:
    scene = Scene(container)
    threading.Timer(0.3, delete_scene, (container, scene.id)).start()
    lines = raw_lines(url, scene.id, 1000)
    assert lines[-3:-1] == ["event: end", 'data: {"reason":"deleted","seq":0}']


def test_a_quarantined_scene_sends_its_log_then_ends(container: Container, url: str) -> None:
    scene = Scene(container)
    scene.append(added("trk-1"))
    with write_transaction(container.engine) as connection:
        container.log.quarantine(connection, scene.id, "needs repair")
    with Client(url) as client:
        assert [e.seq for e in client.stream_events(scene.id)] == [0, 1]  # then it ends
    lines = raw_lines(url, scene.id, 1000, after=0)
    assert lines[-2] == 'data: {"reason":"quarantined","seq":1}'


def test_streams_beyond_the_limit_are_503_and_a_closed_one_frees_its_slot(
    container: Container, app: FastAPI, url: str
) -> None:
    scene = Scene(container)
    path = url + stream_path(scene.id)
    with httpx.Client(timeout=10) as http:
        with http.stream("GET", path), http.stream("GET", path):
            busy = http.get(path)
            assert busy.status_code == 503
            assert busy.headers["retry-after"].isdigit()
            assert busy.json()["type"] == "/problems/too-many-streams"
            assert app.state.streams.open == 2
        deadline = time.monotonic() + 2  # the disconnects end both streams promptly
        while app.state.streams.open > 0:
            assert time.monotonic() < deadline, f"{app.state.streams.open} streams still open"
            time.sleep(0.02)
        with http.stream("GET", path) as again:
            assert again.status_code == 200


def test_a_consumer_that_takes_nothing_is_dropped_within_the_bound(
    container: Container,
) -> None:
    """The server's writes block (a consumer whose socket is full): the stream gives up after
    the write timeout, tries a last `dropped` message, and frees its slot."""
    scene = Scene(container)
    scene.append(added("trk-1"))
    app = create_app(container)
    sent: list[bytes] = []
    never = anyio.Event()

    async def receive() -> dict[str, Any]:
        await never.wait()
        return {"type": "http.disconnect"}

    async def send(message: MutableMapping[str, Any]) -> None:
        if message["type"] == "http.response.body":
            sent.append(message["body"])
            await never.wait()  # the consumer never takes it

    async def run() -> float:
        scope = {
            "type": "http",
            "asgi": {"version": "3.0", "spec_version": "2.3"},
            "http_version": "1.1",
            "method": "GET",
            "scheme": "http",
            "path": stream_path(scene.id),
            "raw_path": stream_path(scene.id).encode(),
            "query_string": b"",
            "root_path": "",
            "headers": [(b"host", b"localhost")],
            "client": ("127.0.0.1", 50000),
            "server": ("127.0.0.1", 80),
        }
        started = time.monotonic()
        with anyio.fail_after(10):
            await app(scope, receive, send)
        return time.monotonic() - started

    elapsed = anyio.run(run)
    assert WRITE_TIMEOUT_S <= elapsed < WRITE_TIMEOUT_S + 1.5 + 1.0
    assert sent[0].startswith(b"id: 0\nevent: scene_created\n")
    assert sent[-1].startswith(b'event: dropped\ndata: {"reason":')
    assert app.state.streams.open == 0


def test_the_client_raises_what_a_retry_cannot_mend(container: Container, url: str) -> None:
    scene = Scene(container)
    with Client(url) as client, pytest.raises(InvalidRequest) as refused:
        next(iter(client.stream_events(scene.id, after=-5)))
    assert refused.value.field == "after"


def test_a_head_answers_the_headers_and_ends(container: Container, app: FastAPI, url: str) -> None:
    scene = Scene(container)
    with httpx.Client(timeout=5) as http:
        head = http.head(url + stream_path(scene.id))
        assert head.status_code == 200 and head.content == b""
        assert head.headers["content-type"].startswith("text/event-stream")
        assert http.get(f"{url}/v1/scenes/{scene.id}").status_code == 200  # the same connection
    assert app.state.streams.open == 0


@pytest.mark.postgres
def test_on_postgres_a_notify_wakes_the_stream_before_its_poll(
    settings: Settings, tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    polling = settings.model_copy(update={"stream_poll_seconds": 4.0})
    engine = engine_for("postgres", tmp_path, request)
    container = build_container(polling, engine=engine)
    try:
        app = create_app(container)
        with served(app) as url:
            scene = Scene(container)
            with Client(url) as client:
                stream = client.stream_events(scene.id)
                assert next(stream).seq == 0  # then the stream waits, up to 4 s
                writer = scene.append_later(0.3, added("trk-1"))
                started = time.monotonic()
                assert next(stream).seq == 1
                elapsed = time.monotonic() - started
                stream.close()  # type: ignore[attr-defined]
            writer.join()
    finally:
        engine.dispose()
    assert 0.3 <= elapsed < 2.0, elapsed  # the append's NOTIFY, not the next poll


@pytest.mark.postgres
def test_on_postgres_each_append_notifies_its_scene_once_at_commit_and_a_stale_one_never(
    settings: Settings, tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    engine = engine_for("postgres", tmp_path, request)
    container = build_container(settings, engine=engine)
    listener: Any = engine.raw_connection()
    try:
        driver = listener.driver_connection  # the psycopg connection
        driver.autocommit = True
        driver.execute(f"LISTEN {EVENTS_CHANNEL}")
        scene = Scene(container)
        stale = scene.state
        many = [added(f"trk-{index}") for index in range(1, 41)]
        for batch in ([added("trk-a")], many):  # one event, and a batch of forty
            scene.append(*batch)
        with pytest.raises(ConcurrencyConflict), container.uow.begin() as work:
            work.append(scene.id, stale, [added("trk-late")])
        # The channel is the database's: other schemas' scenes may be heard too.
        heard = [notice.payload for notice in driver.notifies(timeout=1.0)]
    finally:
        listener.close()
        engine.dispose()
    assert [payload for payload in heard if payload == scene.id] == [scene.id, scene.id]


def test_the_database_unavailable_closes_the_stream_for_a_resumption(
    container: Container, app: FastAPI, url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    scene = Scene(container)
    lines: list[str] = []
    with httpx.stream("GET", url + stream_path(scene.id), timeout=10) as response:
        for line in response.iter_lines():
            lines.append(line)
            if line.startswith("data: "):  # event 0 sent: now the database goes away

                def unavailable(*_args: object, **_kwargs: object) -> None:
                    raise StoreUnavailable("the database", OSError("connection refused"))

                monkeypatch.setattr(container.log, "scene", unavailable)
    assert lines[:2] == ["id: 0", "event: scene_created"]  # then the answer ended, no message
    assert lines[-1] == "" and not any(line.startswith("event: end") for line in lines)
    deadline = time.monotonic() + 2  # the slot is released as the answer ends
    while app.state.streams.open > 0:
        assert time.monotonic() < deadline, "the stream kept its slot"
        time.sleep(0.02)
