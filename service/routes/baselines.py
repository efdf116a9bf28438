"""Frozen baselines: freeze, list, read a package, and the runtime delta after one."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Query

from api_schema import BaselineList, BaselinePackage, Delta
from core.baseline import decide_freeze
from core.errors import NotFound
from core.events import BaselineFrozen
from service.commands import run_command
from service.deps import MAX_INT, ContainerDep, SceneDep
from service.store.baselines import StoredPackage, list_packages, read_package
from service.wire import event_out, package_out, package_summary

router = APIRouter(prefix="/v1/scenes/{scene_id}", tags=["baselines"])
Version = Annotated[int, Query(ge=1, le=MAX_INT, description="Baseline version.")]


def stored_package(container: ContainerDep, scene_id: str, version: int) -> StoredPackage:
    """One stored package; NotFound when the scene has no such version."""
    stored = read_package(container.engine, scene_id, version)
    if stored is None:
        raise NotFound("baseline", f"{scene_id} v{version}", "version")
    return stored


@router.post("/baselines", status_code=201, response_model=BaselinePackage)
def freeze_baseline(scene: SceneDep, container: ContainerDep) -> BaselinePackage:
    """Freeze the confirmed fixtures into an immutable, versioned package; they become pinned."""
    events, _appended = run_command(
        container, scene.id, lambda head: decide_freeze(head, scene.id)[0]
    )
    frozen = events[0]
    assert isinstance(frozen, BaselineFrozen)
    return package_out(stored_package(container, scene.id, frozen.version))


@router.get("/baselines", response_model=BaselineList)
def list_baselines(scene: SceneDep, container: ContainerDep) -> BaselineList:
    """Every frozen baseline of the scene."""
    return BaselineList(
        baselines=[package_summary(p) for p in list_packages(container.engine, scene.id)]
    )


@router.get("/baselines/{version}", response_model=BaselinePackage)
def get_baseline(
    scene: SceneDep,
    container: ContainerDep,
    version: Annotated[int, Path(ge=1, le=MAX_INT, description="Baseline version.")],
) -> BaselinePackage:
    """One package, byte for byte the canonical JSON its sha256 names."""
    return package_out(stored_package(container, scene.id, version))


@router.get("/delta", response_model=Delta)
def get_delta(
    scene: SceneDep,
    container: ContainerDep,
    baseline: Version,
    after: Annotated[
        int | None, Query(ge=0, le=MAX_INT, description="Continue after this seq.")
    ] = None,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
) -> Delta:
    """The runtime delta: every event after the baseline was frozen, paged by seq."""
    stored = stored_package(container, scene.id, baseline)
    cursor = stored.seq if after is None else max(after, stored.seq)
    page = container.log.read(scene.id, after=cursor, limit=limit)
    return Delta(
        scene_id=scene.id,
        baseline=package_summary(stored),
        events=[event_out(e) for e in page],
        next_after=page[-1].seq if len(page) == limit else None,
    )
