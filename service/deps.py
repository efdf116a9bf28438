"""FastAPI dependencies as Annotated aliases."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Path, Query, Request

from service.bootstrap import Container
from service.states import StateReader
from service.store.event_log import SceneRecord

# Largest integer a query or path may carry: the databases store 64-bit signed integers.
MAX_INT = 2**63 - 1


def get_container(request: Request) -> Container:
    """The container the app was built with."""
    container: Container = request.app.state.container
    return container


def get_states(request: Request) -> StateReader:
    """The app's state reader (snapshot + tail, with a small cache)."""
    reader: StateReader = request.app.state.states
    return reader


ContainerDep = Annotated[Container, Depends(get_container)]
StatesDep = Annotated[StateReader, Depends(get_states)]
SceneId = Annotated[
    str, Path(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9._:-]+$", description="Scene id.")
]
TrackId = Annotated[
    str, Path(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9._:-]+$", description="Track id.")
]


def existing_scene(scene_id: SceneId, container: ContainerDep) -> SceneRecord:
    """The scene named in the path; SceneNotFound (404) before any work when it is absent."""
    return container.log.scene(scene_id)


SceneDep = Annotated[SceneRecord, Depends(existing_scene)]
AsOf = Annotated[
    int | None, Query(ge=0, le=MAX_INT, description="Seq to travel back to (default: the head).")
]
