"""problem+json error responses and the body-size limit, on a tiny app."""

from __future__ import annotations

import asyncio
import importlib
import json
import pkgutil
from collections.abc import AsyncIterator
from types import ModuleType
from typing import Any

import httpx
import pytest
from fastapi import FastAPI, Request
from starlette.types import Message

import codec
import core
import service
from api_schema import BatchIn
from codec.observations import decode_batch
from core.errors import NotFound, StateConflict, UnknownTrack, field_path
from pbdag_errors import Failure, PbdagError, Refused
from service.access_errors import (
    BodyTooLarge,
    HostNotAllowed,
    InsufficientScope,
    NotAuthenticated,
    RateLimitExceeded,
)
from service.errors import (
    INTERNAL,
    PROBLEM_MEDIA_TYPE,
    PROBLEMS,
    headers_of,
    install_problem_handlers,
    problem_of,
)
from service.middleware.body_limit import BodySizeLimit
from service.middleware.unexpected import UnexpectedErrors
from service.store.errors import BatchConflict
from service.store.queue_records import QueueFull
from tests.wire_bodies import batch_body, frame_body

MAX_BODY_BYTES = 200_000
PROBLEM_KEYS = {"type", "title", "status", "detail", "field", "errors"}


def make_app() -> tuple[FastAPI, list[str]]:
    """An app with one route per kind of failure; `calls` records which endpoints ran."""
    app = FastAPI()
    install_problem_handlers(app)
    app.add_middleware(BodySizeLimit, max_bytes=MAX_BODY_BYTES)
    app.add_middleware(UnexpectedErrors)
    calls: list[str] = []

    @app.post("/scenes/{scene_id}/batches")
    def post_batch(scene_id: str, batch: BatchIn) -> dict[str, int]:
        calls.append("post_batch")
        return {"frames": len(decode_batch(batch).frames)}

    @app.get("/scenes/{scene_id}")
    def get_scene(scene_id: str) -> dict[str, str]:
        raise NotFound("scene", scene_id)

    @app.post("/conflict")
    def conflict() -> None:
        raise BatchConflict("batch 'b1' was already posted with different content")

    @app.get("/boom")
    def boom() -> None:
        raise RuntimeError("secret database password in /etc/pbdag")

    @app.post("/raw")
    async def raw(request: Request) -> dict[str, int]:
        calls.append("raw")
        return {"bytes": len(await request.body())}

    return app, calls


@pytest.fixture
def app_and_calls() -> tuple[FastAPI, list[str]]:
    return make_app()


class SyncClient:
    """Blocking calls into the app through httpx's ASGI transport."""

    # Not starlette's TestClient: with the pinned httpx it raises a deprecation warning,
    # which the project's pytest configuration turns into an error.

    def __init__(self, app: FastAPI) -> None:
        self.app = app

    def request(self, method: str, url: str, **kwargs: Any) -> httpx.Response:
        async def send() -> httpx.Response:
            # raise_app_exceptions=False: see the 500 response instead of the re-raised error.
            transport = httpx.ASGITransport(app=self.app, raise_app_exceptions=False)
            async with httpx.AsyncClient(transport=transport, base_url="http://test") as client:
                return await client.request(method, url, **kwargs)

        return asyncio.run(send())

    def get(self, url: str, **kwargs: Any) -> httpx.Response:
        return self.request("GET", url, **kwargs)

    def post(self, url: str, **kwargs: Any) -> httpx.Response:
        return self.request("POST", url, **kwargs)

    def delete(self, url: str, **kwargs: Any) -> httpx.Response:
        return self.request("DELETE", url, **kwargs)


@pytest.fixture
def client(app_and_calls: tuple[FastAPI, list[str]]) -> SyncClient:
    return SyncClient(app_and_calls[0])


def problem_in(response: httpx.Response, status: int) -> dict[str, Any]:
    """Check the status, media type and member set of a problem response; return its body."""
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == PROBLEM_MEDIA_TYPE
    problem: dict[str, Any] = response.json()
    assert set(problem) == PROBLEM_KEYS
    assert problem["status"] == status
    return problem


def test_not_found_is_problem_json(client: SyncClient) -> None:
    problem = problem_in(client.get("/scenes/kitchen"), 404)
    assert problem == {
        "type": "/problems/not-found",
        "title": "Not Found",
        "status": 404,
        "detail": "scene 'kitchen' does not exist",
        "field": None,
        "errors": [{"field": None, "reason": "scene 'kitchen' does not exist"}],
    }


def test_conflict_carries_its_field(client: SyncClient) -> None:
    problem = problem_in(client.post("/conflict"), 409)
    assert problem["type"] == "/problems/batch-conflict"
    assert problem["field"] == "batch_id"
    assert "different content" in problem["detail"]


def test_unknown_route_and_wrong_method_are_problem_json(client: SyncClient) -> None:
    problem = problem_in(client.get("/no/such/route"), 404)
    assert (problem["type"], problem["title"]) == ("about:blank", "Not Found")

    response = client.delete("/scenes/kitchen")
    problem = problem_in(response, 405)
    assert problem["title"] == "Method Not Allowed"
    assert response.headers["allow"] == "GET"


def test_valid_batch_passes(client: SyncClient, app_and_calls: tuple[FastAPI, list[str]]) -> None:
    response = client.post("/scenes/s1/batches", json=batch_body())
    assert response.status_code == 200, response.text
    assert response.json() == {"frames": 1}
    assert app_and_calls[1] == ["post_batch"]


def test_pydantic_errors_list_every_field_path_without_body_prefix(client: SyncClient) -> None:
    frame = frame_body()
    frame["intrinsics"]["fx"] = 0
    frame["pose"] = frame["pose"][:3]
    body = batch_body(frame)
    body["batch_id"] = "no spaces allowed"

    response = client.post("/scenes/s1/batches", json=body)

    problem = problem_in(response, 422)
    assert problem["type"] == "/problems/invalid-request"
    fields = sorted(error["field"] for error in problem["errors"])
    assert fields == ["batch_id", "frames[0].intrinsics.fx", "frames[0].pose"]
    assert problem["field"] in fields
    assert "(and 2 more)" in problem["detail"]
    assert all(error["reason"] for error in problem["errors"])
    # The offending input (here a base64 depth image) is never echoed back.
    assert frame["depth"]["data"][:40] not in response.text


def test_nested_pydantic_error_path(client: SyncClient) -> None:
    frame = frame_body()
    frame["detections"][1]["score"] = 2.0
    problem = problem_in(client.post("/scenes/s1/batches", json=batch_body(frame)), 422)
    assert problem["field"] == "frames[0].detections[1].score"
    assert problem["errors"] == [
        {
            "field": "frames[0].detections[1].score",
            "reason": "Input should be less than or equal to 1",
        }
    ]


def test_malformed_json_is_a_422_without_a_field(client: SyncClient) -> None:
    response = client.post(
        "/scenes/s1/batches", content=b'{"batch_id": ', headers={"content-type": "application/json"}
    )
    problem = problem_in(response, 422)
    assert problem["field"] is None
    assert "not valid JSON" in problem["errors"][0]["reason"]


def test_invalid_observation_names_the_field(client: SyncClient) -> None:
    frame = frame_body()
    frame["detections"][0]["mask"]["size"] = [10, 10]
    problem = problem_in(client.post("/scenes/s1/batches", json=batch_body(frame)), 422)
    assert problem["type"] == "/problems/invalid-observation"
    assert problem["field"] == "frames[0].detections[0].mask.size"
    assert problem["errors"][0]["field"] == problem["field"]
    assert "does not match the depth size" in problem["errors"][0]["reason"]
    assert problem["detail"].startswith("frames[0].detections[0].mask.size: ")


def test_unexpected_exception_is_a_500_that_leaks_nothing(client: SyncClient) -> None:
    response = client.get("/boom")
    problem = problem_in(response, 500)
    assert problem["title"] == "Internal Server Error"
    for leak in ("secret", "RuntimeError", "Traceback", "/etc/pbdag"):
        assert leak not in response.text


def test_body_over_the_declared_limit_is_413_before_the_app_reads_it(
    client: SyncClient, app_and_calls: tuple[FastAPI, list[str]]
) -> None:
    response = client.post("/raw", content=b"x" * (MAX_BODY_BYTES + 1))
    problem = problem_in(response, 413)
    assert problem["type"] == "/problems/payload-too-large"
    assert str(MAX_BODY_BYTES) in problem["detail"]
    assert "PBDAG_MAX_BODY_BYTES" in problem["detail"]  # the limit's name, as every other one
    assert app_and_calls[1] == []


def test_body_at_the_limit_passes(client: SyncClient) -> None:
    response = client.post("/raw", content=b"x" * MAX_BODY_BYTES)
    assert response.status_code == 200
    assert response.json() == {"bytes": MAX_BODY_BYTES}


@pytest.mark.parametrize("path", ["/raw", "/scenes/s1/batches"])
def test_streamed_body_over_the_limit_is_413(client: SyncClient, path: str) -> None:
    async def chunks() -> AsyncIterator[bytes]:
        for _ in range(5):
            yield b"x" * (MAX_BODY_BYTES // 4)

    response = client.post(path, content=chunks(), headers={"content-type": "application/json"})
    assert "content-length" not in response.request.headers
    problem_in(response, 413)


def test_streamed_body_stops_being_read_at_the_limit() -> None:
    """Driven at the ASGI level: the middleware must not pull chunks past the limit."""
    chunk_count, chunk_size, limit = 100, 1000, 2500
    pulled = 0
    sent: list[Message] = []

    async def receive() -> Message:
        nonlocal pulled
        pulled += 1
        return {
            "type": "http.request",
            "body": b"x" * chunk_size,
            "more_body": pulled < chunk_count,
        }

    async def send(message: Message) -> None:
        sent.append(message)

    async def read_everything(scope: Any, receive: Any, send: Any) -> None:
        while (await receive()).get("more_body"):
            pass
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"read it all"})

    scope = {"type": "http", "method": "POST", "path": "/", "headers": []}
    asyncio.run(BodySizeLimit(read_everything, max_bytes=limit)(scope, receive, send))

    assert pulled == 3  # 3000 bytes > 2500: the third chunk crosses the limit
    assert sent[0]["status"] == 413
    assert (b"content-type", PROBLEM_MEDIA_TYPE.encode()) in sent[0]["headers"]
    assert json.loads(sent[1]["body"])["status"] == 413


def test_non_http_scopes_pass_through() -> None:
    seen: list[str] = []

    async def app(scope: Any, receive: Any, send: Any) -> None:
        seen.append(scope["type"])

    async def never(*_: Any) -> Any:
        raise AssertionError("not called")

    asyncio.run(BodySizeLimit(app, max_bytes=0)({"type": "lifespan"}, never, never))
    assert seen == ["lifespan"]


@pytest.mark.parametrize(
    ("location", "expected"),
    [
        (("frames", 0, "detections", 2, "mask", "size"), "frames[0].detections[2].mask.size"),
        (("batch_id",), "batch_id"),
        (("frames", 0, "pose", 1, 2), "frames[0].pose[1][2]"),
        (
            ("frames", 0, "detections", 0, "class_scores", "dining table"),
            'frames[0].detections[0].class_scores["dining table"]',
        ),
        ((), None),
    ],
)
def test_field_path(location: tuple[str | int, ...], expected: str | None) -> None:
    assert field_path(location) == expected


def test_query_errors_name_the_parameter(client: SyncClient) -> None:
    app = FastAPI()
    install_problem_handlers(app)

    @app.get("/events")
    def events(limit: int = 10) -> dict[str, int]:
        return {"limit": limit}

    problem = problem_in(SyncClient(app).get("/events", params={"limit": "many"}), 422)
    assert problem["field"] == "limit"


def test_the_problem_table_is_looked_up_along_the_class_hierarchy() -> None:
    class MissingMug(NotFound):
        pass

    class Unregistered(PbdagError):
        pass

    assert problem_of(MissingMug("mug", "m1")) is PROBLEMS[NotFound]
    assert problem_of(UnknownTrack("x")).status == 404
    assert problem_of(StateConflict("x")).status == 409
    assert problem_of(Unregistered("x")) is INTERNAL
    assert problem_of(RuntimeError("x")) is INTERNAL


def every_subclass(cls: type[BaseException]) -> set[type[BaseException]]:
    """`cls`'s subclasses, at every depth, among the modules imported so far."""
    found: set[type[BaseException]] = set()
    for subclass in cls.__subclasses__():
        found |= {subclass} | every_subclass(subclass)
    return found


def imported_everything(*packages: ModuleType) -> None:
    for package in packages:
        for module in pkgutil.walk_packages(package.__path__, f"{package.__name__}."):
            importlib.import_module(module.name)


# Refusals no request meets: these stop a command of `pbdag` before any request is served, and
# these bases are never raised themselves.
COMMAND_LINE_ONLY = {"SettingsError", "UnknownToken"}
BASES = {"AccessProblem", "DomainError"}


def test_what_a_client_can_cause_is_a_4xx_and_what_the_server_fails_at_a_500() -> None:
    """The table reads along the two branches: every refusal of the service or the core has its
    own 4xx (a quota's 507 and the 503 of a server at its stream limit aside), every failure is
    the bare 500 (an unavailable store's 503 aside)."""
    imported_everything(core, codec, service)
    ours = ("core.", "codec.", "service.")
    refusals = {
        cls
        for cls in every_subclass(Refused)
        if cls.__module__.startswith(ours) and cls.__name__ not in COMMAND_LINE_ONLY | BASES
    }
    assert len(refusals) >= 20, sorted(cls.__name__ for cls in refusals)
    status = {cls.__name__: problem_of(cls.__new__(cls)).status for cls in refusals}
    assert {name: code for name, code in status.items() if not 400 <= code < 500} == {
        "QuotaExceeded": 507,
        "TooManyStreams": 503,
    }
    failures = {cls for cls in every_subclass(Failure) if cls.__module__.startswith(ours)}
    assert len(failures) >= 6, sorted(cls.__name__ for cls in failures)
    # A failure answers 500, but for a store that may come back: 503, with Retry-After.
    answered = {cls.__name__: problem_of(cls.__new__(cls)).status for cls in failures}
    assert {name: code for name, code in answered.items() if code != 500} == {
        "StoreUnavailable": 503
    }
    assert [cls for cls, problem in PROBLEMS.items() if problem is INTERNAL] == [Failure]


@pytest.mark.parametrize(
    ("error", "headers"),
    [
        (NotAuthenticated("no token"), {"WWW-Authenticate": 'Bearer realm="pbdag"'}),
        (
            NotAuthenticated("revoked", token_error="invalid_token"),
            {"WWW-Authenticate": 'Bearer realm="pbdag", error="invalid_token"'},
        ),
        (
            InsufficientScope("read only", needed="write"),
            {"WWW-Authenticate": 'Bearer realm="pbdag", error="insufficient_scope", scope="write"'},
        ),
        (RateLimitExceeded(7, per_minute=60, field=None), {"Retry-After": "7"}),
        (QueueFull(10, 10, 3), {"Retry-After": "3"}),
        (HostNotAllowed("evil.example"), None),
        (BodyTooLarge(10), None),
    ],
)
def test_the_headers_http_asks_for_come_from_the_table(
    error: PbdagError, headers: dict[str, str] | None
) -> None:
    assert headers_of(error) == headers


def test_a_500_keeps_the_keep_alive_connection() -> None:
    """A real server: after an unexpected error the client's next request rides the same socket."""
    import socket
    import threading

    import uvicorn

    app, _calls = make_app()
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="critical"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        for _ in range(100):
            if server.started:
                break
            threading.Event().wait(0.05)
        with httpx.Client(base_url=f"http://127.0.0.1:{port}") as http:
            failed = http.get("/boom")
            assert failed.status_code == 500 and failed.headers.get("connection") != "close"
            first_socket = failed.extensions["network_stream"].get_extra_info("socket")
            after = http.get("/scenes/kitchen")
            assert after.status_code == 404
            assert after.extensions["network_stream"].get_extra_info("socket") is first_socket
    finally:
        server.should_exit = True
        thread.join(timeout=10)
