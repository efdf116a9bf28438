"""Test clients the service sees as local ones: Starlette's TestClient, and the typed
`pbdag_client.Client` answered by the app in process."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import httpx
from fastapi.testclient import TestClient
from starlette.types import ASGIApp

from pbdag_client import Client

# Starlette's TestClient reports ("testclient", 50000) and Host "testserver" by default: neither
# is a loopback client nor an allowed host name.
LOOPBACK_CLIENT = ("127.0.0.1", 50000)
LOCAL_BASE_URL = "http://localhost"
# Set again by the transport for the bytes it hands on (TestClient's body is already decoded).
_HOP_HEADERS = frozenset({"host", "content-length", "content-encoding", "transfer-encoding"})


def local_client(app: ASGIApp, **kwargs: Any) -> TestClient:
    """A TestClient from 127.0.0.1 to Host `localhost` (anonymous local access, when allowed)."""
    kwargs.setdefault("base_url", LOCAL_BASE_URL)
    kwargs.setdefault("client", LOOPBACK_CLIENT)
    return TestClient(app, **kwargs)


class AppTransport(httpx.BaseTransport):
    """An httpx transport that hands each request to a TestClient (the app in this process)."""

    def __init__(self, test_client: TestClient) -> None:
        self.test_client = test_client

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        headers = {k: v for k, v in request.headers.items() if k.lower() not in _HOP_HEADERS}
        answer = self.test_client.request(
            request.method,
            request.url.raw_path.decode("ascii"),
            content=request.read(),
            headers=headers,
        )
        kept = [(k, v) for k, v in answer.headers.multi_items() if k.lower() not in _HOP_HEADERS]
        return httpx.Response(answer.status_code, headers=kept, content=answer.content)


@contextmanager
def local_pbdag_client(app: ASGIApp, token: str | None = None, **kwargs: Any) -> Iterator[Client]:
    """The typed client on `app` in process, from 127.0.0.1 (its lifespan runs meanwhile)."""
    with (
        local_client(app, **kwargs) as test_client,
        Client(LOCAL_BASE_URL, token, transport=AppTransport(test_client)) as client,
    ):
        yield client
