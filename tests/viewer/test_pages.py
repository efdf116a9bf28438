"""The pages the service serves itself: open without a token, local assets only, strict CSP."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from service.app import create_app
from service.bootstrap import Container
from service.viewer import STATIC_DIR, VIEWER_CSP
from tests.clients import LOCAL_BASE_URL, local_client

REPO = Path(__file__).resolve().parents[2]
LAN_CLIENT = ("192.168.1.50", 40000)  # an address on the robot's LAN: not loopback
SWAGGER = "/static/vendor/swagger-ui-dist"
# src= and href= values in a page.
REFERENCE = re.compile(r"""(?:src|href)=["']([^"']+)["']""")


@pytest.fixture
def lan(container: Container) -> Iterator[TestClient]:
    with TestClient(create_app(container), base_url=LOCAL_BASE_URL, client=LAN_CLIENT) as client:
        yield client


@pytest.fixture
def local(container: Container) -> Iterator[TestClient]:
    with local_client(create_app(container)) as client:
        yield client


def test_the_viewer_and_its_files_load_without_a_token_but_the_data_needs_one(
    lan: TestClient,
) -> None:
    page = lan.get("/viewer")
    assert page.status_code == 200
    assert page.headers["content-type"].startswith("text/html")
    assert page.headers["content-security-policy"] == VIEWER_CSP
    for path in ("/static/viewer/viewer.js", "/static/viewer/viewer.css"):
        asset = lan.get(path)
        assert asset.status_code == 200, path
        assert asset.headers["content-security-policy"] == VIEWER_CSP
        assert asset.headers["x-content-type-options"] == "nosniff"
    assert lan.get(f"{SWAGGER}/swagger-ui-bundle.js").status_code == 200
    for path in ("/v1/scenes", "/docs", "/openapi.json"):
        assert lan.get(path).status_code == 401, path
    assert lan.get("/static/viewer/no-such-file.js").status_code == 404


def test_the_viewer_policy_allows_only_this_origin() -> None:
    directives = dict(
        directive.strip().split(" ", 1) for directive in VIEWER_CSP.split(";") if directive.strip()
    )
    assert directives["default-src"] == "'self'"
    for name, sources in directives.items():
        assert set(sources.split()) <= {"'self'", "'none'"}, name
    assert "unsafe" not in VIEWER_CSP


def test_the_viewer_page_references_only_files_of_the_package(local: TestClient) -> None:
    html = local.get("/viewer").text
    references = REFERENCE.findall(html)
    assert {"/static/viewer/viewer.js", "/static/viewer/viewer.css"} <= set(references)
    for reference in references:
        assert reference.startswith("/static/viewer/"), reference
        assert (STATIC_DIR / reference.removeprefix("/static/")).is_file(), reference
    script = (STATIC_DIR / "viewer" / "viewer.js").read_text()
    assert "://" not in script  # no other host
    assert "eval(" not in script and "innerHTML" not in script


def test_docs_load_swagger_ui_from_the_package(local: TestClient) -> None:
    html = local.get("/docs").text
    references = REFERENCE.findall(html)
    assert sorted(references) == sorted(
        [
            f"{SWAGGER}/swagger-ui.css",
            f"{SWAGGER}/favicon-32x32.png",
            f"{SWAGGER}/swagger-ui-bundle.js",
        ]
    )
    assert "://" not in html
    for reference in references:
        assert local.get(reference).status_code == 200, reference
    assert local.get("/redoc").status_code == 404  # ReDoc came from a CDN: not served


def test_pages_stay_out_of_the_api_document(local: TestClient) -> None:
    paths = local.get("/openapi.json").json()["paths"]
    assert paths
    assert not [path for path in paths if not path.startswith(("/v1/", "/healthz", "/metrics"))]
    assert not [path for path in paths if path.startswith(("/viewer", "/static", "/docs"))]


def test_vendored_swagger_ui_is_the_pinned_release_with_its_licence() -> None:
    script = (REPO / "scripts" / "vendor-assets.sh").read_text()
    pinned = dict(re.findall(r"^(PACKAGE|VERSION|SHA256)=(\S+)", script, flags=re.MULTILINE))
    folder = STATIC_DIR / "vendor" / pinned["PACKAGE"]
    recorded = (folder / "VERSION").read_text().split()
    assert recorded == [
        pinned["PACKAGE"],
        pinned["VERSION"],
        "npm",
        "tarball",
        "sha256",
        pinned["SHA256"],
    ]
    assert "Apache License" in (folder / "LICENSE").read_text()
    for name in ("swagger-ui-bundle.js", "swagger-ui.css", "NOTICE"):
        assert (folder / name).stat().st_size > 0, name
