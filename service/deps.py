"""FastAPI dependencies as Annotated aliases."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any

from fastapi import Depends, Path, Query, Request
from fastapi.exceptions import RequestValidationError
from pydantic import (
    AwareDatetime,
    Field,
    ValidationError,
    ValidatorFunctionWrapHandler,
    WrapValidator,
)

from api_schema.requests import PRINTABLE
from service.bootstrap import Container
from service.feed import StreamSlots
from service.handoff import Handoff
from service.settings import Settings
from service.states import StateReader
from service.store.errors import SceneQuarantined, SeqOutOfRange
from service.store.event_log import SceneRecord
from service.store.notifications import Wakeups
from service.store.queue_records import Admission

# Largest integer a query or path may carry: the databases store 64-bit signed integers.
MAX_INT = 2**53 - 1  # integers a JSON number carries exactly
MAX_TIMESTAMP = 1e11  # seconds either side of 1970, as a frame's timestamp (api_schema)


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


def get_handoff(request: Request) -> Handoff | None:
    """The hand-off to this process's worker (None when the process runs none)."""
    handoff: Handoff | None = request.app.state.handoff
    return handoff


def get_wakeups(request: Request) -> Wakeups | None:
    """The app's LISTEN/NOTIFY wake-ups (None but on PostgreSQL, while the app runs)."""
    wakeups: Wakeups | None = request.app.state.wakeups
    return wakeups


ContainerDep = Annotated[Container, Depends(get_container)]
StatesDep = Annotated[StateReader, Depends(get_states)]
StreamsDep = Annotated[StreamSlots, Depends(get_streams)]
WakeupsDep = Annotated[Wakeups | None, Depends(get_wakeups)]
HandoffDep = Annotated[Handoff | None, Depends(get_handoff)]
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


SeqQuery = Annotated[
    int | None, Query(ge=0, le=MAX_INT, description="Seq to travel back to (default: the head).")
]


def _one_reason(value: Any, handler: ValidatorFunctionWrapHandler) -> Any:
    """One reason for a time that is neither form (not one per member of the union)."""
    try:
        return handler(value)
    except ValidationError:
        raise ValueError(
            "ISO 8601 with a timezone (2026-12-03T10:15:00Z) or unix seconds, finite, "
            f"within +-{MAX_TIMESTAMP:g}"
        ) from None


# A time on the robot's clock: unix seconds (the frames' range), or ISO 8601 with a timezone.
WallTime = Annotated[
    Annotated[float, Field(ge=-MAX_TIMESTAMP, le=MAX_TIMESTAMP, allow_inf_nan=False)]
    | AwareDatetime,
    WrapValidator(_one_reason),
]
TimeQuery = Annotated[
    WallTime | None,
    Query(
        description="Wall-clock time to travel back to, on the robot's clock (its frames' "
        "timestamps): ISO 8601 with a timezone (`2026-12-03T10:15:00Z`) or unix seconds "
        "(`1796292900.5`). The state after the last batch whose newest frame is at or before "
        "it; 404 before the scene's first batch. Not with `as_of`.",
    ),
]


def invalid_input(field: str, reason: str, where: str = "query") -> RequestValidationError:
    """A 422 naming `field` of the query (or the body), as FastAPI's own validation answers."""
    return RequestValidationError([{"type": "value_error", "loc": (where, field), "msg": reason}])


def seconds(value: float | datetime) -> float:
    """Unix seconds of a WallTime."""
    return value.timestamp() if isinstance(value, datetime) else float(value)


def resolve_as_of(
    scene: AnySceneDep,
    container: ContainerDep,
    as_of: SeqQuery = None,
    as_of_time: TimeQuery = None,
) -> int | None:
    """The seq a read travels back to: `as_of`, or the last seq a batch appended at or before
    `as_of_time` on the robot's clock; None for the head."""
    if as_of_time is None:
        return as_of
    if as_of is not None:
        raise invalid_input("as_of_time", "give as_of or as_of_time, not both")
    at = seconds(as_of_time)
    seq = container.log.seq_at_time(scene.id, at)
    if seq is None:
        raise SeqOutOfRange(
            f"no batch of scene {scene.id!r} is at or before {at:.3f} s", "as_of_time"
        )
    return seq


# The seq to read at: `as_of` or `as_of_time` (both: 422), None for the head.
AsOf = Annotated[int | None, Depends(resolve_as_of)]
