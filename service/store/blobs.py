"""Content-addressed blob store for raw batch payloads (depth never goes into the database)."""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path
from typing import Protocol

from core.errors import PbdagError


class BlobNotFound(KeyError):
    """No blob is stored under the key (never written, or deleted by `pbdag gc`)."""


class RawBatchMissing(PbdagError):
    """A batch's raw body is not in the blob store, though nothing collected it."""

    def __init__(self, batch_id: str, key: str) -> None:
        super().__init__(f"batch {batch_id!r}: its raw body (blob {key}) is missing", "batch_id")


class BlobStore(Protocol):
    """Put bytes, get them back by their sha256, delete them.

    `get` of a missing key raises `BlobNotFound`. `delete` is idempotent: it returns whether a
    blob was there. `pbdag gc` deletes through this protocol only.
    """

    def put(self, content: bytes) -> str: ...
    def get(self, key: str) -> bytes: ...
    def delete(self, key: str) -> bool: ...


class FileBlobStore:
    """Blobs under a folder, sharded by hash; written durably before the API answers 202."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.root.mkdir(parents=True, exist_ok=True)

    def _path(self, key: str) -> Path:
        return self.root / key[:2] / key[2:4] / key

    def put(self, content: bytes) -> str:
        """Store `content` (idempotent) and return its key."""
        key = hashlib.sha256(content).hexdigest()
        path = self._path(key)
        if path.exists():
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
        directory = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(directory)
        finally:
            os.close(directory)
        return key

    def get(self, key: str) -> bytes:
        """The bytes stored under `key`; BlobNotFound when there are none."""
        try:
            return self._path(key).read_bytes()
        except FileNotFoundError:
            raise BlobNotFound(key) from None

    def delete(self, key: str) -> bool:
        """Remove the blob (the rename of `put` makes this atomic); False when it was absent."""
        path = self._path(key)
        try:
            path.unlink()
        except FileNotFoundError:
            return False
        directory = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(directory)
        finally:
            os.close(directory)
        return True


class MemoryBlobStore:
    """In-memory blobs for tests."""

    def __init__(self) -> None:
        self._blobs: dict[str, bytes] = {}

    def put(self, content: bytes) -> str:
        """Store `content` and return its key."""
        key = hashlib.sha256(content).hexdigest()
        self._blobs[key] = content
        return key

    def get(self, key: str) -> bytes:
        """The bytes stored under `key`; BlobNotFound when there are none."""
        try:
            return self._blobs[key]
        except KeyError:
            raise BlobNotFound(key) from None

    def delete(self, key: str) -> bool:
        """Remove the blob; False when it was absent."""
        return self._blobs.pop(key, None) is not None
