"""Snapshots written by an older body codec: still read by as_of, rewritten by rebuild."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import sqlalchemy as sa

from core.params import Params
from service.bootstrap import Container
from service.commands import create_scene
from service.settings import Settings
from service.store.projection import rebuild_scene
from service.store.snapshot_codec import SNAPSHOT_VERSION, SNAPSHOT_VERSION_ROWS, encode_snapshot
from service.store.tables import snapshots
from tests.service.minimal_events import added, append_batch, missed
from tests.service.snapshot_bodies import rows_body


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    """A snapshot after every append."""
    return Settings(data_dir=tmp_path / "data", snapshot_interval=1, lease_seconds=30.0)


def _scene_with_snapshots(container: Container) -> tuple[str, list[int]]:
    scene = create_scene(container, "s", Params())
    append_batch(container, scene.id, [added("trk-000001"), added("trk-000002", 2.0)])
    append_batch(container, scene.id, [missed("trk-000001", 0.3, 1)])
    seqs = container.log.snapshot_seqs(scene.id)
    assert seqs
    return scene.id, seqs


def _store_rows_body(container: Container, scene_id: str, seq: int, body: bytes) -> None:
    with container.engine.begin() as connection:
        connection.execute(
            sa.update(snapshots)
            .where(snapshots.c.scene_id == scene_id, snapshots.c.seq == seq)
            .values(format_version=SNAPSHOT_VERSION_ROWS, body=body)
        )


def test_as_of_reads_a_snapshot_of_the_former_body_version(container: Container) -> None:
    scene_id, seqs = _scene_with_snapshots(container)
    last = seqs[-1]
    state = container.log.load_state(scene_id, last)
    marked = dataclasses.replace(state, name="read from the version 3 body")
    _store_rows_body(container, scene_id, last, rows_body(marked))
    assert container.log.load_state(scene_id, last).name == "read from the version 3 body"
    _store_rows_body(container, scene_id, last, rows_body(state))
    assert container.log.load_state(scene_id, last) == state
    assert container.log.load_state(scene_id).to_dict() == container.log.replay(scene_id).to_dict()


def test_rebuild_rewrites_former_bodies_as_snapshots_rewritten(container: Container) -> None:
    scene_id, seqs = _scene_with_snapshots(container)
    states = {seq: container.log.load_state(scene_id, seq) for seq in seqs}
    for seq, state in states.items():
        _store_rows_body(container, scene_id, seq, rows_body(state))
    report = rebuild_scene(container.log, scene_id)
    assert report.identical and report.snapshots_reencoded == len(seqs)
    assert not report.snapshots_differ
    with container.engine.begin() as connection:
        stored = connection.execute(
            sa.select(snapshots.c.seq, snapshots.c.format_version, snapshots.c.body).where(
                snapshots.c.scene_id == scene_id
            )
        ).all()
    assert sorted((row.seq, row.format_version) for row in stored) == [
        (seq, SNAPSHOT_VERSION) for seq in seqs
    ]
    assert all(bytes(row.body) == encode_snapshot(states[row.seq]) for row in stored)
