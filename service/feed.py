"""The live change feed: a scene's events as Server-Sent Events, from a seq cursor on, then live.

New events are found the one way every API process can find them, whichever process's worker
appended them: by reading the log. An idle stream reads the scene's row (its head) every
`stream_poll_seconds`, and the events after its cursor (`EventLog.read`, `seq > last`, the
primary key's order) only when the head moved. Nothing is shared between processes but the
database, so N API processes serve the same feed. On PostgreSQL a NOTIFY at each append's
commit wakes the waiting streams early (`service/store/notifications.py`); the poll remains.

The stream is pulled: the log is read only once what was read before has been taken by the
server (each `send` returns when the server's write buffer has room: uvicorn pauses the
writer above its high-water mark), and at most `stream_max_unsent_bytes` of events are read at a
time. A consumer that takes nothing for `stream_write_timeout_seconds` is dropped: a last
`dropped` message (best effort: the consumer may never read it), then the stream ends. A
stream also ends, with an `end` message and its reason, when the scene is deleted, or once a
quarantined scene's log has been sent (a quarantined scene takes no more events). A client
that disconnects ends its stream at once (the disconnect is watched beside the writer). The
database unavailable closes the stream without a message: the consumer resumes.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field

import anyio
import orjson
from starlette.responses import Response
from starlette.types import Message, Receive, Scope, Send

from pbdag_errors import Refused
from service.middleware.methods import HEAD_KEY
from service.settings import Settings
from service.store.errors import SceneNotFound, StoreUnavailable
from service.store.event_log import EventLog, StoredEvent
from service.wire import event_out

MEDIA_TYPE = "text/event-stream"
PAGE_ROWS = 500  # events read at once, fewer when their bytes reach the unsent bound
DROP_NOTICE_SECONDS = 1.0  # how long the last `dropped` message may wait for the consumer
HEARTBEAT = b": heartbeat\n\n"

logger = logging.getLogger("pbdag.feed")


class TooManyStreams(Refused):
    """This process already serves `max_streams` event streams (503 with Retry-After)."""

    def __init__(self, limit: int, retry_after: int) -> None:
        super().__init__(f"this server already serves {limit} event streams; retry later")
        self.retry_after = retry_after


class StreamSlots:
    """The event streams open in this process, at most `limit` of them."""

    def __init__(self, limit: int, retry_after: int = 5) -> None:
        self.limit = limit
        self.retry_after = retry_after
        self.open = 0
        self._lock = threading.Lock()

    def acquire(self) -> None:
        """Take a slot; TooManyStreams when none is free."""
        with self._lock:
            if self.open >= self.limit:
                raise TooManyStreams(self.limit, self.retry_after)
            self.open += 1

    def release(self) -> None:
        """Give a slot back."""
        with self._lock:
            self.open -= 1


@dataclass(frozen=True)
class FeedTiming:
    """How an event stream polls, keeps alive and gives up on a consumer."""

    poll_s: float
    heartbeat_s: float
    write_timeout_s: float
    max_unsent_bytes: int

    @classmethod
    def of(cls, settings: Settings) -> FeedTiming:
        """The timing the settings give."""
        return cls(
            poll_s=settings.stream_poll_seconds,
            heartbeat_s=settings.stream_heartbeat_seconds,
            write_timeout_s=settings.stream_write_timeout_seconds,
            max_unsent_bytes=settings.stream_max_unsent_bytes,
        )


def sse_message(event: str, data: bytes, seq: int | None = None) -> bytes:
    """One SSE message: its id (the seq), its event name and its one line of JSON data."""
    head = b"" if seq is None else b"id: %d\n" % seq
    return head + b"event: " + event.encode() + b"\ndata: " + data + b"\n\n"


def event_message(event: StoredEvent) -> bytes:
    """A log row as its SSE message: the JSON of `GET .../events`, on one line."""
    return sse_message(event.type, event_out(event).model_dump_json().encode(), event.seq)


def reason_message(event: str, reason: str, **more: object) -> bytes:
    """An `end` or `dropped` message: a JSON object with the reason."""
    return sse_message(event, orjson.dumps({"reason": reason, **more}))


@dataclass
class LogCursor:
    """Where a stream is in one scene's log, and what it reads (its filters)."""

    log: EventLog
    scene_id: str
    after: int
    track_id: str | None = None
    event_type: str | None = None
    scanned: int = field(init=False)

    def __post_init__(self) -> None:
        self.scanned = self.after  # every seq up to here has been read (sent or filtered out)

    def step(self, max_bytes: int) -> tuple[bytes, str | None]:
        """The messages of the next events (b"" when none is new) and, when the stream ends,
        why (`deleted`, `quarantined`). Blocking: run in a worker thread."""
        try:
            scene = self.log.scene(self.scene_id)
        except SceneNotFound:
            return b"", "deleted"
        if scene.head_seq <= self.scanned:
            return b"", "quarantined" if scene.quarantined is not None else None
        page = self.log.read(
            self.scene_id,
            after=self.scanned,
            up_to=scene.head_seq,
            limit=PAGE_ROWS,
            track_id=self.track_id,
            event_type=self.event_type,
        )
        chunks: list[bytes] = []
        size = 0
        for event in page:
            message = event_message(event)
            if chunks and size + len(message) > max_bytes:
                return b"".join(chunks), None  # the rest on the next step, read again
            chunks.append(message)
            size += len(message)
            self.scanned = event.seq
        if len(page) < PAGE_ROWS:
            self.scanned = scene.head_seq  # the rest up to the head was filtered out
        return b"".join(chunks), None


class EventStreamResponse(Response):
    """The SSE answer of one stream: pulls from its cursor, writes, keeps alive; releases its
    slot however it ends."""

    media_type = MEDIA_TYPE

    def __init__(
        self,
        cursor: LogCursor,
        timing: FeedTiming,
        release: Callable[[], None],
        idle: Callable[[float], Awaitable[None]] = anyio.sleep,
    ) -> None:
        self.cursor = cursor
        self.timing = timing
        self.release = release
        self.idle = idle  # waits up to its seconds; may return early when the log grew
        self.status_code = 200
        self.background = None
        # No caching, no buffering by a proxy (nginx honours X-Accel-Buffering).
        self.init_headers({"Cache-Control": "no-store", "X-Accel-Buffering": "no"})

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        try:
            start: Message = {
                "type": "http.response.start",
                "status": self.status_code,
                "headers": self.raw_headers,
            }
            await send(start)
            if scope.get(HEAD_KEY):  # the headers are the whole answer to a HEAD
                await send({"type": "http.response.body", "body": b"", "more_body": False})
                return
            async with anyio.create_task_group() as group:
                group.start_soon(_until_disconnect, receive, group.cancel_scope)
                await self._pump(send)
                group.cancel_scope.cancel()
        except OSError:
            pass  # the client went away while a write was under way: nothing more to say
        finally:
            self.release()

    async def _pump(self, send: Send) -> None:
        """Send what the log holds after the cursor, then what comes, until the stream ends."""
        last_write = time.monotonic()
        while True:
            try:
                chunk, ended = await anyio.to_thread.run_sync(
                    self.cursor.step, self.timing.max_unsent_bytes
                )  # `ended` only once every event was read
            except StoreUnavailable as error:  # the consumer resumes once the database is back
                logger.warning("event stream of %s closed: %s", self.cursor.scene_id, error)
                await send({"type": "http.response.body", "body": b"", "more_body": False})
                return
            if chunk:
                message = chunk
            elif ended is not None:
                message = reason_message("end", ended, seq=self.cursor.scanned)
            elif time.monotonic() - last_write >= self.timing.heartbeat_s:
                message = HEARTBEAT
            else:
                await self.idle(self.timing.poll_s)
                continue
            if not await self._write(send, message):
                await self._drop(send)
                return
            last_write = time.monotonic()
            if ended is not None:
                await send({"type": "http.response.body", "body": b"", "more_body": False})
                return
            if not chunk:
                await self.idle(self.timing.poll_s)
            # else catching up: read on at once

    async def _write(self, send: Send, body: bytes) -> bool:
        """One write; False when the consumer did not take it within the write timeout."""
        with anyio.move_on_after(self.timing.write_timeout_s) as deadline:
            await send({"type": "http.response.body", "body": body, "more_body": True})
        return not deadline.cancelled_caught

    async def _drop(self, send: Send) -> None:
        """The last `dropped` message, if the consumer takes it soon; then the stream ends."""
        notice = reason_message(
            "dropped",
            f"the consumer took nothing for {self.timing.write_timeout_s:g} s; "
            "resume with Last-Event-ID",
        )
        with anyio.move_on_after(DROP_NOTICE_SECONDS):
            await send({"type": "http.response.body", "body": notice, "more_body": False})


async def _until_disconnect(receive: Receive, scope: anyio.CancelScope) -> None:
    """Cancel the stream when the client disconnects."""
    while True:
        message = await receive()
        if message["type"] == "http.disconnect":
            scope.cancel()
            return
