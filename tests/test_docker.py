"""The Docker files keep the service's defaults safe (no Docker engine runs the tests)."""

from __future__ import annotations

import re
from pathlib import Path

import yaml

from tests.import_graph import ROOT, imported_roots

DOCKER = Path(__file__).resolve().parents[1] / "docker"


def test_the_image_runs_as_an_unprivileged_user() -> None:
    dockerfile = (DOCKER / "Dockerfile").read_text()
    users = re.findall(r"^USER\s+(\S+)", dockerfile, flags=re.MULTILINE)
    assert users and users[-1].split(":")[0] not in ("root", "0")
    assert dockerfile.index("USER") > dockerfile.index("pip install")  # installed as root


def test_compose_publishes_on_loopback_and_hard_codes_no_password() -> None:
    text = (DOCKER / "compose.yaml").read_text()
    compose = yaml.safe_load(text)
    assert compose["services"]["api"]["ports"] == ["${PBDAG_PUBLISH:-127.0.0.1}:8000:8000"]
    postgres = compose["services"]["postgres"]["environment"]
    assert "POSTGRES_PASSWORD" not in postgres
    assert postgres["POSTGRES_PASSWORD_FILE"] == "/run/secrets/postgres_password"
    assert compose["secrets"]["postgres_password"]["file"].startswith(
        "${PBDAG_POSTGRES_PASSWORD_FILE:?"
    )  # compose stops with a message when it is unset
    for name in ("api", "worker-1", "worker-2"):
        service = compose["services"][name]
        url = service["environment"]["PBDAG_DATABASE_URL"]
        assert ":" not in url.split("//", 1)[1].split("@", 1)[0]  # user only, no password
        assert {"source": "postgres_password", "target": "pbdag_database_password"} in service[
            "secrets"
        ]


def test_compose_shares_nothing_but_the_database_between_api_and_workers() -> None:
    """The raw batches are in PostgreSQL; no volume is mounted into the API or a worker, so each
    may run on another host."""
    compose = yaml.safe_load((DOCKER / "compose.yaml").read_text())
    assert set(compose["volumes"]) == {"pgdata"}
    for name in ("api", "worker-1", "worker-2"):
        service = compose["services"][name]
        assert "volumes" not in service
        assert service["environment"]["PBDAG_BLOB_BACKEND"] == "postgres"


def test_the_image_copies_every_package_the_service_imports() -> None:
    """`pip install .` in the image sees only what is copied: every package of this repository
    that the service imports, directly or through another one, must be there."""
    copied = set(re.findall(r"^COPY\s+(\w+)\s", (DOCKER / "Dockerfile").read_text(), re.MULTILINE))
    packages = {p.parent.name for p in ROOT.glob("*/__init__.py")}
    needed, todo = set(), ["service"]
    while todo:
        package = todo.pop()
        needed.add(package)
        for path in (ROOT / package).rglob("*.py"):
            todo += sorted((imported_roots(path) & packages) - needed - set(todo))
    assert needed <= copied, f"not copied: {sorted(needed - copied)}"
