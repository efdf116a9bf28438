"""The event log, paged by seq cursor, and its live feed (Server-Sent Events)."""

from __future__ import annotations

import functools
from typing import Annotated, Any

import anyio
from fastapi import APIRouter, Header, Query
from starlette.responses import Response

from api_schema import EventOut, EventPage
from service.deps import MAX_INT, AnySceneDep, ContainerDep, StreamsDep, WakeupsDep, text_query
from service.feed import MEDIA_TYPE, EventStreamResponse, FeedTiming, LogCursor
from service.wire import event_out

router = APIRouter(prefix="/v1/scenes/{scene_id}", tags=["events"])

After = Annotated[
    int,
    Query(ge=-1, le=MAX_INT, description="Return events with seq > after (-1: from the start)."),
]
TrackFilter = Annotated[str | None, text_query("Only events of this track.", 64)]
TypeFilter = Annotated[
    str | None,
    text_query("Only events of this audit type (add, update, confirm, ...), every topic.", 64),
]
STREAM_ANSWER: dict[int | str, dict[str, Any]] = {
    200: {
        "description": "Server-Sent Events: each event as `id: <seq>`, `event: <type>`, "
        "`data: <the event's JSON>`; `: heartbeat` comments while idle; `event: end` (the scene "
        "was deleted, or a quarantined scene's log was sent) or `event: dropped` (the consumer "
        "took nothing within PBDAG_STREAM_WRITE_TIMEOUT_SECONDS) with a JSON reason, last.",
        "content": {MEDIA_TYPE: {"schema": {"type": "string"}}},
    }
}


@router.get("/events", response_model=EventPage)
def list_events(
    scene: AnySceneDep,
    container: ContainerDep,
    after: After = -1,
    limit: Annotated[int, Query(ge=1, le=1000, description="Page size.")] = 100,
    track_id: TrackFilter = None,
    type: TypeFilter = None,
) -> EventPage:
    """Events after a seq cursor; `next_after` continues the listing (null at the end)."""
    page = container.log.read(
        scene.id, after=after, limit=limit, track_id=track_id, event_type=type
    )
    events: list[EventOut] = [event_out(e) for e in page]
    return EventPage(events=events, next_after=page[-1].seq if len(page) == limit else None)


@router.get("/events/stream", response_class=Response, responses=STREAM_ANSWER)
def stream_events(
    scene: AnySceneDep,
    container: ContainerDep,
    streams: StreamsDep,
    wakeups: WakeupsDep,
    after: After = -1,
    track_id: TrackFilter = None,
    type: TypeFilter = None,
    last_event_id: Annotated[
        int | None,
        Header(
            alias="Last-Event-ID",
            ge=-1,
            le=MAX_INT,
            description="The seq of the last event received: a resuming consumer's cursor "
            "(wins over `after`).",
        ),
    ] = None,
) -> Response:
    """The events after a seq cursor, then every new one as it is appended, as Server-Sent
    Events with the filters and the event JSON of `GET .../events`."""
    cursor = LogCursor(
        container.log,
        scene.id,
        after if last_event_id is None else last_event_id,
        track_id=track_id,
        event_type=type,
    )
    idle = anyio.sleep if wakeups is None else functools.partial(wakeups.wait, scene.id)
    streams.acquire()  # 503 when this process serves PBDAG_MAX_STREAMS already
    timing = FeedTiming.of(container.settings)
    return EventStreamResponse(cursor, timing, streams.release, idle)
