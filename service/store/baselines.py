"""Reads of the frozen baseline packages (the `baselines` projection)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import orjson
import sqlalchemy as sa

from core.baseline import BaselinePackage
from service.store.engine import read_transaction
from service.store.tables import baselines


@dataclass(frozen=True)
class StoredPackage:
    """One frozen package: where it was frozen, its hash and its canonical content."""

    scene_id: str
    version: int
    seq: int
    sha256: str
    package: BaselinePackage


def read_package(engine: sa.Engine, scene_id: str, version: int) -> StoredPackage | None:
    """The package of a scene's baseline `version`, or None."""
    with read_transaction(engine) as connection:
        row = connection.execute(
            sa.select(baselines).where(
                baselines.c.scene_id == scene_id, baselines.c.version == version
            )
        ).first()
    if row is None:
        return None
    return _package(scene_id, row)


def list_packages(engine: sa.Engine, scene_id: str) -> list[StoredPackage]:
    """Every package of a scene, by version."""
    with read_transaction(engine) as connection:
        rows = connection.execute(
            sa.select(baselines)
            .where(baselines.c.scene_id == scene_id)
            .order_by(baselines.c.version)
        ).all()
    return [_package(scene_id, row) for row in rows]


def _package(scene_id: str, row: sa.Row[Any]) -> StoredPackage:
    # The projection's own canonical JSON, written from `core.baseline.baseline_package`.
    package = cast(BaselinePackage, orjson.loads(row.body))
    return StoredPackage(scene_id, row.version, row.seq, row.sha256, package)
