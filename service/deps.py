"""FastAPI dependencies as Annotated aliases."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import Depends, Path, Query, Request

from api_schema.requests import PRINTABLE
from service.bootstrap import Container
from service.feed import StreamSlots
from service.settings import Settings
from service.states import StateReader
from service.store.errors import SceneQuarantined
from service.store.event_log import SceneRecord
from service.store.notifications import Wakeups
from service.store.queue_records import Admission

# Largest integer a query or path may carry: the databases store 64-bit signed integers.
MAX_INT = 2**53 - 1  # integers a JSON number carries exactly


def get_container(request: Request) -> Container:
    """The container the app was built with."""
    container: Container = request.app.state.container
    return container


def get_states(request: Request) -> StateReader:
    """The app's state reader (snapshot + tail, with a small cache)."""
    reader: StateReader = request.app.state.states
    return reader


def get_streams(request: Request) -> StreamSlots:
    """The app's event stream slots (this process's open streams)."""
    slots: StreamSlots = request.app.state.streams
    return slots


def get_wakeups(request: Request) -> Wakeups | None:
    """The app's LISTEN/NOTIFY wake-ups (None but on PostgreSQL, while the app runs)."""
    wakeups: Wakeups | None = request.app.state.wakeups
    return wakeups


ContainerDep = Annotated[Container, Depends(get_container)]
StatesDep = Annotated[StateReader, Depends(get_states)]
StreamsDep = Annotated[StreamSlots, Depends(get_streams)]
WakeupsDep = Annotated[Wakeups | None, Depends(get_wakeups)]
SceneId = Annotated[
    str, Path(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9._:-]+$", description="Scene id.")
]
TrackId = Annotated[
    str, Path(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9._:-]+$", description="Track id.")
]


def any_scene(scene_id: SceneId, container: ContainerDep) -> SceneRecord:
    """The scene named in the path, quarantined or not; SceneNotFound (404) when absent."""
    return container.log.scene(scene_id)


def live_scene(scene: Annotated[SceneRecord, Depends(any_scene)]) -> SceneRecord:
    """The scene named in the path; SceneQuarantined (409) once `pbdag repair` quarantined it."""
    if scene.quarantined is not None:
        raise SceneQuarantined(scene.id, scene.quarantined)
    return scene


# Every route but the scene itself and its raw log needs a scene that is not quarantined.
SceneDep = Annotated[SceneRecord, Depends(live_scene)]
AnySceneDep = Annotated[SceneRecord, Depends(any_scene)]


def admission(settings: Settings) -> Admission:
    """The bounds of every scene's queue."""
    return Admission(
        max_queued=settings.max_queued_batches_per_scene,
        max_blob_bytes=settings.max_scene_blob_bytes,
        retry_after_seconds=settings.queue_full_retry_after_seconds,
    )


def text_query(description: str, max_length: int = 200) -> Any:
    """A printable string query parameter (PostgreSQL cannot compare against a NUL)."""
    return Query(max_length=max_length, pattern=PRINTABLE, description=description)


AsOf = Annotated[
    int | None, Query(ge=0, le=MAX_INT, description="Seq to travel back to (default: the head).")
]
