"""Scenes: create, list, read, rename, delete.

Deleting a scene (admin scope, `?confirm=` the scene's id) is the one exception to the
append-only log: the scene's rows go from every table (service/store/scene_deletion.py).
"""

from __future__ import annotations

import dataclasses
from typing import Annotated

from fastapi import APIRouter, Query

from api_schema import Scene, SceneCreate, SceneDeleted, SceneList, SceneRename
from core.errors import InvalidCommand, NotFound
from core.params import Params, deep_merge
from core.profiles import PROFILES
from core.values import BaselineSource
from service.auth import RequireAdmin
from service.commands import create_scene, rename_scene
from service.deps import AnySceneDep, ContainerDep, SceneDep, StatesDep, text_query
from service.store.baselines import read_package
from service.store.errors import SceneNotFound
from service.store.scene_deletion import delete_scene
from service.wire import scene_out

router = APIRouter(prefix="/v1/scenes", tags=["scenes"])


@router.post("", status_code=201, response_model=Scene)
def post_scene(body: SceneCreate, container: ContainerDep) -> Scene:
    """Create a scene; its parameters (the profile's, plus overrides) are recorded as event 0."""
    overrides = deep_merge(dict(PROFILES[body.profile].overrides), body.params or {})
    params = Params.from_dict(overrides)  # InvalidParams (422) names the field
    if body.baseline is None:
        return scene_out(create_scene(container, body.name, params))
    # A later session in the same house: the package's fixtures keep their identities.
    container.log.scene(body.baseline.scene_id)
    stored = read_package(container.engine, body.baseline.scene_id, body.baseline.version)
    if stored is None:
        raise NotFound(
            "baseline", f"{body.baseline.scene_id} v{body.baseline.version}", "baseline.version"
        )
    source = BaselineSource(scene_id=stored.scene_id, version=stored.version, sha256=stored.sha256)
    return scene_out(create_scene(container, body.name, params, stored.package, source))


@router.get("", response_model=SceneList)
def list_scenes(
    container: ContainerDep,
    after: Annotated[
        str | None, text_query("Return the scenes created after this one (a scene id).", 64)
    ] = None,
    limit: Annotated[int, Query(ge=1, le=1000, description="Page size.")] = 100,
) -> SceneList:
    """The scenes with their head seqs, oldest first; `next_after` continues the listing."""
    try:
        page = container.log.scenes(after=after, limit=limit)
    except SceneNotFound:
        raise NotFound("scene", after or "", "after") from None
    return SceneList(
        scenes=[scene_out(record) for record in page],
        next_after=page[-1].id if len(page) == limit else None,
    )


@router.get("/{scene_id}", response_model=Scene)
def get_scene(scene: AnySceneDep) -> Scene:
    """One scene with its head seq and parameters."""
    return scene_out(scene)


@router.patch("/{scene_id}", response_model=Scene)
def patch_scene(scene: SceneDep, body: SceneRename, container: ContainerDep) -> Scene:
    """Rename the scene: a `scene_renamed` event in its log (the name is part of the log, so
    replay and `pbdag rebuild` give the same name); the same name again appends nothing."""
    rename_scene(container, scene.id, body.name)
    return scene_out(container.log.scene(scene.id))


@router.delete("/{scene_id}", response_model=SceneDeleted)
def delete_scene_route(
    _admin: RequireAdmin,
    scene: AnySceneDep,
    container: ContainerDep,
    states: StatesDep,
    confirm: Annotated[
        str | None, text_query("The scene's id again: the deletion cannot be undone.", 64)
    ] = None,
) -> SceneDeleted:
    """Delete the scene and everything it holds (admin scope), quarantined or not: its log,
    projections, queue rows and the raw batches no other scene names. The one exception to the
    append-only log; scenes started from its baselines keep their copy."""
    if confirm != scene.id:
        raise InvalidCommand(
            "confirm must repeat the scene's id to delete it; nothing was deleted", "confirm"
        )
    deleted = delete_scene(container.engine, container.blobs, scene.id)
    states.forget(scene.id)
    return SceneDeleted(**dataclasses.asdict(deleted))
