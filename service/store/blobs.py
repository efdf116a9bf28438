"""Content-addressed blob store for raw batch payloads (depth never goes into the database)."""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path
from typing import Protocol


class BlobStore(Protocol):
    """Put bytes, get them back by their sha256."""

    def put(self, content: bytes) -> str: ...
    def get(self, key: str) -> bytes: ...


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
        """The bytes stored under `key`."""
        return self._path(key).read_bytes()


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
        """The bytes stored under `key`."""
        return self._blobs[key]
