"""Blob stores (folder, PostgreSQL, memory), the backend setting, atomic enqueue, `pbdag blobs migrate`."""

from __future__ import annotations

import hashlib
from collections.abc import Iterator
from pathlib import Path

import pytest
import sqlalchemy as sa

from service.app import create_app
from service.bootstrap import Container, blob_store, build_container
from service.cli import main
from service.settings import Settings, SettingsError
from service.store.blobs import (
    BlobNotFound,
    BlobStore,
    FileBlobStore,
    MemoryBlobStore,
    PgBlobStore,
)
from service.store.engine import make_engine, migrate, write_transaction
from service.store.errors import StoreUnavailable
from service.store.queue_records import Admission
from service.store.tables import batches
from service.store.tables import blobs as blobs_table
from tests.clients import local_client
from tests.conftest import store_backends
from tests.wire_scenes import batch

BOUNDS = Admission(max_queued=100, max_blob_bytes=10**9, retry_after_seconds=2)
STORES = ["memory", "folder", *(["postgres"] if "postgres" in store_backends() else [])]


@pytest.fixture(params=STORES)
def store(
    request: pytest.FixtureRequest, tmp_path: Path
) -> Iterator[tuple[BlobStore, sa.Engine | None]]:
    """A blob store of each kind, with its engine (PostgreSQL only)."""
    if request.param == "memory":
        yield MemoryBlobStore(), None
    elif request.param == "folder":
        yield FileBlobStore(tmp_path / "blobs"), None
    else:
        container = build_container(
            Settings(data_dir=tmp_path / "unused"),
            engine=engine_on_fresh_schema(request),
        )
        yield container.blobs, container.engine
        container.engine.dispose()


def engine_on_fresh_schema(request: pytest.FixtureRequest) -> sa.Engine:
    url, schema = request.getfixturevalue("postgres_schema_url")
    return make_engine(url, connect_args={"options": f"-csearch_path={schema}"})


def test_a_blob_is_named_by_its_sha256_and_can_be_listed_and_deleted(
    store: tuple[BlobStore, sa.Engine | None],
) -> None:
    blobs, _engine = store
    one, two = b"\x00\x01 opaque bytes \xff", bytes(range(256)) * 1000
    key = blobs.put(one)
    assert key == hashlib.sha256(one).hexdigest()
    assert blobs.put(one) == key  # idempotent
    assert blobs.get(key) == one
    other = blobs.put(two)
    assert blobs.get(other) == two
    assert sorted(blobs.keys()) == sorted([key, other])
    assert blobs.delete(key) is True
    assert blobs.delete(key) is False
    assert list(blobs.keys()) == [other]
    with pytest.raises(BlobNotFound):
        blobs.get(key)
    blobs.put(one)
    listing = blobs.keys()  # a collector deletes while it lists
    for stored in listing:
        assert blobs.delete(stored)
    assert list(blobs.keys()) == []


def test_the_folder_lists_complete_blobs_only(tmp_path: Path) -> None:
    blobs = FileBlobStore(tmp_path)
    key = blobs.put(b"kept")
    (tmp_path / key[:2] / key[2:4] / ".incoming-abc").write_bytes(b"torn")  # a crash's leftover
    assert list(blobs.keys()) == [key]


@pytest.mark.skipif("postgres" not in store_backends(), reason="needs PostgreSQL")
def test_a_postgres_blob_rolls_back_with_its_transaction(request: pytest.FixtureRequest) -> None:
    engine = engine_on_fresh_schema(request)
    try:
        migrate(engine)
        blobs = PgBlobStore(engine)
        with pytest.raises(RuntimeError), write_transaction(engine) as connection:
            blobs.put(b"never committed", connection)
            raise RuntimeError("the process dies before the commit")
        assert list(blobs.keys()) == []
        with write_transaction(engine) as connection:
            key = blobs.put(b"committed", connection)
        assert blobs.get(key) == b"committed"
    finally:
        engine.dispose()


def test_a_crash_between_the_blob_and_the_row_leaves_neither_in_postgres(
    container: Container, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The queue writes the blob, then fails before its row: PostgreSQL keeps neither; the
    folder keeps an orphan file (which a collector may remove) and no row."""
    with local_client(create_app(container)) as client:
        scene_id = client.post("/v1/scenes", json={"name": "crash"}).json()["id"]

    def crash() -> float:
        raise RuntimeError("killed between the blob and the queue row")

    monkeypatch.setattr(container.queue, "clock", crash)
    with pytest.raises(RuntimeError):
        container.queue.submit(scene_id, "b0", "a" * 64, b"the raw batch", 1, BOUNDS)
    with container.engine.connect() as connection:
        assert connection.execute(sa.select(sa.func.count()).select_from(batches)).scalar() == 0
    stored = list(container.blobs.keys())
    if isinstance(container.blobs, PgBlobStore):
        assert stored == []
    else:
        assert stored == [hashlib.sha256(b"the raw batch").hexdigest()]


def test_a_repost_writes_no_blob_and_a_refused_batch_none_either(container: Container) -> None:
    with local_client(create_app(container)) as client:
        scene_id = client.post("/v1/scenes", json={"name": "idem"}).json()["id"]
        assert client.post(f"/v1/scenes/{scene_id}/batches", json=batch("b0", 0)).status_code == 202
        (key,) = list(container.blobs.keys())
        assert container.blobs.delete(key)
        assert client.post(f"/v1/scenes/{scene_id}/batches", json=batch("b0", 0)).status_code == 200
        assert list(container.blobs.keys()) == []  # the re-post did not write it again
    tiny = Admission(max_queued=100, max_blob_bytes=10, retry_after_seconds=2)
    with pytest.raises(Exception, match="quota"):
        container.queue.submit(scene_id, "b1", "b" * 64, b"more than ten bytes", 1, tiny)
    assert list(container.blobs.keys()) == []


def test_auto_picks_the_table_on_postgres_and_the_folder_on_sqlite(
    backend: str, container: Container
) -> None:
    expected = PgBlobStore if backend == "postgres" else FileBlobStore
    assert type(container.blobs) is expected


def test_postgres_blobs_on_sqlite_stop_the_command_with_a_clear_message(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    engine = make_engine(f"sqlite:///{tmp_path / 'pbdag.db'}")
    with engine.connect():  # the file exists: the commands below refuse a missing one first
        pass
    with pytest.raises(SettingsError, match="PBDAG_BLOB_BACKEND=postgres needs a PostgreSQL"):
        blob_store(Settings(blob_backend="postgres", data_dir=tmp_path), engine)
    assert type(blob_store(Settings(blob_backend="folder", data_dir=tmp_path), engine)) is (
        FileBlobStore
    )
    monkeypatch.setenv("PBDAG_DATA_DIR", str(tmp_path))
    monkeypatch.delenv("PBDAG_DATABASE_URL", raising=False)
    monkeypatch.setenv("PBDAG_BLOB_BACKEND", "postgres")
    assert main(["worker", "--drain"]) == 2
    error = capsys.readouterr().err
    assert "PBDAG_BLOB_BACKEND=postgres needs a PostgreSQL database" in error
    assert "sqlite" in error and "Traceback" not in error
    monkeypatch.setenv("PBDAG_BLOB_BACKEND", "auto")
    assert main(["blobs", "migrate", "--to", "postgres"]) == 2
    assert "the database is not PostgreSQL" in capsys.readouterr().err
    monkeypatch.setenv("PBDAG_BLOB_BACKEND", "postgres")
    assert main(["migrate"]) == 2  # the one command that may create the database refuses too
    assert "PBDAG_BLOB_BACKEND=postgres needs a PostgreSQL database" in capsys.readouterr().err
    monkeypatch.setenv("PBDAG_BLOB_BACKEND", "sideways")
    with pytest.raises(ValueError, match="blob_backend"):
        Settings()


@pytest.mark.skipif("postgres" not in store_backends(), reason="needs PostgreSQL")
def test_blobs_migrate_copies_checks_resumes_and_goes_back(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    request: pytest.FixtureRequest,
) -> None:
    """Batches queued with folder blobs; `--to postgres` copies them, a second run copies
    nothing, a damaged copy is replaced, a blob gone from both is reported; a worker on the
    table then does them all; `--to folder` brings them to a fresh folder."""
    url, schema = request.getfixturevalue("postgres_schema_url")
    monkeypatch.setenv("PBDAG_DATABASE_URL", f"{url}?options=-csearch_path%3D{schema}")
    monkeypatch.setenv("PBDAG_DATA_DIR", str(tmp_path / "host-a"))
    monkeypatch.setenv("PBDAG_BLOB_BACKEND", "folder")
    container = build_container(Settings(allow_anonymous_local=True))
    try:
        migrate_there_and_back(container, tmp_path, monkeypatch, capsys)
    finally:
        container.engine.dispose()


def migrate_there_and_back(
    container: Container,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    with local_client(create_app(container)) as client:
        scene_id = client.post("/v1/scenes", json={"name": "move"}).json()["id"]
        for i in range(5):
            body = batch(f"b{i}", i, mug=i < 3)
            assert client.post(f"/v1/scenes/{scene_id}/batches", json=body).status_code == 202
    keys = container.queue.blob_keys()
    assert len(keys) == 5 and sorted(container.blobs.keys()) == keys

    assert main(["blobs", "migrate", "--to", "postgres"]) == 0
    out = capsys.readouterr().out
    assert "5 copied" in out and "0 already there" in out and "5/5 blobs" in out
    table = PgBlobStore(container.engine)
    assert sorted(table.keys()) == keys
    assert all(hashlib.sha256(table.get(key)).hexdigest() == key for key in keys)

    with (
        container.engine.begin() as connection
    ):  # a damaged copy, as a torn earlier run might leave
        connection.execute(
            sa.update(blobs_table).where(blobs_table.c.key == keys[0]).values(content=b"torn")
        )
    assert main(["blobs", "migrate", "--to", "postgres"]) == 0
    out = capsys.readouterr().out
    assert "1 copied" in out and "4 already there" in out
    assert table.get(keys[0]) == container.blobs.get(keys[0])

    saved = table.get(keys[1])
    table.delete(keys[1])
    container.blobs.delete(keys[1])
    assert main(["blobs", "migrate", "--to", "postgres"]) == 1
    captured = capsys.readouterr()
    assert "1 missing" in captured.out and keys[1] in captured.err
    table.put(saved)  # back, so that the queue can finish

    monkeypatch.setenv("PBDAG_BLOB_BACKEND", "postgres")
    monkeypatch.setenv("PBDAG_DATA_DIR", str(tmp_path / "host-b"))  # another host, empty
    assert main(["worker", "--drain"]) == 0
    assert "processed 5 batches" in capsys.readouterr().out
    assert container.queue.counts(scene_id) == {"done": 5}
    assert not (tmp_path / "host-b" / "blobs").exists()  # the worker never touched a folder

    first = container.queue.get(scene_id, "b0")  # retention collects one raw body
    assert first is not None
    _marked, deletable = container.queue.mark_collected([first.id])
    assert deletable == {first.blob_key} and table.delete(first.blob_key)
    monkeypatch.setenv("PBDAG_DATA_DIR", str(tmp_path / "host-c"))
    assert main(["blobs", "migrate", "--to", "folder"]) == 0
    out = capsys.readouterr().out
    assert "4 blobs named by the queue" in out and "4 copied" in out
    expected = sorted(set(keys) - {first.blob_key})
    assert sorted(FileBlobStore(tmp_path / "host-c" / "blobs").keys()) == expected


@pytest.mark.skipif("postgres" not in store_backends(), reason="needs PostgreSQL")
def test_a_driver_error_reading_a_postgres_blob_is_translated_as_the_engine_does(
    request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The binary read goes to psycopg directly; a lost connection becomes the store's
    StoreUnavailable (the worker retries it), any other driver error stays SQLAlchemy's."""
    import service.store.blobs

    engine = engine_on_fresh_schema(request)
    try:
        migrate(engine)
        blobs = PgBlobStore(engine)
        key = blobs.put(b"x" * 5000)
        assert blobs.get(key) == b"x" * 5000
        monkeypatch.setattr(service.store.blobs, "GET_SQL", "SELECT content FROM gone WHERE %s")
        with pytest.raises(sa.exc.ProgrammingError, match="gone"):
            blobs.get(key)
        monkeypatch.setattr(
            service.store.blobs,
            "GET_SQL",
            "SELECT content FROM blobs WHERE key = %s AND pg_terminate_backend(pg_backend_pid())",
        )
        with pytest.raises(StoreUnavailable) as lost:
            blobs.get(key)
        assert lost.value.cause_name == "OperationalError"
        monkeypatch.undo()
        assert blobs.get(key) == b"x" * 5000  # the pool replaced the invalidated connection
    finally:
        engine.dispose()


def test_a_failing_folder_is_unavailable_and_a_missing_blob_not_found(tmp_path: Path) -> None:
    """The folder's OSErrors leave the adapter as the store's own errors."""
    blobs = FileBlobStore(tmp_path / "blobs")
    key = blobs.put(b"kept")
    blocked = hashlib.sha256(b"blocked").hexdigest()
    (tmp_path / "blobs" / blocked[:2]).write_bytes(b"a file where a shard folder belongs")
    with pytest.raises(StoreUnavailable) as writing:
        blobs.put(b"blocked")
    assert writing.value.cause_name in ("FileExistsError", "NotADirectoryError")
    (tmp_path / "blobs" / key[:2] / key[2:4] / key).unlink()
    (tmp_path / "blobs" / key[:2] / key[2:4] / key).mkdir()  # a folder where the blob belongs
    with pytest.raises(StoreUnavailable) as reading:
        blobs.get(key)
    assert reading.value.cause_name == "IsADirectoryError"
    never = hashlib.sha256(b"never written").hexdigest()
    with pytest.raises(BlobNotFound, match=f"no blob is stored under {never}"):
        blobs.get(never)


def test_a_database_error_that_may_pass_leaves_the_engine_as_the_stores_own(
    tmp_path: Path,
) -> None:
    """SQLite's write lock held by another writer: StoreUnavailable, the driver's error kept as
    its cause; an error that cannot pass (an integrity error) stays SQLAlchemy's."""
    url = f"sqlite:///{tmp_path / 'x.db'}"
    engine = make_engine(url)
    sa.event.listen(engine, "connect", lambda driver, _: driver.execute("PRAGMA busy_timeout=0"))
    other = sa.create_engine(url, poolclass=sa.NullPool)
    try:
        with other.connect() as holder:
            holder.connection.driver_connection.isolation_level = None  # type: ignore[union-attr]
            holder.exec_driver_sql("BEGIN IMMEDIATE")
            with pytest.raises(StoreUnavailable) as locked, write_transaction(engine):
                pass
            holder.exec_driver_sql("ROLLBACK")
        assert locked.value.cause_name == "OperationalError"
        assert "locked" in str(locked.value.__cause__)
        with pytest.raises(sa.exc.IntegrityError), write_transaction(engine) as connection:
            connection.exec_driver_sql("CREATE TABLE t (id INTEGER PRIMARY KEY)")
            connection.exec_driver_sql("INSERT INTO t VALUES (1), (1)")
    finally:
        engine.dispose()
        other.dispose()
