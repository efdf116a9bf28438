"""`pbdag blobs migrate --to postgres|folder`: copy every blob the queue names to the other backend.

Each blob is read from the source, checked against its key (the sha256 of its bytes), written to
the target, read back and checked again. A blob the target already holds intact is skipped, so
the command is idempotent and an interrupted run resumes where it stopped. The source is left as
it was (a garbage collector may remove it once the fleet runs on the target).
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from service.store.blobs import BlobNotFound, BlobStore


@dataclass
class BlobMigrationReport:
    """What one run of `pbdag blobs migrate` found and did."""

    referenced: int = 0
    copied: int = 0
    already_there: int = 0
    bytes_copied: int = 0
    missing: list[str] = field(default_factory=list)  # in neither backend
    corrupt: list[str] = field(default_factory=list)  # the source's bytes do not match the key
    seconds: float = 0.0

    @property
    def complete(self) -> bool:
        """Every referenced blob is in the target, intact."""
        return not self.missing and not self.corrupt


def intact(store: BlobStore, key: str) -> bool:
    """True when `store` holds the blob `key` and its bytes hash to the key."""
    try:
        content = store.get(key)
    except BlobNotFound:
        return False
    return hashlib.sha256(content).hexdigest() == key


def migrate_blobs(
    keys: Sequence[str],
    source: BlobStore,
    target: BlobStore,
    progress: Callable[[str], None] = print,
    every: int = 100,
) -> BlobMigrationReport:
    """Copy the blobs `keys` from `source` to `target`, checked by sha256 (see the module doc)."""
    started = time.monotonic()
    report = BlobMigrationReport(referenced=len(keys))
    for index, key in enumerate(keys, start=1):
        if intact(target, key):
            report.already_there += 1
        else:
            try:
                content = source.get(key)
            except BlobNotFound:
                report.missing.append(key)
                content = None
            if content is not None:
                if hashlib.sha256(content).hexdigest() != key:
                    report.corrupt.append(key)
                else:
                    target.delete(key)  # a torn or altered copy left by an earlier run
                    if target.put(content) != key or not intact(target, key):
                        raise RuntimeError(f"blob {key}: the target did not keep it intact")
                    report.copied += 1
                    report.bytes_copied += len(content)
        if index % every == 0 or index == len(keys):
            progress(
                f"  {index}/{len(keys)} blobs: {report.copied} copied "
                f"({report.bytes_copied / 1e6:.1f} MB), {report.already_there} already there, "
                f"{len(report.missing) + len(report.corrupt)} unreadable"
            )
    report.seconds = time.monotonic() - started
    return report
