"""HTTP around the routes: `X-Content-Type-Options: nosniff` on every answer, HEAD wherever GET
(with the GET's scope), and a 405 whose `Allow` lists every method of the path."""

from __future__ import annotations

from collections.abc import Iterator

import httpx2
import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from service.app import create_app
from service.auth import RequireAdmin, create_token
from service.bootstrap import Container
from tests.clients import LOCAL_BASE_URL, local_client

LAN_CLIENT = ("192.168.1.50", 40000)


def make_app(container: Container) -> FastAPI:
    """The service, plus a GET only an admin may call and a route that fails unexpectedly."""
    app = create_app(container)

    @app.get("/v1/admin/whoami")
    def whoami(principal: RequireAdmin) -> dict[str, str | None]:
        return {"token_id": principal.token_id}

    @app.get("/v1/boom")
    def boom() -> None:
        raise RuntimeError("unexpected")

    return app


@pytest.fixture
def app(container: Container) -> FastAPI:
    return make_app(container)


@pytest.fixture
def local(app: FastAPI) -> Iterator[TestClient]:
    """From loopback, anonymous (read and write)."""
    with local_client(app, raise_server_exceptions=False) as client:
        yield client


@pytest.fixture
def scene_id(local: TestClient) -> str:
    return str(local.post("/v1/scenes", json={"name": "hall"}).json()["id"])


def nosniff(response: httpx2.Response) -> bool:
    return response.headers.get_list("x-content-type-options") == ["nosniff"]


# --- nosniff -----------------------------------------------------------------------------------


def test_json_answers_exports_and_pages_say_nosniff_once(local: TestClient, scene_id: str) -> None:
    assert local.get("/v1/scenes").status_code == 200
    assert nosniff(local.get("/v1/scenes"))
    export = local.get(f"/v1/scenes/{scene_id}/graph", params={"format": "graphml"})
    assert export.status_code == 200 and nosniff(export)
    as_json = local.get(f"/v1/scenes/{scene_id}/graph", params={"format": "json-graph"})
    assert as_json.status_code == 200 and nosniff(as_json)
    assert nosniff(local.get("/healthz")) and nosniff(local.get("/metrics"))
    viewer = local.get("/viewer")  # sets its own: still one header
    assert viewer.status_code == 200 and nosniff(viewer)


def test_every_error_answer_says_nosniff(app: FastAPI, local: TestClient) -> None:
    statuses = {
        404: local.get("/v1/scenes/scn-missing"),
        405: local.delete("/healthz"),
        422: local.post("/v1/scenes", json={"name": ""}),
        500: local.get("/v1/boom"),
    }
    with TestClient(app, base_url="http://attacker.example", client=LAN_CLIENT) as foreign:
        statuses[400] = foreign.get("/v1/scenes")
    with TestClient(app, base_url=LOCAL_BASE_URL, client=LAN_CLIENT) as lan:
        statuses[401] = lan.get("/v1/scenes")
    for status, response in statuses.items():
        assert response.status_code == status, (status, response.text)
        assert response.headers["content-type"] == "application/problem+json"
        assert nosniff(response), status


# --- HEAD --------------------------------------------------------------------------------------


def test_head_answers_what_get_answers_without_the_body(local: TestClient, scene_id: str) -> None:
    for path, params in (
        ("/v1/scenes", {}),
        (f"/v1/scenes/{scene_id}", {}),
        (f"/v1/scenes/{scene_id}/graph", {"format": "graphml"}),
        ("/healthz", {}),
        ("/openapi.json", {}),
        ("/viewer", {}),
    ):
        get = local.get(path, params=params)
        head = local.head(path, params=params)
        assert (head.status_code, get.status_code) == (200, 200), path
        assert head.content == b"" and get.content != b"", path
        for header in ("content-type", "content-length"):
            assert head.headers.get(header) == get.headers.get(header), (path, header)
    missing = local.head("/v1/scenes/scn-missing")
    assert missing.status_code == 404 and missing.content == b""


def test_a_head_needs_the_scope_its_get_needs(app: FastAPI, container: Container) -> None:
    read = create_token(container.engine, "reader", ["read"]).token
    admin = create_token(container.engine, "operator", ["admin"]).token
    with TestClient(app, base_url=LOCAL_BASE_URL, client=LAN_CLIENT) as lan:
        assert lan.head("/v1/scenes").status_code == 401
        answer = lan.head("/v1/scenes", headers={"Authorization": f"Bearer {read}"})
        assert answer.status_code == 200 and answer.content == b""
        for token, status in ((read, 403), (admin, 200)):
            headers = {"Authorization": f"Bearer {token}"}
            assert lan.get("/v1/admin/whoami", headers=headers).status_code == status
            assert lan.head("/v1/admin/whoami", headers=headers).status_code == status
        denied = lan.head("/v1/admin/whoami", headers={"Authorization": f"Bearer {read}"})
        assert 'scope="admin"' in denied.headers["www-authenticate"]


# --- 405 and Allow -----------------------------------------------------------------------------


def allow(response: httpx2.Response) -> list[str]:
    return [method.strip() for method in response.headers["allow"].split(",")]


def test_a_405_allows_every_method_of_the_path(local: TestClient, scene_id: str) -> None:
    for method in ("OPTIONS", "DELETE", "PUT"):
        response = local.request(method, "/v1/scenes")
        assert response.status_code == 405, (method, response.text)
        assert response.headers["content-type"] == "application/problem+json"
        assert allow(response) == ["GET", "HEAD", "POST"], method
    assert allow(local.put(f"/v1/scenes/{scene_id}/plan")) == ["GET", "HEAD", "POST"]
    batches = f"/v1/scenes/{scene_id}/batches"  # POST only
    assert allow(local.get(batches)) == ["POST"]
    head = local.head(batches)
    assert head.status_code == 405 and allow(head) == ["POST"] and head.content == b""
    assert allow(local.post("/healthz")) == ["GET", "HEAD"]
    assert allow(local.post(f"/v1/scenes/{scene_id}")) == ["GET", "HEAD", "PATCH", "DELETE"]
