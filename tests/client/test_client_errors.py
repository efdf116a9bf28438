"""Problem documents and batch outcomes as typed exceptions; the token on the wire; what the
client package may import."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import pytest

from pbdag_client import (
    AccessDenied,
    ApiError,
    BatchDead,
    BatchTimeout,
    Client,
    InsufficientStorage,
    InvalidRequest,
    PbdagError,
    RateLimited,
    RequestRefused,
    ServerError,
    Unauthorized,
)
from pbdag_errors import Failure, Refused
from service.auth import create_token
from tests.client.conftest import open_settings, serving
from tests.import_graph import ROOT, imported_roots


def problem(status: int, type: str, title: str, field: str | None = None) -> dict[str, Any]:
    detail = f"{field}: is wrong" if field else "it went wrong"
    return {
        "type": type,
        "title": title,
        "status": status,
        "detail": detail,
        "field": field,
        "errors": [{"field": field, "reason": "is wrong"}],
    }


def answering(handler: Callable[[httpx.Request], httpx.Response]) -> Client:
    return Client("http://pbdag.test", transport=httpx.MockTransport(handler))


def test_a_full_queue_is_rate_limited_with_its_retry_after() -> None:
    body = problem(429, "/problems/queue-full", "Too Many Requests")
    with (
        answering(lambda _: httpx.Response(429, json=body, headers={"Retry-After": "3"})) as c,
        pytest.raises(RateLimited) as raised,
    ):
        c.scenes()
    assert raised.value.retry_after == 3.0 and raised.value.type == "/problems/queue-full"
    assert str(raised.value) == "HTTP 429 Too Many Requests: it went wrong"


def test_quota_and_unknown_statuses_keep_their_problem() -> None:
    body = problem(507, "/problems/quota-exceeded", "Insufficient Storage", "batch_id")
    with (
        answering(lambda _: httpx.Response(507, json=body)) as client,
        pytest.raises(InsufficientStorage) as raised,
    ):
        client.scenes()
    assert raised.value.field == "batch_id" and raised.value.status == 507
    teapot = problem(418, "/problems/teapot", "I'm a teapot")
    with (
        answering(lambda _: httpx.Response(418, json=teapot)) as client,
        pytest.raises(RequestRefused) as other,
    ):
        client.scenes()
    assert type(other.value) is RequestRefused and other.value.title == "I'm a teapot"


def test_answers_mirror_the_one_hierarchy() -> None:
    """A 4xx is a `Refused` and a 5xx a `Failure`, as the service's own errors are; every
    answer is a `PbdagError` (the very class, not one of the same name)."""
    assert issubclass(InvalidRequest, Refused) and issubclass(InsufficientStorage, Refused)
    assert issubclass(ServerError, Failure) and not issubclass(ServerError, Refused)
    assert issubclass(ApiError, PbdagError) and PbdagError.__module__ == "pbdag_errors"
    with (
        answering(lambda _: httpx.Response(404, json=problem(404, "/x", "Not Found"))) as c,
        pytest.raises(Refused) as missing,
    ):
        c.scenes()
    assert isinstance(missing.value, ApiError) and missing.value.status == 404


def test_a_proxy_page_is_a_server_error_with_its_text() -> None:
    page = "<html><body>502 Bad Gateway</body></html>"
    with (
        answering(lambda _: httpx.Response(502, text=page)) as client,
        pytest.raises(ServerError) as raised,
    ):
        client.health()
    assert raised.value.status == 502 and raised.value.type == "about:blank"
    assert "Bad Gateway" in raised.value.detail and raised.value.field is None


def batch_status(status: str, error: str | None = None) -> dict[str, Any]:
    return {
        "batch_id": "b1",
        "scene_id": "s1",
        "status": status,
        "attempts": 3 if status == "dead" else 1,
        "frame_count": 1,
        "content_sha256": "0" * 64,
        "first_seq": None,
        "last_seq": None,
        "error": error,
        "received_at": 0.0,
        "finished_at": None,
    }


def test_waiting_for_a_dead_batch_raises_with_its_error() -> None:
    answers = iter(["queued", "running", "failed", "dead"])

    def service(request: httpx.Request) -> httpx.Response:
        status = next(answers)
        return httpx.Response(200, json=batch_status(status, "decode failed"))

    with answering(service) as client, pytest.raises(BatchDead) as raised:
        client.wait_for_batch("s1", "b1", poll_interval=0.0)
    assert raised.value.batch.status == "dead" and raised.value.batch.error == "decode failed"
    assert "decode failed" in str(raised.value)


def test_waiting_polls_through_rate_limits_and_times_out() -> None:
    seen: list[str] = []

    def service(request: httpx.Request) -> httpx.Response:
        seen.append(request.url.path)
        if len(seen) == 1:
            limited = problem(429, "/problems/rate-limited", "Too Many Requests")
            return httpx.Response(429, json=limited, headers={"Retry-After": "0"})
        return httpx.Response(200, json=batch_status("queued"))

    with answering(service) as client, pytest.raises(BatchTimeout) as raised:
        client.wait_for_batch("s1", "b1", timeout=0.05, poll_interval=0.01)
    # Polled through the 429 (the first answer) to a queued status at least once; how many
    # polls fit in the timeout depends on the machine's load, not on the client.
    assert raised.value.batch.status == "queued" and len(seen) >= 2
    assert set(seen) == {"/v1/scenes/s1/batches/b1"}


def test_the_token_is_sent_and_path_segments_are_encoded() -> None:
    requests: list[httpx.Request] = []

    def service(request: httpx.Request) -> httpx.Response:
        requests.append(request)
        return httpx.Response(200, json=batch_status("done"))

    transport = httpx.MockTransport(service)
    with Client("http://pbdag.test/", "secret-token", transport=transport) as client:
        client.batch("scene/with slash", "b1")
    assert requests[0].headers["authorization"] == "Bearer secret-token"
    assert requests[0].url.raw_path == b"/v1/scenes/scene%2Fwith%20slash/batches/b1"


def test_a_token_protected_service_refuses_without_a_valid_token(tmp_path: Path) -> None:
    settings = open_settings(tmp_path)
    settings.allow_anonymous_local = False
    with serving(settings) as service:
        token = create_token(service.container.engine, "client-test", ["read", "write"]).token
        with Client(service.url) as anonymous, pytest.raises(Unauthorized) as raised:
            anonymous.scenes()
        assert raised.value.status == 401 and raised.value.type == "/problems/unauthorized"
        assert isinstance(raised.value, AccessDenied)
        with (
            Client(service.url, "pbdag_000000000000_wrong") as wrong,
            pytest.raises(Unauthorized),
        ):
            wrong.create_scene("nope")
        with Client(service.url, token) as client:
            scene = client.create_scene("with-token")
            assert [s.id for s in client.scenes()] == [scene.id]
            assert client.health().status == "ok"
            with pytest.raises(InvalidRequest) as invalid:
                client.events_page(scene.id, limit=0)
            assert invalid.value.field == "limit"


def test_the_client_needs_only_the_wire_models_httpx_numpy_and_pillow() -> None:
    allowed = {
        "api_schema",
        "pbdag_client",
        "pbdag_errors",
        "httpx",
        "numpy",
        "PIL",
        "pydantic",
        "__future__",
    }
    modules = sorted((ROOT / "pbdag_client").glob("*.py"))
    assert len(modules) >= 3
    outside = {
        module.name: sorted(imported_roots(module) - allowed - set(sys.stdlib_module_names))
        for module in modules
    }
    assert {name: extra for name, extra in outside.items() if extra} == {}
    # api_schema itself is pydantic only, so the client installs without the service.
    wire = {"api_schema", "pydantic", "pydantic_core", "__future__"}
    for module in sorted((ROOT / "api_schema").glob("*.py")):
        assert imported_roots(module) - set(sys.stdlib_module_names) <= wire, module.name


def test_problem_documents_parse_from_the_service_shape() -> None:
    body = problem(422, "/problems/invalid-observation", "Invalid observation", "frames[0].depth")
    body["errors"].append({"field": "frames[1].pose", "reason": "not rigid"})
    with (
        answering(lambda _: httpx.Response(422, content=json.dumps(body).encode())) as client,
        pytest.raises(InvalidRequest) as raised,
    ):
        client.scenes()
    assert raised.value.fields == ["frames[0].depth", "frames[1].pose"]
    assert [e.reason for e in raised.value.errors] == ["is wrong", "not rigid"]
