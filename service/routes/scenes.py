"""Scenes: create, list, read."""

from __future__ import annotations

from fastapi import APIRouter

from api_schema import Scene, SceneCreate, SceneList
from core.params import Params
from service.commands import create_scene_from_baseline
from service.deps import ContainerDep
from service.errors import FieldError, ProblemError
from service.routes.baselines import read_package
from service.store.event_log import SceneRecord

router = APIRouter(prefix="/v1/scenes", tags=["scenes"])


class InvalidParams(ProblemError):
    """A parameter override that does not fit the method's parameter tree."""

    status = 422
    title = "Invalid parameters"
    type = "/problems/invalid-params"


def scene_out(record: SceneRecord) -> Scene:
    """Wire form of a scene row."""
    return Scene.model_validate(record, from_attributes=True)


@router.post("", status_code=201, response_model=Scene)
def create_scene(body: SceneCreate, container: ContainerDep) -> Scene:
    """Create a scene; its parameters (defaults plus overrides) are recorded as event 0."""
    try:
        params = Params.from_dict(body.params)
    except ValueError as error:
        field = str(error).split(":", 1)[0]
        raise InvalidParams(
            str(error), field=field, errors=[FieldError(field, str(error))]
        ) from error
    if body.baseline is None:
        return scene_out(container.log.create_scene(body.name, params))
    # A later session in the same house: the package's fixtures keep their identities.
    source = read_package(container, body.baseline.scene_id, body.baseline.version)
    reference = {"scene_id": source.scene_id, "version": source.version, "sha256": source.sha256}
    return scene_out(
        create_scene_from_baseline(container, body.name, params, source.package, reference)
    )


@router.get("", response_model=SceneList)
def list_scenes(container: ContainerDep) -> SceneList:
    """Every scene with its head seq."""
    return SceneList(scenes=[scene_out(record) for record in container.log.scenes()])


@router.get("/{scene_id}", response_model=Scene)
def get_scene(scene_id: str, container: ContainerDep) -> Scene:
    """One scene with its head seq and parameters."""
    return scene_out(container.log.scene(scene_id))
