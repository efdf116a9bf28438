"""Frozen baselines: freeze, list, read a package, and the runtime delta after one."""

from __future__ import annotations

from typing import Annotated

import orjson
import sqlalchemy as sa
from fastapi import APIRouter, Query

from api_schema import BaselineList, BaselinePackage, BaselineSummary, Delta
from core.baseline import decide_freeze
from service.commands import run_command
from service.deps import ContainerDep
from service.errors import NotFound
from service.routes.events import event_out
from service.store.engine import read_transaction
from service.store.tables import baselines

router = APIRouter(prefix="/v1/scenes/{scene_id}", tags=["baselines"])


def read_package(container: ContainerDep, scene_id: str, version: int) -> BaselinePackage:
    """One stored package; NotFound when the scene has no such version."""
    container.log.scene(scene_id)
    with read_transaction(container.engine) as connection:
        row = connection.execute(
            sa.select(baselines).where(
                baselines.c.scene_id == scene_id, baselines.c.version == version
            )
        ).first()
    if row is None:
        raise NotFound("baseline", f"{scene_id} v{version}")
    return BaselinePackage(
        scene_id=scene_id,
        version=row.version,
        seq=row.seq,
        sha256=row.sha256,
        package=orjson.loads(row.body),
    )


def summary(package: BaselinePackage) -> BaselineSummary:
    """The package's version, seq, hash and size."""
    return BaselineSummary(
        version=package.version,
        seq=package.seq,
        sha256=package.sha256,
        fixture_count=len(package.package["fixtures"]),
    )


@router.post("/baselines", status_code=201, response_model=BaselinePackage)
def freeze_baseline(scene_id: str, container: ContainerDep) -> BaselinePackage:
    """Freeze the confirmed fixtures into an immutable, versioned package; they become pinned."""
    _state, events, _seqs = run_command(
        container, scene_id, lambda head: decide_freeze(head, scene_id)[0]
    )
    return read_package(container, scene_id, int(events[0].details["version"]))


@router.get("/baselines", response_model=BaselineList)
def list_baselines(scene_id: str, container: ContainerDep) -> BaselineList:
    """Every frozen baseline of the scene."""
    container.log.scene(scene_id)
    with read_transaction(container.engine) as connection:
        versions = (
            connection.execute(
                sa.select(baselines.c.version)
                .where(baselines.c.scene_id == scene_id)
                .order_by(baselines.c.version)
            )
            .scalars()
            .all()
        )
    return BaselineList(baselines=[summary(read_package(container, scene_id, v)) for v in versions])


@router.get("/baselines/{version}", response_model=BaselinePackage)
def get_baseline(scene_id: str, version: int, container: ContainerDep) -> BaselinePackage:
    """One package, byte for byte the canonical JSON its sha256 names."""
    return read_package(container, scene_id, version)


@router.get("/delta", response_model=Delta)
def get_delta(
    scene_id: str,
    container: ContainerDep,
    baseline: Annotated[int, Query(ge=1, description="Baseline version.")],
    after: Annotated[int | None, Query(ge=0, description="Continue after this seq.")] = None,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
) -> Delta:
    """The runtime delta: every event after the baseline was frozen, paged by seq."""
    package = read_package(container, scene_id, baseline)
    cursor = package.seq if after is None else max(after, package.seq)
    page = container.log.read(scene_id, after=cursor, limit=limit)
    return Delta(
        scene_id=scene_id,
        baseline=summary(package),
        events=[event_out(e) for e in page],
        next_after=page[-1].seq if len(page) == limit else None,
    )
