"""The one place that talks to the service, through the typed client: find or create the scene,
post each batch, optionally wait until the batches are processed.

Everything else in `ingest` builds `api_schema` models.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TypeVar

import httpx

from api_schema.requests import BatchIn
from api_schema.responses import BatchStatus
from pbdag_client import ApiError, Client, RateLimited, ServerError, scenes_called
from pbdag_client.errors import retry_after_seconds
from pbdag_errors import PbdagError

FINAL_STATUSES = frozenset({"done", "dead"})
# A full queue (429) or a busy database (503) says when to come back; give up after this long.
MAX_BACKOFF_SECONDS = 600.0


class SinkError(PbdagError):
    """The service refused a request or could not be reached; the message says why."""


@dataclass
class SinkResult:
    """What the service did with the batches."""

    scene_id: str
    scene_created: bool
    posted: int = 0
    accepted_before: set[str] = field(default_factory=set)  # the same batch sent before
    statuses: dict[str, str] = field(default_factory=dict)  # batch id -> last known status
    events_appended: int | None = None  # by the batches first accepted now; known when waited
    errors: dict[str, str] = field(default_factory=dict)  # dead batch id -> its error
    busy_retries: int = 0  # requests repeated after a 429 (queue full, rate limit) or a 503


_T = TypeVar("_T")


def _readable(error: ApiError, action: str) -> SinkError:
    """A refused request as one line: what was asked, the status, the detail and the field."""
    where = f" (field {error.field})" if error.field else ""
    hint = ""
    if error.status == 409 and action.startswith("post batch"):
        # The same batch ids with other content: a re-ingest with other options, or another
        # recording under the same name.
        hint = "; to post it anew, give other batch ids (--batch-prefix) or another --scene"
    return SinkError(f"{action}: HTTP {error.status}: {error.detail}{where}{hint}")


def _call(
    client: Client, action: str, request: Callable[[], _T], result: SinkResult | None = None
) -> _T:
    """One request through the typed client; a 429 (queue full, rate limit) or a 503 (database
    busy) is repeated after the Retry-After the service sends (counted in `result`)."""
    waited = 0.0
    while True:
        try:
            return request()
        except (RateLimited, ServerError) as error:
            if error.status not in (429, 503) or waited >= MAX_BACKOFF_SECONDS:
                raise _readable(error, action) from error
            delay = retry_after_seconds(error.headers.get("retry-after"))
            delay = min(max(1.0 if delay is None else delay, 0.1), 30.0)
            time.sleep(delay)
            waited += delay
            if result is not None:
                result.busy_retries += 1
        except ApiError as error:
            raise _readable(error, action) from error
        except httpx.TransportError as error:
            raise SinkError(f"{action}: cannot reach {client.base_url}: {error}") from error


def find_or_create_scene(client: Client, scene: str) -> tuple[str, bool]:
    """(scene id, created): the scene whose id or name is `scene`, else a new one named so."""
    named = scenes_called(_call(client, "list scenes", client.scenes), scene)
    if len(named) > 1:
        ids = ", ".join(entry.id for entry in named)
        raise SinkError(
            f"{len(named)} scenes are named {scene!r} ({ids}); pass one's id as --scene"
        )
    if named:
        return named[0].id, False
    created = _call(client, f"create scene {scene!r}", lambda: client.create_scene(scene))
    return created.id, True


def post_batches(
    url: str,
    scene: str,
    batches: Iterable[BatchIn],
    *,
    token: str | None = None,
    wait: bool = False,
    wait_timeout: float = 600.0,
    on_posted: Callable[[BatchIn, str], None] | None = None,
    transport: httpx.BaseTransport | None = None,
) -> SinkResult:
    """Post `batches` (consumed lazily, one at a time) to the scene `scene` (an id, or a name:
    found, else created) of the service at `url`; with `wait`, poll until every batch is done or
    dead and count the events they appended."""
    with Client(url, token, timeout=60.0, transport=transport) as client:
        scene_id, created = find_or_create_scene(client, scene)
        result = SinkResult(scene_id=scene_id, scene_created=created)
        for batch in batches:
            submitted = _call(
                client,
                f"post batch {batch.batch_id}",
                functools.partial(client.submit_batch, scene_id, batch),
                result,
            )
            status = submitted.status.status
            result.posted += 1
            if not submitted.new:
                result.accepted_before.add(batch.batch_id)
            result.statuses[batch.batch_id] = status
            if on_posted is not None:
                on_posted(batch, status)
        if wait:
            _wait(client, result, wait_timeout)
        return result


def _status(client: Client, result: SinkResult, batch_id: str) -> BatchStatus:
    """One batch's status record."""
    record = _call(
        client,
        f"status of batch {batch_id}",
        lambda: client.batch(result.scene_id, batch_id),
        result,
    )
    result.statuses[batch_id] = record.status
    return record


def _wait(client: Client, result: SinkResult, timeout: float) -> None:
    """Poll the batches until each is done or dead (or the timeout passes); count the events
    that the batches accepted in this run appended."""
    deadline = time.monotonic() + timeout
    appended = 0
    # Batches of a scene are processed in order: poll the oldest unfinished one, then the next.
    for batch_id in list(result.statuses):
        record = _status(client, result, batch_id)
        while record.status not in FINAL_STATUSES:
            if time.monotonic() > deadline:
                raise SinkError(f"batch {batch_id} is still {record.status} after {timeout:g} s")
            time.sleep(0.2)
            record = _status(client, result, batch_id)
        if record.status == "dead":
            result.errors[batch_id] = str(record.error)
        first, last = record.first_seq, record.last_seq
        if batch_id not in result.accepted_before and first is not None and last is not None:
            appended += last - first + 1
    result.events_appended = appended
