"""The live change feed on the client side: an SSE decoder, and the resuming reader both clients use.

`SseDecoder` parses the `text/event-stream` format as the HTML standard defines it (section
9.2.6): lines end in CRLF, LF or CR, even split across chunks; `:` lines are comments; `data`
lines of one message are joined with newlines; a blank line dispatches the message; the id
persists from message to message. `Resume` is what `Client.stream_events` and
`AsyncClient.stream_events` share: the cursor (the seq of the last event received, sent as
`Last-Event-ID` on every reconnection), which messages end the stream, and the bounded backoff
between attempts.
"""

from __future__ import annotations

import asyncio
import json
import random
import time
from collections.abc import AsyncIterator, Callable, Iterator
from dataclasses import dataclass, field

import httpx

from api_schema import EventOut
from pbdag_client.errors import RateLimited, ServerError, problem_error

__all__ = ["Resume", "SseDecoder", "SseMessage", "follow", "follow_async"]

MAX_LINE_BYTES = 16 * 1024 * 1024  # a line longer than this is no stream of this service
FIRST_DELAY_S = 0.1
MAX_DELAY_S = 5.0
CONTROL = ("end", "dropped")
# What a reconnection may mend: the connection lost, a server restarting or too busy.
PASSING = (
    httpx.TransportError,
    ServerError,
    RateLimited,
)  # the stream's own messages (events are named by audit type)


@dataclass(frozen=True)
class SseMessage:
    """One dispatched message: its event name (`message` when none was given), its data (the
    data lines joined with newlines) and the last event id seen (None before any)."""

    event: str
    data: str
    id: str | None


@dataclass
class SseDecoder:
    """An incremental `text/event-stream` parser: `feed` bytes, get the messages completed."""

    last_id: str | None = None
    retry_ms: int | None = None
    _buffer: bytes = b""
    _after_cr: bool = False
    _event: str = ""
    _data: list[str] = field(default_factory=list)

    def feed(self, chunk: bytes) -> list[SseMessage]:
        """The messages `chunk` completes."""
        if not chunk:
            return []
        if self._after_cr and chunk.startswith(b"\n"):
            chunk = chunk[1:]  # the LF of a CRLF split across chunks
        self._after_cr = chunk.endswith(b"\r")
        text = self._buffer + chunk
        lines = text.replace(b"\r\n", b"\n").replace(b"\r", b"\n").split(b"\n")
        self._buffer = lines.pop()
        if len(self._buffer) > MAX_LINE_BYTES:
            raise ValueError(f"an event stream line is over {MAX_LINE_BYTES} bytes")
        messages: list[SseMessage] = []
        for line in lines:
            message = self._line(line.decode("utf-8", errors="replace"))
            if message is not None:
                messages.append(message)
        return messages

    def _line(self, line: str) -> SseMessage | None:
        if not line:
            return self._dispatch()
        if line.startswith(":"):
            return None  # a comment (the server's heartbeat)
        name, colon, value = line.partition(":")
        if colon and value.startswith(" "):
            value = value[1:]
        if name == "event":
            self._event = value
        elif name == "data":
            self._data.append(value)
        elif name == "id" and "\0" not in value:
            self.last_id = value
        elif name == "retry" and value.isdigit():
            self.retry_ms = int(value)
        return None

    def _dispatch(self) -> SseMessage | None:
        event, data = self._event or "message", self._data
        self._event, self._data = "", []
        if not data:
            return None  # no data field: nothing is dispatched
        return SseMessage(event, "\n".join(data), self.last_id)


@dataclass
class Resume:
    """The cursor and the retry policy of one consumer across its connections.

    `max_failures` consecutive failed attempts (no event between them) raise the last error;
    the delay between attempts doubles from 0.1 s up to `max_delay_s`, with jitter, or follows
    a 503's Retry-After (capped the same).
    """

    after: int = -1
    max_failures: int = 10
    max_delay_s: float = MAX_DELAY_S
    failures: int = 0
    ended: str | None = None  # why the server ended the stream for good (`end`)

    def headers(self) -> dict[str, str]:
        """The request headers of the next attempt."""
        headers = {"Accept": "text/event-stream", "Cache-Control": "no-store"}
        if self.after >= 0:
            headers["Last-Event-ID"] = str(self.after)
        return headers

    def check(self, response: httpx.Response) -> None:
        """Raise the typed error of an error answer (after reading its body)."""
        if response.is_error:
            raise problem_error(response)

    def accept(self, message: SseMessage) -> EventOut | None:
        """The event a message carries, None for one already seen or not an event. `end` (the
        scene deleted, or a quarantined scene's log complete) sets `ended`: no reconnection.
        `dropped` needs nothing: the connection ends and the next one resumes."""
        if message.event == "end":
            self.ended = _reason(message.data)
            return None
        if message.event in CONTROL:
            return None
        event = EventOut.model_validate_json(message.data)
        if event.seq <= self.after:
            return None  # already given to the caller (never expected; never given twice)
        self.after = event.seq
        self.failures = 0
        return event

    def delay(self, error: Exception | None) -> float:
        """Seconds before the next attempt after a connection ended (with `error`, or cleanly
        when None); re-raises `error` once `max_failures` attempts in a row failed (the clients
        raise an answer a retry cannot change, a 4xx other than 429, without retrying)."""
        self.failures += 1
        if error is not None and self.failures >= self.max_failures:
            raise error
        retry_after = _retry_after(error)
        if retry_after is not None:
            return float(min(retry_after, self.max_delay_s))
        backoff = min(FIRST_DELAY_S * 2.0 ** (self.failures - 1), self.max_delay_s)
        return backoff * (0.5 + random.random() / 2)


def _reason(data: str) -> str:
    """The `reason` of an `end` message's JSON (the data itself if it is no such object)."""
    try:
        value = json.loads(data)
    except ValueError:
        return data
    return str(value.get("reason", data)) if isinstance(value, dict) else data


def _retry_after(error: Exception | None) -> float | None:
    headers = getattr(error, "headers", None)
    value = None if headers is None else headers.get("retry-after")
    if value is None or not value.isdigit():
        return None
    return float(value)


def follow(
    http: httpx.Client, request: Callable[[], httpx.Request], resume: Resume
) -> Iterator[EventOut]:
    """The events of the stream `request` builds, over as many connections as it takes."""
    while True:
        error: Exception | None = None
        attempt = request()
        attempt.headers.update(resume.headers())
        try:
            response = http.send(attempt, stream=True)
            try:
                if response.is_error:
                    response.read()
                    resume.check(response)
                decoder = SseDecoder()
                for chunk in response.iter_bytes():
                    for message in decoder.feed(chunk):
                        event = resume.accept(message)
                        if event is not None:
                            yield event
                        elif resume.ended is not None:
                            return
            finally:
                response.close()
        except PASSING as failure:
            error = failure
        time.sleep(resume.delay(error))


async def follow_async(
    http: httpx.AsyncClient, request: Callable[[], httpx.Request], resume: Resume
) -> AsyncIterator[EventOut]:
    """`follow` for asyncio."""
    while True:
        error: Exception | None = None
        attempt = request()
        attempt.headers.update(resume.headers())
        try:
            response = await http.send(attempt, stream=True)
            try:
                if response.is_error:
                    await response.aread()
                    resume.check(response)
                decoder = SseDecoder()
                async for chunk in response.aiter_bytes():
                    for message in decoder.feed(chunk):
                        event = resume.accept(message)
                        if event is not None:
                            yield event
                        elif resume.ended is not None:
                            return
            finally:
                await response.aclose()
        except PASSING as failure:
            error = failure
        await asyncio.sleep(resume.delay(error))
