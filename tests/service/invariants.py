"""What must hold of a store after any fault: blobs and rows agree, projections equal a replay."""

from __future__ import annotations

from service.bootstrap import Container
from service.store.projection import rebuild_scene


def blobs_agree_with_rows(container: Container, scene_id: str) -> set[str]:
    """Every row not collected has its blob and every blob is held by such a row (the store
    holds this one scene); the blob keys."""
    keys = set(container.blobs.keys())
    records = container.queue.of_scene(scene_id)
    held = {r.blob_key for r in records if r.blob_collected_at is None}
    assert held <= keys, "a row a worker may claim points at a missing blob"
    assert keys <= held, f"{len(keys - held)} blobs without a row that holds them"
    return keys


def projections_equal_a_replay(container: Container, scene_id: str) -> None:
    """The scene's projections are what a replay of its log writes."""
    report = rebuild_scene(container.log, scene_id)
    assert report.identical, report
