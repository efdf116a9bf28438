"""The one place that talks HTTP to the service: find or create the scene, post each batch,
optionally wait until the batches are processed.

Everything else in `ingest` builds `api_schema` models; swapping this module for a typed client
changes nothing else.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import httpx

from api_schema.requests import BatchIn, SceneCreate

FINAL_STATUSES = frozenset({"done", "dead"})
# A full queue (429) or a busy database (503) says when to come back; give up after this long.
MAX_BACKOFF_SECONDS = 600.0


class SinkError(Exception):
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


def _problem(response: httpx.Response, action: str) -> SinkError:
    """A readable error of a refused request (problem+json: detail and field)."""
    try:
        body: Any = response.json()
    except ValueError:
        body = None
    if isinstance(body, dict):
        detail = body.get("detail") or body.get("title") or response.text
        where = f" (field {body['field']})" if body.get("field") else ""
        return SinkError(f"{action}: HTTP {response.status_code}: {detail}{where}")
    return SinkError(f"{action}: HTTP {response.status_code}: {response.text[:500]}")


def _request(
    client: httpx.Client,
    method: str,
    path: str,
    action: str,
    result: SinkResult | None = None,
    **kwargs: Any,
) -> httpx.Response:
    """One request; 429 and 503 are retried after the Retry-After the service sends (counted in
    `result`)."""
    waited = 0.0
    while True:
        try:
            response = client.request(method, path, **kwargs)
        except httpx.TransportError as error:
            raise SinkError(f"{action}: cannot reach {client.base_url}: {error}") from error
        if response.status_code not in (429, 503) or waited >= MAX_BACKOFF_SECONDS:
            return response
        try:
            delay = float(response.headers.get("retry-after", "1"))
        except ValueError:
            delay = 1.0
        delay = min(max(delay, 0.1), 30.0)
        time.sleep(delay)
        waited += delay
        if result is not None:
            result.busy_retries += 1


def find_or_create_scene(client: httpx.Client, scene: str) -> tuple[str, bool]:
    """(scene id, created): the scene whose id or name is `scene`, else a new one named so."""
    response = _request(client, "GET", "/v1/scenes", "list scenes")
    if response.status_code != 200:
        raise _problem(response, "list scenes")
    scenes = response.json()["scenes"]
    by_id = [entry for entry in scenes if entry["id"] == scene]
    if by_id:
        return str(by_id[0]["id"]), False
    named = [entry for entry in scenes if entry["name"] == scene]
    if len(named) > 1:
        ids = ", ".join(entry["id"] for entry in named)
        raise SinkError(
            f"{len(named)} scenes are named {scene!r} ({ids}); pass one's id as --scene"
        )
    if named:
        return str(named[0]["id"]), False
    body = SceneCreate(name=scene).model_dump(mode="json", exclude_none=True)
    response = _request(client, "POST", "/v1/scenes", f"create scene {scene!r}", json=body)
    if response.status_code != 201:
        raise _problem(response, f"create scene {scene!r}")
    return str(response.json()["id"]), True


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
    headers = {"Authorization": f"Bearer {token}"} if token else {}
    with httpx.Client(
        base_url=url.rstrip("/"), headers=headers, timeout=60.0, transport=transport
    ) as client:
        scene_id, created = find_or_create_scene(client, scene)
        result = SinkResult(scene_id=scene_id, scene_created=created)
        for batch in batches:
            action = f"post batch {batch.batch_id}"
            response = _request(
                client,
                "POST",
                f"/v1/scenes/{scene_id}/batches",
                action,
                result,
                json=batch.model_dump(mode="json", exclude_none=True),
            )
            if response.status_code not in (200, 202):
                raise _problem(response, action)
            status = str(response.json()["status"])
            result.posted += 1
            if response.status_code == 200:
                result.accepted_before.add(batch.batch_id)
            result.statuses[batch.batch_id] = status
            if on_posted is not None:
                on_posted(batch, status)
        if wait:
            _wait(client, result, wait_timeout)
        return result


def _status(client: httpx.Client, result: SinkResult, batch_id: str) -> dict[str, Any]:
    """One batch's status record."""
    action = f"status of batch {batch_id}"
    path = f"/v1/scenes/{result.scene_id}/batches/{batch_id}"
    response = _request(client, "GET", path, action, result)
    if response.status_code != 200:
        raise _problem(response, action)
    record: dict[str, Any] = response.json()
    result.statuses[batch_id] = str(record["status"])
    return record


def _wait(client: httpx.Client, result: SinkResult, timeout: float) -> None:
    """Poll the batches until each is done or dead (or the timeout passes); count the events
    that the batches accepted in this run appended."""
    deadline = time.monotonic() + timeout
    appended = 0
    # Batches of a scene are processed in order: poll the oldest unfinished one, then the next.
    for batch_id in list(result.statuses):
        record = _status(client, result, batch_id)
        while record["status"] not in FINAL_STATUSES:
            if time.monotonic() > deadline:
                raise SinkError(f"batch {batch_id} is still {record['status']} after {timeout:g} s")
            time.sleep(0.2)
            record = _status(client, result, batch_id)
        if record["status"] == "dead":
            result.errors[batch_id] = str(record.get("error"))
        first, last = record.get("first_seq"), record.get("last_seq")
        if batch_id not in result.accepted_before and first is not None and last is not None:
            appended += int(last) - int(first) + 1
    result.events_appended = appended
