"""Shared fixtures: a container per store backend (SQLite always, PostgreSQL when it answers)."""

from __future__ import annotations

import functools
import os
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
import sqlalchemy as sa

from service.bootstrap import Container, build_container
from service.settings import Settings
from service.store.engine import make_engine

POSTGRES_URL = os.environ.get(
    "PBDAG_TEST_POSTGRES_URL", "postgresql+psycopg://postgres@127.0.0.1:5432/test"
)


@functools.cache
def postgres_answers() -> bool:
    """True when the test PostgreSQL server accepts a connection."""
    try:
        engine = sa.create_engine(POSTGRES_URL, connect_args={"connect_timeout": 3})
        with engine.connect() as connection:
            connection.execute(sa.text("select 1"))
        engine.dispose()
        return True
    except Exception:
        return False


def store_backends() -> list[str]:
    """SQLite always; PostgreSQL when a server answers, and always on CI (where one must)."""
    if os.environ.get("CI") or postgres_answers():
        return ["sqlite", "postgres"]
    return ["sqlite"]


@pytest.fixture
def postgres_schema_url() -> Iterator[tuple[str, str]]:
    """A fresh schema on the test server, dropped afterwards: (url, schema)."""
    schema = f"pbdag_test_{uuid.uuid4().hex[:10]}"
    admin = sa.create_engine(POSTGRES_URL)
    with admin.begin() as connection:
        connection.execute(sa.text(f'CREATE SCHEMA "{schema}"'))
    try:
        yield POSTGRES_URL, schema
    finally:
        with admin.begin() as connection:
            connection.execute(sa.text(f'DROP SCHEMA "{schema}" CASCADE'))
        admin.dispose()


def engine_for(backend: str, tmp_path: Path, request: pytest.FixtureRequest) -> sa.Engine:
    """An engine on a temporary SQLite file or a fresh PostgreSQL schema."""
    if backend == "sqlite":
        return make_engine(f"sqlite:///{tmp_path / 'pbdag.db'}")
    url, schema = request.getfixturevalue("postgres_schema_url")
    return make_engine(url, connect_args={"options": f"-csearch_path={schema}"})


@pytest.fixture(params=store_backends())
def backend(request: pytest.FixtureRequest) -> str:
    """Name of the store backend under test."""
    return str(request.param)


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    """Settings with a small snapshot interval so snapshots are exercised; loopback clients
    (tests.clients.local_client) need no token."""
    return Settings(
        data_dir=tmp_path / "data",
        snapshot_interval=25,
        lease_seconds=30.0,
        max_attempts=3,
        allow_anonymous_local=True,
    )


@pytest.fixture
def container(
    backend: str, settings: Settings, tmp_path: Path, request: pytest.FixtureRequest
) -> Iterator[Container]:
    """A migrated store on the backend under test, with blobs under the temp dir."""
    engine = engine_for(backend, tmp_path, request)
    built = build_container(settings, engine=engine)
    try:
        yield built
    finally:
        engine.dispose()


SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def real_kitchen() -> Path:
    """The real 7-Scenes kitchen sequence, read where it lies (never copied into the repo)."""
    path = SHARED_DATA / "7scenes-kitchen"
    if not (path / "frame-000000.depth.png").is_file():
        pytest.skip(f"needs the real sequence in ../shared/data ({path} is absent in this clone)")
    return path
