"""The client's side of the change feed: the SSE decoder, and the resumption with Last-Event-ID
of `Client.stream_events` and `AsyncClient.stream_events` (on httpx's mock transport)."""

from __future__ import annotations

import asyncio
import json

import httpx
import pytest

from pbdag_client import AsyncClient, Client, ServerError
from pbdag_client.feed import SseDecoder, SseMessage


def decoded(*chunks: bytes) -> list[SseMessage]:
    decoder = SseDecoder()
    return [message for chunk in chunks for message in decoder.feed(chunk)]


def test_messages_fields_comments_and_multi_line_data() -> None:
    stream = b': hello\n\nid: 3\nevent: add\ndata: {"a":\ndata:1}\n\ndata: plain\n\n'
    assert decoded(stream) == [
        SseMessage("add", '{"a":\n1}', "3"),
        SseMessage("message", "plain", "3"),  # the id persists; no event: "message"
    ]


def test_crlf_cr_and_lines_split_across_chunks() -> None:
    whole = b"id: 7\r\nevent: update\r\ndata: x\r\n\r\nid: 8\rdata: y\r\r"
    expected = [SseMessage("update", "x", "7"), SseMessage("message", "y", "8")]
    assert decoded(whole) == expected
    for cut in range(1, len(whole)):  # every split, a CRLF's halves in two chunks included
        assert decoded(whole[:cut], b"", whole[cut:]) == expected, cut
    assert decoded(*(bytes([b]) for b in whole)) == expected


def test_what_is_not_dispatched() -> None:
    assert decoded(b"event: add\n\n") == []  # no data
    assert decoded(b"data: a\n") == []  # not finished by a blank line
    assert decoded(b"id: 1\0\ndata: a\n\n") == [SseMessage("message", "a", None)]
    assert decoded(b"data\n\n") == [SseMessage("message", "", None)]  # a field without colon
    decoder = SseDecoder()
    decoder.feed(b"retry: 1500\nretry: soon\n\n")
    assert decoder.retry_ms == 1500


def test_an_overlong_line_is_refused() -> None:
    decoder = SseDecoder()
    with pytest.raises(ValueError, match="over"):
        decoder.feed(b"data: " + b"x" * (16 * 1024 * 1024 + 1))


def event_message(seq: int) -> bytes:
    body = {
        "seq": seq,
        "type": "add",
        "topic": "object_added",
        "track_id": f"trk-{seq}",
        "state": "tentative",
        "batch_id": None,
        "frame_id": "f",
        "recorded_at": 1.0,
        "details": {},
    }
    return f"id: {seq}\nevent: add\ndata: {json.dumps(body)}\n\n".encode()


class Feed:
    """A server that answers each connection with the next planned answer, noting the
    Last-Event-ID each connection carried."""

    def __init__(self, *answers: httpx.Response) -> None:
        self.answers = list(answers)
        self.last_ids: list[str | None] = []

    def __call__(self, request: httpx.Request) -> httpx.Response:
        self.last_ids.append(request.headers.get("last-event-id"))
        assert request.url.path == "/v1/scenes/s1/events/stream"
        assert request.headers["accept"] == "text/event-stream"
        return self.answers.pop(0)


def sse(*parts: bytes) -> httpx.Response:
    return httpx.Response(
        200, content=b"".join(parts), headers={"content-type": "text/event-stream"}
    )


def unavailable() -> httpx.Response:
    problem = {
        "type": "/problems/too-many-streams",
        "title": "Service Unavailable",
        "status": 503,
        "detail": "busy",
        "field": None,
        "errors": [],
    }
    return httpx.Response(503, json=problem, headers={"retry-after": "0"})


def planned_feed() -> Feed:
    return Feed(
        sse(event_message(0), event_message(1)),  # the connection ends: resumed after 1
        unavailable(),  # a server at its limit: retried
        sse(b'event: dropped\ndata: {"reason": "slow"}\n\n'),  # dropped: resumed
        sse(event_message(1), event_message(2), b": heartbeat\n\n"),  # 1 again: not twice
        sse(event_message(3), b'event: end\ndata: {"reason": "deleted"}\n\n'),
    )


def test_the_client_resumes_with_last_event_id_and_gives_each_seq_once() -> None:
    feed = planned_feed()
    with Client("http://pbdag", transport=httpx.MockTransport(feed)) as client:
        seqs = [event.seq for event in client.stream_events("s1")]
    assert seqs == [0, 1, 2, 3]
    assert feed.last_ids == [None, "1", "1", "1", "2"]


def test_the_async_client_resumes_the_same_way() -> None:
    feed = planned_feed()

    async def consume() -> list[int]:
        transport = httpx.MockTransport(feed)
        async with AsyncClient("http://pbdag", transport=transport) as client:
            return [event.seq async for event in client.stream_events("s1")]

    assert asyncio.run(consume()) == [0, 1, 2, 3]
    assert feed.last_ids == [None, "1", "1", "1", "2"]


def test_failures_in_a_row_raise_the_last_one() -> None:
    feed = Feed(*(unavailable() for _ in range(3)))
    transport = httpx.MockTransport(feed)
    with Client("http://pbdag", transport=transport) as client, pytest.raises(ServerError):
        list(client.stream_events("s1", after=4, max_failures=3))
    assert feed.last_ids == ["4", "4", "4"]
