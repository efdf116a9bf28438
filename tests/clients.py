"""Test clients the service sees as local ones."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient
from starlette.types import ASGIApp

# Starlette's TestClient reports ("testclient", 50000) and Host "testserver" by default: neither
# is a loopback client nor an allowed host name.
LOOPBACK_CLIENT = ("127.0.0.1", 50000)
LOCAL_BASE_URL = "http://localhost"


def local_client(app: ASGIApp, **kwargs: Any) -> TestClient:
    """A TestClient from 127.0.0.1 to Host `localhost` (anonymous local access, when allowed)."""
    kwargs.setdefault("base_url", LOCAL_BASE_URL)
    kwargs.setdefault("client", LOOPBACK_CLIENT)
    return TestClient(app, **kwargs)
