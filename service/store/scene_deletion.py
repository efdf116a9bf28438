"""Deleting a whole scene: the one exception to the append-only log.

Nothing else updates or deletes an event row. An administrator's deliberate deletion of a scene
(`DELETE /v1/scenes/{id}`, `pbdag scenes delete`) removes everything the scene holds, in one
transaction: its events, its projections (tracks, snapshots, baseline packages), its queue rows
whatever their status, and its scene row. What it leaves is consistent: no row names the scene.

The raw batch blobs go too, those that no other scene's batch row names (`pbdag repair` copies
a batch's row into the repaired scene with the same blob): PostgreSQL's blob table in the same
transaction, a folder's files after the commit (a file deleted before the commit could be
needed by a rollback), those no put touched within `ORPHAN_GRACE_SECONDS`: a batch of another
scene with the same bytes may be being queued (the folder writes the file, or refreshes its
time, before the row commits). A younger file, or one the folder cannot delete, is left to
`pbdag gc`, whose sweep deletes blobs no row names once they are as old (service/retention.py).

Writers of the scene meet a scene that is gone: the scene row is locked first, so an append
that was waiting for it finds no head to move (`ConcurrencyConflict`), and a worker's fenced
completion finds no batch row (`LeaseLost`); the worker then drops the batch
(service/worker.py). Every row that names a scene has a foreign key to it, so nothing written
later can bring the scene back.

A scene created from this scene's baseline package keeps working: its event 0 names the package
(scene, version, sha256) as a value and its event 1 holds the fixtures; nothing reads the
source scene again.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import sqlalchemy as sa

from service.store.blobs import ORPHAN_GRACE_SECONDS, BlobStore
from service.store.engine import read_transaction, write_transaction
from service.store.errors import SceneNotFound, StoreUnavailable
from service.store.tables import baselines, batches, events, scenes, snapshots, tracks

logger = logging.getLogger("pbdag.store")

CHUNK = 500  # keys per IN (...) list
clock = time.time  # when the files are judged (a test moves it on)


@dataclass(frozen=True)
class SceneDeletion:
    """What deleting a scene removed."""

    scene_id: str
    events: int
    tracks: int
    snapshots: int
    baselines: int
    batches: int
    blobs: int  # raw batch blobs deleted (a folder's that could not be deleted are not counted)
    bytes: int  # their sizes, as their batch rows recorded them


def delete_scene(engine: sa.Engine, blobs: BlobStore, scene_id: str) -> SceneDeletion:
    """Delete the scene and everything it holds (see the module's docstring); SceneNotFound
    when there is no such scene, and then nothing is deleted."""
    with write_transaction(engine) as connection:
        # Locked first (PostgreSQL; SQLite's write transaction holds the whole database): an
        # append to the scene waits, then finds no row to move the head of.
        locked = connection.execute(
            sa.select(scenes.c.id).where(scenes.c.id == scene_id).with_for_update()
        ).first()
        if locked is None:
            raise SceneNotFound(scene_id)
        sizes = _blob_sizes(connection, scene_id)
        removed = {
            table.name: int(
                connection.execute(sa.delete(table).where(table.c.scene_id == scene_id)).rowcount
            )
            for table in (snapshots, tracks, baselines, events, batches)
        }
        connection.execute(sa.delete(scenes).where(scenes.c.id == scene_id))
        unnamed = sorted(set(sizes) - _still_named(connection, sorted(sizes)))
        deleted: list[str] = []
        if blobs.joins_transaction:
            deleted = [key for key in unnamed if blobs.delete(key, connection)]
    if not blobs.joins_transaction:
        deleted = _delete_files(engine, blobs, unnamed)
    return SceneDeletion(
        scene_id=scene_id,
        events=removed["events"],
        tracks=removed["tracks"],
        snapshots=removed["snapshots"],
        baselines=removed["baselines"],
        batches=removed["batches"],
        blobs=len(deleted),
        bytes=sum(sizes[key] for key in deleted),
    )


def _blob_sizes(connection: sa.Connection, scene_id: str) -> dict[str, int]:
    """The blobs the scene's batch rows still hold (not collected by `pbdag gc`), by key."""
    rows = connection.execute(
        sa.select(batches.c.blob_key, sa.func.max(batches.c.blob_bytes))
        .where(batches.c.scene_id == scene_id, batches.c.blob_collected_at.is_(None))
        .group_by(batches.c.blob_key)
    ).all()
    return {str(key): int(size) for key, size in rows}


def _still_named(connection: sa.Connection, keys: list[str]) -> set[str]:
    """The keys among these that a batch row (of another scene, once this one's are gone)
    names."""
    named: set[str] = set()
    for start in range(0, len(keys), CHUNK):
        named |= set(
            connection.execute(
                sa.select(batches.c.blob_key)
                .where(batches.c.blob_key.in_(keys[start : start + CHUNK]))
                .distinct()
            ).scalars()
        )
    return named


def _delete_files(engine: sa.Engine, blobs: BlobStore, keys: list[str]) -> list[str]:
    """After the commit: the files no row names now and no put touched within the grace. A
    batch of another scene with the same bytes may be being queued at this moment (its put
    writes or refreshes the file before its row commits); such a file, and any younger one, is
    left to `pbdag gc`'s sweep, which applies the same grace."""
    if not keys:
        return []
    with read_transaction(engine) as connection:
        named = _still_named(connection, keys)
    cutoff = clock() - ORPHAN_GRACE_SECONDS
    deleted = []
    for key in keys:
        stored = blobs.stored_at(key)
        if key in named or stored is None or stored >= cutoff:
            continue
        if _delete_file(blobs, key):
            deleted.append(key)
    return deleted


def _delete_file(blobs: BlobStore, key: str) -> bool:
    """Delete a blob after the commit; a failure leaves it to `pbdag gc`'s sweep."""
    try:
        return blobs.delete(key)
    except StoreUnavailable as error:
        logger.warning("blob %s of a deleted scene is left to `pbdag gc`: %s", key, error.detail)
        return False
