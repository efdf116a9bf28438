"""Bearer tokens and scopes, anonymous local access, allowed hosts, CORS and rate limits over HTTP."""

from __future__ import annotations

import hashlib
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx2
import pytest
import sqlalchemy as sa
from fastapi import FastAPI
from fastapi.testclient import TestClient

from service.app import create_app
from service.auth import (
    ANONYMOUS_LOCAL_SCOPES,
    Principal,
    RequireAdmin,
    create_token,
    effective_scopes,
    is_loopback,
    list_tokens,
    revoke_token,
    verify_token,
)
from service.bootstrap import Container
from service.ratelimit import RateLimiter
from service.security import AllowedHosts, hosts_when_serving
from service.settings import Settings
from service.store.tables import api_tokens
from tests.clients import LOCAL_BASE_URL, local_client
from tests.wire_scenes import batch

LAN_CLIENT = ("192.168.1.50", 40000)
TOKEN_PATTERN = re.compile(r"pbdag_[0-9a-f]{12}_[A-Za-z0-9_-]{43}")


def make_app(container: Container, **settings: object) -> FastAPI:
    """The service with these settings changed, and one admin route as later ones will be."""
    container.settings.allow_anonymous_local = False
    for name, value in settings.items():
        setattr(container.settings, name, value)
    app = create_app(container)

    @app.get("/v1/admin/whoami")
    def whoami(principal: RequireAdmin) -> dict[str, str | None]:
        return {"token_id": principal.token_id}

    return app


def lan_client(app: FastAPI) -> TestClient:
    """A client on the robot's LAN (not loopback), using an allowed Host name."""
    return TestClient(app, base_url=LOCAL_BASE_URL, client=LAN_CLIENT)


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def problem(response: httpx2.Response, status: int) -> dict[str, Any]:
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == "application/problem+json"
    body: dict[str, Any] = response.json()
    assert body["status"] == status
    return body


@pytest.fixture
def lan(container: Container) -> Iterator[TestClient]:
    with lan_client(make_app(container)) as client:
        yield client


def test_a_write_without_a_token_is_401_with_a_bearer_challenge(
    container: Container, lan: TestClient
) -> None:
    response = lan.post("/v1/scenes", json={"name": "kitchen"})
    body = problem(response, 401)
    assert response.headers["www-authenticate"].startswith("Bearer")
    assert body["field"] == "authorization"
    assert "pbdag token create" in body["detail"]
    assert container.log.scenes() == []


def test_a_read_token_reads_but_its_write_is_403_naming_the_scope(
    container: Container, lan: TestClient
) -> None:
    token = create_token(container.engine, "viewer", ["read"]).token
    assert lan.get("/v1/scenes", headers=bearer(token)).status_code == 200
    body = problem(lan.post("/v1/scenes", json={"name": "x"}, headers=bearer(token)), 403)
    assert body["field"] == "authorization"
    assert "'write' scope" in body["detail"]
    assert container.log.scenes() == []


def test_a_write_token_posts_scenes_and_batches(container: Container, lan: TestClient) -> None:
    token = create_token(container.engine, "robot-1", ["write"]).token
    created = lan.post("/v1/scenes", json={"name": "kitchen"}, headers=bearer(token))
    assert created.status_code == 201, created.text
    scene_id = created.json()["id"]
    posted = lan.post(f"/v1/scenes/{scene_id}/batches", json=batch("b0", 0), headers=bearer(token))
    assert posted.status_code == 202, posted.text
    assert lan.get(f"/v1/scenes/{scene_id}", headers=bearer(token)).status_code == 200


def test_a_revoked_token_is_401(container: Container, lan: TestClient) -> None:
    new = create_token(container.engine, "robot-1", ["write"])
    assert lan.get("/v1/scenes", headers=bearer(new.token)).status_code == 200
    revoke_token(container.engine, new.record.id)
    response = lan.get("/v1/scenes", headers=bearer(new.token))
    assert "revoked" in problem(response, 401)["detail"]
    assert 'error="invalid_token"' in response.headers["www-authenticate"]


@pytest.mark.parametrize(
    "authorization",
    [
        "Basic dXNlcjpwYXNz",
        "Bearer",
        "Bearer not-a-token",
        "Bearer pbdag_0123456789ab_" + "A" * 43,  # well formed, never issued
    ],
)
def test_malformed_foreign_and_unknown_credentials_are_401(
    container: Container, lan: TestClient, authorization: str
) -> None:
    create_token(container.engine, "robot-1", ["write"])
    response = lan.get("/v1/scenes", headers={"Authorization": authorization})
    assert problem(response, 401)["field"] == "authorization"
    assert response.headers["www-authenticate"].startswith("Bearer")


def test_a_token_with_its_secret_altered_is_401(container: Container, lan: TestClient) -> None:
    token = create_token(container.engine, "robot-1", ["write"]).token
    altered = token[:-1] + ("A" if token[-1] != "A" else "B")
    problem(lan.get("/v1/scenes", headers=bearer(altered)), 401)
    assert lan.get("/v1/scenes", headers=bearer(token)).status_code == 200


def test_admin_routes_need_the_admin_scope(container: Container, lan: TestClient) -> None:
    writer = create_token(container.engine, "robot-1", ["write"]).token
    body = problem(lan.get("/v1/admin/whoami", headers=bearer(writer)), 403)
    assert "'admin' scope" in body["detail"] and body["field"] == "authorization"
    admin = create_token(container.engine, "operator", ["admin"])
    response = lan.get("/v1/admin/whoami", headers=bearer(admin.token))
    assert response.status_code == 200 and response.json() == {"token_id": admin.record.id}
    # admin implies write and read
    assert (
        lan.post("/v1/scenes", json={"name": "x"}, headers=bearer(admin.token)).status_code == 201
    )


def test_scopes_nest_admin_write_read() -> None:
    assert effective_scopes(["read"]) == {"read"}
    assert effective_scopes(["write"]) == {"read", "write"}
    assert effective_scopes(["admin"]) == {"read", "write", "admin"}
    assert "admin" not in ANONYMOUS_LOCAL_SCOPES and "write" in ANONYMOUS_LOCAL_SCOPES


def test_tokens_are_stored_as_sha256_only(container: Container) -> None:
    new = create_token(container.engine, "robot-1", ["read", "write"])
    assert TOKEN_PATTERN.fullmatch(new.token)
    assert new.token.startswith(f"pbdag_{new.record.id}_")
    with container.engine.connect() as connection:
        rows = [dict(row._mapping) for row in connection.execute(sa.select(api_tokens))]
    assert len(rows) == 1
    stored = rows[0]
    assert stored["token_sha256"] == hashlib.sha256(new.token.encode()).hexdigest()
    secret = new.token.split("_", 2)[2]  # the secret itself may contain "_"
    assert len(secret) == 43
    for value in stored.values():
        assert new.token not in str(value) and secret not in str(value)
    assert stored["scopes"] == "read write"
    assert verify_token(container.engine, new.token) == new.record
    assert [record.id for record in list_tokens(container.engine)] == [new.record.id]


def test_token_creation_rejects_unknown_or_no_scopes_and_empty_names(container: Container) -> None:
    with pytest.raises(ValueError, match="unknown scopes"):
        create_token(container.engine, "x", ["root"])
    with pytest.raises(ValueError, match="at least one scope"):
        create_token(container.engine, "x", [])
    with pytest.raises(ValueError, match="name"):
        create_token(container.engine, "  ", ["read"])
    assert list_tokens(container.engine) == []


def test_healthz_stays_open_and_docs_need_read(container: Container, lan: TestClient) -> None:
    assert lan.get("/healthz").status_code == 200
    for path in ("/openapi.json", "/docs"):
        problem(lan.get(path), 401)
    token = create_token(container.engine, "viewer", ["read"]).token
    for path in ("/openapi.json", "/docs"):
        assert lan.get(path, headers=bearer(token)).status_code == 200, path
    document = lan.get("/openapi.json", headers=bearer(token)).json()
    assert document["components"]["securitySchemes"]["bearer"]["scheme"] == "bearer"
    assert document["security"] == [{"bearer": []}]
    assert document["paths"]["/healthz"]["get"]["security"] == []


def test_unknown_paths_need_a_token_too(lan: TestClient) -> None:
    problem(lan.get("/v1/no/such/route"), 401)


# --- anonymous local access --------------------------------------------------------------------


def test_loopback_needs_a_token_unless_anonymous_local_access_is_on(container: Container) -> None:
    with local_client(make_app(container)) as local:
        problem(local.post("/v1/scenes", json={"name": "x"}), 401)
    with local_client(make_app(container, allow_anonymous_local=True)) as local:
        assert local.post("/v1/scenes", json={"name": "x"}).status_code == 201
        # read and write, never admin
        assert "'admin' scope" in problem(local.get("/v1/admin/whoami"), 403)["detail"]
        # a bad token is refused even from loopback
        problem(local.get("/v1/scenes", headers=bearer("pbdag_0123456789ab_" + "A" * 43)), 401)


def test_anonymous_local_access_never_extends_to_other_addresses(container: Container) -> None:
    app = make_app(container, allow_anonymous_local=True)
    with lan_client(app) as lan:
        problem(lan.post("/v1/scenes", json={"name": "x"}), 401)
        problem(lan.get("/v1/scenes"), 401)
    with TestClient(app, base_url=LOCAL_BASE_URL) as default_client:  # "testclient"
        problem(default_client.get("/v1/scenes"), 401)
    assert [scene.name for scene in container.log.scenes()] == []


def test_loopback_addresses() -> None:
    host: str | None
    for host in ("127.0.0.1", "127.8.9.10", "::1", "[::1]", "::ffff:127.0.0.1", "localhost"):
        assert is_loopback(host), host
    for host in ("192.168.1.50", "10.0.0.1", "0.0.0.0", "::", "testclient", "", None):
        assert not is_loopback(host), host


# --- allowed hosts and CORS --------------------------------------------------------------------


def test_a_foreign_host_header_is_rejected_before_anything_else(container: Container) -> None:
    app = make_app(container, allow_anonymous_local=True)
    with local_client(app, base_url="http://attacker.example") as client:
        response = client.get("/healthz")
        body = problem(response, 400)
        assert body["field"] == "host" and "attacker.example" in body["detail"]
        assert body["errors"] == [{"field": "host", "reason": body["detail"]}]
        problem(client.post("/v1/scenes", json={"name": "x"}), 400)
    for base_url in ("http://localhost:8000", "http://127.0.0.1:8000", "http://[::1]:8000"):
        with local_client(app, base_url=base_url) as client:
            assert client.get("/v1/scenes").status_code == 200, base_url
    assert container.log.scenes() == []


def test_allowed_host_patterns() -> None:
    hosts = AllowedHosts(FastAPI(), ["robot.lan", "*.fleet.example", "[fd00::7]"])
    assert hosts.allows("robot.lan:8000") and hosts.allows("ROBOT.LAN")
    assert hosts.allows("r1.fleet.example") and not hosts.allows("fleet.example.evil")
    assert hosts.allows("[fd00::7]:8000") and not hosts.allows("[fd00::8]:8000")
    assert not hosts.allows("") and not hosts.allows("evil.lan")


def test_serving_on_a_lan_address_allows_that_host_but_not_a_wildcard() -> None:
    default = ["localhost", "127.0.0.1", "::1"]
    assert hosts_when_serving(default, "192.168.1.20") == [*default, "192.168.1.20"]
    assert hosts_when_serving(default, "0.0.0.0") == default
    assert hosts_when_serving(default, "::") == default
    assert hosts_when_serving(default, "127.0.0.1") == default


def test_cors_is_off_by_default_and_allows_configured_origins(container: Container) -> None:
    preflight = {
        "Origin": "http://viewer.lan",
        "Access-Control-Request-Method": "GET",
        "Access-Control-Request-Headers": "authorization",
    }
    with lan_client(make_app(container)) as client:
        response = client.options("/v1/scenes", headers=preflight)
        assert "access-control-allow-origin" not in response.headers
    with lan_client(make_app(container, cors_origins=["http://viewer.lan"])) as client:
        response = client.options("/v1/scenes", headers=preflight)
        assert response.status_code == 200
        assert response.headers["access-control-allow-origin"] == "http://viewer.lan"
        assert "authorization" in response.headers["access-control-allow-headers"].lower()
        # an error answer carries the CORS headers too, so the viewer can read it
        denied = client.get("/v1/scenes", headers={"Origin": "http://viewer.lan"})
        assert denied.status_code == 401
        assert denied.headers["access-control-allow-origin"] == "http://viewer.lan"


# --- rate limits -------------------------------------------------------------------------------


def test_rate_limit_is_per_token_and_answers_429_with_retry_after(container: Container) -> None:
    app = make_app(container, rate_limit_per_minute=60, rate_limit_burst=2)
    first = create_token(container.engine, "robot-1", ["read"]).token
    second = create_token(container.engine, "robot-2", ["read"]).token
    with lan_client(app) as client:
        assert [client.get("/v1/scenes", headers=bearer(first)).status_code for _ in range(2)] == [
            200,
            200,
        ]
        response = client.get("/v1/scenes", headers=bearer(first))
        body = problem(response, 429)
        assert int(response.headers["retry-after"]) >= 1
        assert "60 requests per minute" in body["detail"]
        assert client.get("/v1/scenes", headers=bearer(second)).status_code == 200
        assert client.get("/healthz").status_code == 200  # probes are never limited


def test_anonymous_and_failed_requests_are_limited_per_address(container: Container) -> None:
    app = make_app(container, rate_limit_per_minute=60, rate_limit_burst=2)
    with lan_client(app) as client:
        assert [client.get("/v1/scenes").status_code for _ in range(3)] == [401, 401, 429]
    app = make_app(
        container, allow_anonymous_local=True, rate_limit_per_minute=60, rate_limit_burst=2
    )
    with local_client(app) as client:
        assert [client.get("/v1/scenes").status_code for _ in range(3)] == [200, 200, 429]


def test_rate_limit_zero_turns_it_off(container: Container) -> None:
    app = make_app(container, allow_anonymous_local=True, rate_limit_per_minute=0)
    with local_client(app) as client:
        assert {client.get("/v1/scenes").status_code for _ in range(300)} == {200}


def test_token_bucket_refills_at_the_configured_rate() -> None:
    now = [0.0]
    limiter = RateLimiter(per_minute=120, burst=3, clock=lambda: now[0])  # 2 per second
    assert [limiter.acquire("a") for _ in range(3)] == [0.0, 0.0, 0.0]
    assert limiter.acquire("a") == pytest.approx(0.5)
    assert limiter.acquire("b") == 0.0  # another key has its own bucket
    now[0] = 0.5
    assert limiter.acquire("a") == 0.0
    assert limiter.acquire("a") == pytest.approx(0.5)
    now[0] = 100.0  # a long pause refills up to the burst, not beyond
    assert [limiter.acquire("a") for _ in range(4)][-1] > 0


def test_the_principal_of_a_scoped_route_needs_access_control_in_front() -> None:
    from fastapi import Depends

    from service.auth import require_scope
    from service.errors import install_problem_handlers

    bare = FastAPI()
    install_problem_handlers(bare)

    @bare.get("/admin", dependencies=[Depends(require_scope("admin"))])
    def admin_only() -> dict[str, bool]:
        return {"ok": True}

    with TestClient(bare) as client:
        assert client.get("/admin").status_code == 401


def test_principal_descriptions_name_the_token() -> None:
    token = Principal("token", frozenset({"read"}), "token:abc", token_id="abc", name="robot")
    assert token.describe() == "token abc (robot)"
    assert Principal("anonymous-local", ANONYMOUS_LOCAL_SCOPES, "address:127.0.0.1").describe()


# --- settings ----------------------------------------------------------------------------------


def test_security_settings_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PBDAG_ALLOWED_HOSTS", "robot.lan, 192.168.1.20")
    monkeypatch.setenv("PBDAG_CORS_ORIGINS", '["http://viewer.lan"]')
    monkeypatch.setenv("PBDAG_ALLOW_ANONYMOUS_LOCAL", "true")
    monkeypatch.setenv("PBDAG_RATE_LIMIT_PER_MINUTE", "600")
    settings = Settings()
    assert settings.allowed_hosts == ["robot.lan", "192.168.1.20"]
    assert settings.cors_origins == ["http://viewer.lan"]
    assert settings.allow_anonymous_local is True
    assert settings.rate_limit_per_minute == 600


def test_secure_defaults(monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("ALLOWED_HOSTS", "CORS_ORIGINS", "ALLOW_ANONYMOUS_LOCAL", "RATE_LIMIT_PER_MINUTE"):
        monkeypatch.delenv(f"PBDAG_{name}", raising=False)
    settings = Settings()
    assert settings.allow_anonymous_local is False
    assert settings.allowed_hosts == ["localhost", "127.0.0.1", "::1"]
    assert settings.cors_origins == []
    assert settings.rate_limit_per_minute == 1200


def test_secret_files_set_the_database_url_and_password(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("PBDAG_DATABASE_URL", raising=False)
    monkeypatch.delenv("PBDAG_DATABASE_PASSWORD", raising=False)
    (tmp_path / "pbdag_database_url").write_text("postgresql+psycopg://pbdag@db:5432/pbdag\n")
    (tmp_path / "pbdag_database_password").write_text("s3cr@t/pw\n")
    settings = Settings(_secrets_dir=tmp_path)
    url = sa.make_url(settings.resolved_database_url())
    assert (url.host, url.username, url.password) == ("db", "pbdag", "s3cr@t/pw")
    assert "s3cr@t" not in repr(settings)
    # the environment wins over a secret file
    monkeypatch.setenv("PBDAG_DATABASE_URL", "postgresql+psycopg://other:given@db/x")
    url = sa.make_url(Settings(_secrets_dir=tmp_path).resolved_database_url())
    assert (url.username, url.password) == ("other", "given")


def test_a_missing_secrets_directory_is_no_warning(tmp_path: Path) -> None:
    # pytest turns warnings into errors: this fails if pydantic-settings warns.
    settings = Settings(_secrets_dir=tmp_path / "absent")
    assert settings.database_password is None
