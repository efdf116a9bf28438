"""The event log, paged by seq cursor."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query

from api_schema import EventOut, EventPage
from service.deps import MAX_INT, AnySceneDep, ContainerDep, text_query
from service.wire import event_out

router = APIRouter(prefix="/v1/scenes/{scene_id}", tags=["events"])


@router.get("/events", response_model=EventPage)
def list_events(
    scene: AnySceneDep,
    container: ContainerDep,
    after: Annotated[
        int,
        Query(
            ge=-1, le=MAX_INT, description="Return events with seq > after (-1: from the start)."
        ),
    ] = -1,
    limit: Annotated[int, Query(ge=1, le=1000, description="Page size.")] = 100,
    track_id: Annotated[str | None, text_query("Only events of this track.", 64)] = None,
    type: Annotated[
        str | None,
        text_query("Only events of this audit type (add, update, confirm, ...), every topic.", 64),
    ] = None,
) -> EventPage:
    """Events after a seq cursor; `next_after` continues the listing (null at the end)."""
    page = container.log.read(
        scene.id, after=after, limit=limit, track_id=track_id, event_type=type
    )
    events: list[EventOut] = [event_out(e) for e in page]
    return EventPage(events=events, next_after=page[-1].seq if len(page) == limit else None)
