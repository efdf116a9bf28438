"""What a scene holds in each table, counted by SQL, for the tests of deleting scenes."""

from __future__ import annotations

import sqlalchemy as sa

from service.auth import create_token
from service.bootstrap import Container
from service.store.tables import baselines, batches, events, scenes, snapshots, tracks

SCENE_TABLES = (events, tracks, snapshots, baselines, batches)


def rows_of(engine: sa.Engine, scene_id: str) -> dict[str, int]:
    """The scene's rows in every table that holds them (`scenes` its own row: 0 or 1)."""
    with engine.connect() as connection:
        counted = {
            table.name: int(
                connection.execute(
                    sa.select(sa.func.count()).where(table.c.scene_id == scene_id)
                ).scalar_one()
            )
            for table in SCENE_TABLES
        }
        counted["scenes"] = int(
            connection.execute(
                sa.select(sa.func.count()).where(scenes.c.id == scene_id)
            ).scalar_one()
        )
    return counted


def blob_keys_of(engine: sa.Engine, scene_id: str) -> set[str]:
    """The blob keys the scene's batch rows name."""
    with engine.connect() as connection:
        return set(
            connection.execute(
                sa.select(batches.c.blob_key).where(batches.c.scene_id == scene_id)
            ).scalars()
        )


def bearer(container: Container, *scopes: str) -> dict[str, str]:
    """The Authorization header of a new token with these scopes."""
    token = create_token(container.engine, "-".join(scopes), list(scopes)).token
    return {"Authorization": f"Bearer {token}"}
