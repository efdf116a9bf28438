"""Who the client is, and which host it asked for: the strict Host check, the client address
of rate limits, and anonymous local access, through the app as `pbdag serve` hands it to uvicorn
(X-Forwarded-For read from PBDAG_TRUSTED_PROXIES only)."""

from __future__ import annotations

import socket
from collections.abc import Callable
from pathlib import Path

import pydantic
import pytest
import uvicorn
from fastapi import FastAPI
from fastapi.testclient import TestClient
from starlette.types import ASGIApp

from service.app import create_app
from service.bootstrap import Container
from service.cli import main
from service.security import AllowedHosts, parse_host
from service.settings import Settings
from tests.clients import LOCAL_BASE_URL, LOOPBACK_CLIENT, local_client

BAD_TOKEN = {"Authorization": "Bearer pbdag_0123456789ab_" + "A" * 43}
LAN_CLIENT = ("192.168.1.50", 40000)
HOSTILE_HOSTS = [
    "localhost:80@evil.com",
    "[::1]evil.com",
    "localhost..",
    "evil.com@localhost",
    "localhost:",
    "localhost:0",
    "localhost:65536",
    "localhost:123456",
    "localhost:80:80",
    "localhost:+80",
    "localhost:\u0668\u0660",  # Arabic-Indic digits are digits to str.isdigit
    "local host",
    "local_host",
    "-localhost",
    "localhost-",
    ".localhost",
    "[::1",
    "::1",
    "[fe80::1%eth0]:8000",
    "[127.0.0.1]",
    "127.0.0.1.",
    "127.1",
    "127.0.0.256",
    "a" * 64 + ".localhost",
]
NORMAL_HOSTS = {
    "localhost": "localhost",
    "localhost:8000": "localhost",
    "127.0.0.1:8000": "127.0.0.1",
    "[::1]:8000": "::1",
    "[::1]": "::1",
    "LocalHost:65535": "localhost",
    "localhost.": "localhost",  # the absolute form of the same name
    "[0:0:0:0:0:0:0:1]:1": "::1",
}


# --- the Host header -------------------------------------------------------------------------


@pytest.mark.parametrize("host", HOSTILE_HOSTS)
def test_a_malformed_host_header_is_a_400_naming_the_host(container: Container, host: str) -> None:
    assert parse_host(host) is None
    for allowed in (["localhost", "127.0.0.1", "::1", "evil.com"], ["*"]):
        container.settings.allowed_hosts = allowed
        with local_client(create_app(container)) as client:
            response = client.get("/healthz", headers={b"host": host.encode()})
            assert response.status_code == 400, (host, allowed, response.text)
            assert response.headers["content-type"] == "application/problem+json"
            assert response.json()["field"] == "host"


@pytest.mark.parametrize(("host", "name"), NORMAL_HOSTS.items())
def test_well_formed_host_headers_pass(container: Container, host: str, name: str) -> None:
    assert parse_host(host) == name
    with local_client(create_app(container)) as client:
        response = client.get("/v1/scenes", headers={"host": host})
        assert response.status_code == 200, (host, response.text)


def test_names_and_addresses_compare_in_canonical_form() -> None:
    hosts = AllowedHosts(FastAPI(), ["Robot.LAN.", "[FD00:0::7]:8000", "*.fleet.example"])
    assert hosts.allows("robot.lan:8000") and hosts.allows("ROBOT.lan.")
    assert hosts.allows("[fd00::7]") and hosts.allows("[fd00:0:0::7]:1")
    assert hosts.allows("r1.fleet.example") and not hosts.allows("r1.fleet.example..")
    assert not hosts.allows("") and not hosts.allows("robot.lan:80@evil.com")


# --- client identity, through `pbdag serve` --------------------------------------------------


ServeFn = Callable[..., ASGIApp]


@pytest.fixture
def serve(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> ServeFn:
    """Run `pbdag serve` with these PBDAG_* variables, up to uvicorn's Server.run, and answer the
    ASGI app uvicorn would serve with the options it was given (its proxy-headers layer
    included)."""

    def start(**variables: str) -> ASGIApp:
        monkeypatch.setenv("PBDAG_DATA_DIR", str(tmp_path))
        monkeypatch.delenv("PBDAG_DATABASE_URL", raising=False)
        monkeypatch.setenv("PBDAG_RUN_WORKER", "false")
        monkeypatch.setenv("PBDAG_RATE_LIMIT_PER_MINUTE", "60")
        monkeypatch.setenv("PBDAG_RATE_LIMIT_BURST", "5")
        monkeypatch.setenv("PBDAG_PORT", str(free_port()))  # serve binds it before Server.run
        for name, value in variables.items():
            monkeypatch.setenv(f"PBDAG_{name}", value)
        given: dict[str, uvicorn.Config] = {}

        def run(server: uvicorn.Server, sockets: list[socket.socket] | None = None) -> None:
            given["config"] = server.config
            server.started = True

        monkeypatch.setattr(uvicorn.Server, "run", run)
        assert main(["serve"]) == 0
        config = given["config"]
        config.load()
        served: ASGIApp = config.loaded_app
        return served

    return start


def free_port() -> int:
    """A loopback port nobody listens on."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def statuses(client: TestClient, forwarded_for: list[str | None], **headers: str) -> list[int]:
    """The status of one GET /v1/scenes per X-Forwarded-For value (None: no header)."""
    answers = []
    for value in forwarded_for:
        sent = dict(headers) | ({"X-Forwarded-For": value} if value is not None else {})
        answers.append(client.get("/v1/scenes", headers=sent).status_code)
    return answers


def rotating(count: int) -> list[str | None]:
    return [f"203.0.113.{i}" for i in range(count)]


def test_without_trusted_proxies_the_client_is_the_socket_peer(serve: ServeFn) -> None:
    app = serve()
    # A rotated X-Forwarded-For is no new client: failed attempts reach the limit.
    with TestClient(app, base_url=LOCAL_BASE_URL, client=LOOPBACK_CLIENT) as local:
        assert statuses(local, rotating(8), **BAD_TOKEN) == [401] * 5 + [429] * 3
    with TestClient(app, base_url=LOCAL_BASE_URL, client=LAN_CLIENT) as lan:
        assert statuses(lan, rotating(8), **BAD_TOKEN) == [401] * 5 + [429] * 3


def test_anonymous_local_access_rests_on_the_socket_peer_alone(serve: ServeFn) -> None:
    app = serve(ALLOW_ANONYMOUS_LOCAL="true")
    with TestClient(app, base_url=LOCAL_BASE_URL, client=LOOPBACK_CLIENT) as local:
        # From loopback, as it says, it is local; a forwarded request is somebody else's.
        assert statuses(local, [None, "127.0.0.9", "192.168.1.50"]) == [200, 401, 401]
    with TestClient(app, base_url=LOCAL_BASE_URL, client=LAN_CLIENT) as lan:
        assert statuses(lan, ["127.0.0.1", "::1", None]) == [401, 401, 401]


def test_a_trusted_proxy_names_the_client_but_never_makes_it_local(serve: ServeFn) -> None:
    app = serve(TRUSTED_PROXIES="10.0.0.0/24", ALLOW_ANONYMOUS_LOCAL="true")
    proxy = ("10.0.0.7", 50000)
    with TestClient(app, base_url=LOCAL_BASE_URL, client=proxy) as through:
        # Each client behind the proxy has its own bucket; one client's guesses are limited.
        assert statuses(through, rotating(8), **BAD_TOKEN) == [401] * 8
        assert statuses(through, ["198.51.100.1"] * 6, **BAD_TOKEN) == [401] * 5 + [429]
        assert statuses(through, ["198.51.100.2"], **BAD_TOKEN) == [401]
        # Whatever the proxy says, its clients are not loopback ones.
        assert statuses(through, ["127.0.0.1", "::1", None]) == [401, 401, 401]
    with TestClient(app, base_url=LOCAL_BASE_URL, client=LAN_CLIENT) as lan:  # no proxy
        assert statuses(lan, rotating(6), **BAD_TOKEN) == [401] * 5 + [429]
    with TestClient(app, base_url=LOCAL_BASE_URL, client=LOOPBACK_CLIENT) as local:
        assert statuses(local, [None]) == [200]


def test_a_proxy_on_loopback_is_no_local_client(serve: ServeFn) -> None:
    app = serve(TRUSTED_PROXIES="127.0.0.1", ALLOW_ANONYMOUS_LOCAL="true")
    with TestClient(app, base_url=LOCAL_BASE_URL, client=LOOPBACK_CLIENT) as proxied:
        assert statuses(proxied, [None, "127.0.0.5", "192.168.1.50"]) == [401, 401, 401]
    with TestClient(app, base_url=LOCAL_BASE_URL, client=("127.0.0.2", 50000)) as local:
        assert statuses(local, [None]) == [200]  # another loopback address is no proxy


def test_trusted_proxies_are_addresses_or_networks(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PBDAG_TRUSTED_PROXIES", " 10.1.2.3/8, 127.0.0.1,::1 ")
    assert Settings().trusted_proxies == ["10.0.0.0/8", "127.0.0.1", "::1"]
    monkeypatch.delenv("PBDAG_TRUSTED_PROXIES")
    assert Settings().trusted_proxies == []
    for value in ("*", "proxy.lan", "10.0.0.0/33"):
        monkeypatch.setenv("PBDAG_TRUSTED_PROXIES", value)
        with pytest.raises(pydantic.ValidationError, match="trusted_proxies"):
            Settings()
