"""The event log, paged by seq cursor."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query

from api_schema import EventOut, EventPage
from service.deps import ContainerDep
from service.store.event_log import StoredEvent

router = APIRouter(prefix="/v1/scenes/{scene_id}", tags=["events"])


def event_out(event: StoredEvent) -> EventOut:
    """Wire form of a log row."""
    return EventOut.model_validate(event, from_attributes=True)


@router.get("/events", response_model=EventPage)
def list_events(
    scene_id: str,
    container: ContainerDep,
    after: Annotated[
        int, Query(ge=-1, description="Return events with seq > after (-1: from the start).")
    ] = -1,
    limit: Annotated[int, Query(ge=1, le=1000, description="Page size.")] = 100,
    track_id: Annotated[str | None, Query(description="Only events of this track.")] = None,
    type: Annotated[
        str | None, Query(description="Only events of this type (add, confirm, ...).")
    ] = None,
) -> EventPage:
    """Events after a seq cursor; `next_after` continues the listing (null at the end)."""
    container.log.scene(scene_id)
    page = container.log.read(
        scene_id, after=after, limit=limit, track_id=track_id, event_type=type
    )
    next_after = page[-1].seq if len(page) == limit else None
    return EventPage(events=[event_out(e) for e in page], next_after=next_after)
