"""Content-addressed blob stores for raw batch payloads: a folder, or a table of PostgreSQL.

A blob's key is the sha256 of its bytes; the bytes are opaque to the store. The queue writes a
batch's blob with its row (`BatchQueue.submit`):

- `PgBlobStore` inserts it on the connection of the transaction that inserts the row
  (`put(content, connection)`), so both commit or roll back together: a crash never leaves a
  queued batch without its blob, nor a blob without its batch. Processes on several hosts then
  share nothing but the database.
- `FileBlobStore` writes the file durably (fsync, rename) before that transaction opens (SQLite's
  write lock is not held over the fsync): a queued batch always has its blob; a crash before the
  commit may leave a file that no batch names, which `keys()` lists for `pbdag gc`'s sweep.
"""

from __future__ import annotations

import hashlib
import os
import re
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Protocol

import sqlalchemy as sa
from sqlalchemy.dialects import postgresql

from service.store.engine import may_pass, write_transaction
from service.store.errors import StoreError, StoreUnavailable
from service.store.tables import blobs

_KEY = re.compile(r"^[0-9a-f]{64}$")


class BlobNotFound(StoreError, KeyError):
    """No blob is stored under the key (never written, or deleted by `pbdag gc`)."""

    def __init__(self, key: str) -> None:
        super().__init__(f"no blob is stored under {key}")
        self.key = key

    def __str__(self) -> str:
        return self.detail  # KeyError's own would quote it


class RawBatchMissing(StoreError):
    """A batch's raw body is not in the blob store, though nothing collected it."""

    def __init__(self, batch_id: str, key: str) -> None:
        super().__init__(f"batch {batch_id!r}: its raw body (blob {key}) is missing", "batch_id")


# A blob no row names may be a batch's being queued now (the folder writes it before the row,
# and a put of bytes already stored refreshes the file's time): it is deleted only this old.
ORPHAN_GRACE_SECONDS = 3600.0


class BlobStore(Protocol):
    """Put bytes, get them back by their sha256, delete them, list the keys.

    `get` of a missing key raises `BlobNotFound`. `delete` is idempotent: it returns whether a
    blob was there. `pbdag gc` deletes through this protocol only. A failure that may pass (the
    disk, the database) is raised as `StoreUnavailable`, whatever the backend.
    """

    # True when `put(content, connection)` commits with that connection's transaction (the
    # queue then writes the blob inside the transaction that inserts the batch's row); False
    # when `put` is durable at once (the queue then writes it before that transaction).
    joins_transaction: bool

    def put(self, content: bytes, connection: sa.Connection | None = None) -> str:
        """Store `content` (idempotent) and return its key. With `connection`, the blob is
        durable once that connection's transaction commits (the enqueue's); without, on return."""
        ...

    def get(self, key: str) -> bytes:
        """The bytes stored under `key`; BlobNotFound if none."""
        ...

    def delete(self, key: str, connection: sa.Connection | None = None) -> bool:
        """Remove the blob; False when there was none. The caller decides that no batch still
        needs it. With `connection`, a store that joins transactions deletes in that one (it
        commits or rolls back with it); any other deletes at once."""
        ...

    def keys(self) -> Iterator[str]:
        """Every stored key, in no particular order."""
        ...

    def stored_at(self, key: str) -> float | None:
        """When the blob was last stored (unix seconds), None when there is none."""
        ...

    def remove_leftovers(self, stored_before: float) -> int:
        """Remove what interrupted writes left behind before that time (a killed `put` or
        `pbdag blobs migrate`); how many. Nothing on a store whose writes are transactions."""
        ...


def blob_key(content: bytes) -> str:
    """The key of `content`: its sha256 in hex."""
    return hashlib.sha256(content).hexdigest()


class FileBlobStore:
    """Blobs under a folder, sharded by hash; written durably before the API answers 202."""

    joins_transaction = False

    def __init__(self, root: Path) -> None:
        self.root = root
        self.root.mkdir(parents=True, exist_ok=True)

    def _path(self, key: str) -> Path:
        return self.root / key[:2] / key[2:4] / key

    def put(self, content: bytes, connection: sa.Connection | None = None) -> str:
        """Store `content` (idempotent) and return its key; durable on return, whatever the
        transaction of `connection` does later."""
        key = blob_key(content)
        path = self._path(key)
        with _disk_failures("writing a blob"):
            if path.exists():
                # Stored again: refreshed, so that gc's sweep of blobs no row names leaves it to
                # the row being written now.
                os.utime(path)
                return key
            path.parent.mkdir(parents=True, exist_ok=True)
            # Write to a temp file, fsync, then rename, so a crash never leaves a torn blob.
            fd, temp_name = tempfile.mkstemp(dir=path.parent, prefix=".incoming-")
            try:
                with os.fdopen(fd, "wb") as handle:
                    handle.write(content)
                    handle.flush()
                    os.fsync(handle.fileno())
                os.replace(temp_name, path)
            except BaseException:
                Path(temp_name).unlink(missing_ok=True)
                raise
            _sync_directory(path.parent)
        return key

    def get(self, key: str) -> bytes:
        """The bytes stored under `key`; BlobNotFound when there are none."""
        with _disk_failures("reading a blob"):
            try:
                return self._path(key).read_bytes()
            except FileNotFoundError:
                raise BlobNotFound(key) from None

    def delete(self, key: str, connection: sa.Connection | None = None) -> bool:
        """Remove the blob (the rename of `put` makes this atomic); False when it was absent.
        At once, whatever `connection` is: a file joins no transaction."""
        path = self._path(key)
        with _disk_failures("deleting a blob"):
            try:
                path.unlink()
            except FileNotFoundError:
                return False
            _sync_directory(path.parent)
        return True

    def keys(self) -> Iterator[str]:
        """Every complete blob (a crash's `.incoming-*` leftovers are not blobs)."""
        for path in self.root.glob("??/??/*"):
            if _KEY.match(path.name) and path.is_file():
                yield path.name

    def stored_at(self, key: str) -> float | None:
        """The blob file's modification time (a `put` of stored bytes refreshes it)."""
        with _disk_failures("reading a blob's time"):
            try:
                return self._path(key).stat().st_mtime
            except FileNotFoundError:
                return None

    def remove_leftovers(self, stored_before: float) -> int:
        """Delete `.incoming-*` temp files last written before that time."""
        removed = 0
        with _disk_failures("removing a blob's leftovers"):
            for path in self.root.glob("??/??/.incoming-*"):
                try:
                    if path.stat().st_mtime < stored_before:
                        path.unlink()
                        removed += 1
                except FileNotFoundError:  # another gc, or the put it belonged to, got there
                    continue
        return removed


@contextmanager
def _disk_failures(what: str) -> Iterator[None]:
    """The folder's OSErrors as the store's StoreUnavailable: a full or failing disk may pass."""
    try:
        yield
    except OSError as error:
        raise StoreUnavailable(what, error) from error


def _sync_directory(directory: Path) -> None:
    """fsync a folder, so that a rename or an unlink in it survives a crash."""
    handle = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(handle)
    finally:
        os.close(handle)


GET_SQL = "SELECT content FROM blobs WHERE key = %s"


class PgBlobStore:
    """Blobs in the `blobs` table of the service's PostgreSQL database (bytea, stored out of
    line without compression: the bytes are opaque and may already be compressed)."""

    joins_transaction = True

    def __init__(self, engine: sa.Engine) -> None:
        if engine.dialect.name != "postgresql":
            raise ValueError(f"PgBlobStore needs PostgreSQL, not {engine.dialect.name}")
        self.engine = engine

    def put(self, content: bytes, connection: sa.Connection | None = None) -> str:
        """Insert the blob on `connection` (it commits with that transaction), or in a
        transaction of its own; a blob already stored is not written again."""
        key = blob_key(content)
        statement = (
            postgresql.insert(blobs)
            .values(key=key, content=content, size=len(content), created_at=time.time())
            .on_conflict_do_nothing(index_elements=[blobs.c.key])
        )
        if connection is not None:
            connection.execute(statement)
        else:
            with write_transaction(self.engine) as own:
                own.execute(statement)
        return key

    def get(self, key: str) -> bytes:
        """The bytes stored under `key`; BlobNotFound when none.

        Read in psycopg's binary format (a bytea in text format travels as hex: 4x slower for a
        batch), past SQLAlchemy: a driver error is translated here as the engine translates its
        own (service.store.engine), StoreUnavailable when it may pass, else SQLAlchemy's."""
        import psycopg

        with self.engine.connect() as connection:
            driver = connection.connection.driver_connection
            assert driver is not None
            try:
                with driver.cursor(binary=True) as cursor:
                    cursor.execute(GET_SQL, (key,))
                    row = cursor.fetchone()
                driver.rollback()  # end the read-only transaction the query opened
            except psycopg.Error as error:
                connection.invalidate()
                translated = sa.exc.DBAPIError.instance(GET_SQL, (key,), error, psycopg.Error)
                if may_pass(translated):
                    raise StoreUnavailable("reading a blob", translated) from error
                raise translated from error
        if row is None:
            raise BlobNotFound(key)
        return bytes(row[0])

    def delete(self, key: str, connection: sa.Connection | None = None) -> bool:
        """Remove the blob's row, in `connection`'s transaction or one of its own; False when
        there was none."""
        statement = sa.delete(blobs).where(blobs.c.key == key)
        if connection is not None:
            return bool(connection.execute(statement).rowcount)
        with write_transaction(self.engine) as own:
            return bool(own.execute(statement).rowcount)

    def keys(self) -> Iterator[str]:
        """Every stored key, streamed (a server-side cursor)."""
        with self.engine.connect() as connection:
            result = connection.execution_options(yield_per=1000).execute(sa.select(blobs.c.key))
            for key in result.scalars():
                yield str(key)

    def stored_at(self, key: str) -> float | None:
        """The blob row's `created_at`."""
        with self.engine.connect() as connection:
            value = connection.execute(
                sa.select(blobs.c.created_at).where(blobs.c.key == key)
            ).scalar()
        return None if value is None else float(value)

    def remove_leftovers(self, stored_before: float) -> int:
        """Nothing: a blob row commits whole or not at all."""
        return 0


class MemoryBlobStore:
    """In-memory blobs for tests."""

    joins_transaction = False

    def __init__(self) -> None:
        self._blobs: dict[str, bytes] = {}
        self._stored: dict[str, float] = {}

    def put(self, content: bytes, connection: sa.Connection | None = None) -> str:
        """Store `content` and return its key."""
        key = blob_key(content)
        self._blobs[key] = content
        self._stored[key] = time.time()
        return key

    def get(self, key: str) -> bytes:
        """The bytes stored under `key`."""
        try:
            return self._blobs[key]
        except KeyError:
            raise BlobNotFound(key) from None

    def delete(self, key: str, connection: sa.Connection | None = None) -> bool:
        """Forget the blob (at once); False when there was none."""
        return self._blobs.pop(key, None) is not None

    def keys(self) -> Iterator[str]:
        """Every stored key."""
        yield from list(self._blobs)

    def stored_at(self, key: str) -> float | None:
        """When `put` last stored it."""
        return self._stored.get(key) if key in self._blobs else None

    def remove_leftovers(self, stored_before: float) -> int:
        """Nothing: memory leaves no leftovers."""
        return 0
