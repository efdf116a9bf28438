"""`Client` and `AsyncClient`: every route of the v1 API, typed with the `api_schema` models.

Each route is described once (`_Call`: method, path, query, body and how to read the answer);
the two clients only differ in how they send it. Error answers raise the typed exceptions of
`pbdag_client.errors`.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any, Generic, Literal, TypeVar
from urllib.parse import quote

import httpx
from pydantic import BaseModel, TypeAdapter

from api_schema import (
    BaselineList,
    BaselinePackage,
    BaselineRef,
    BaselineSummary,
    BatchIn,
    BatchStatus,
    CommandResult,
    Delta,
    EventOut,
    EventPage,
    Explanation,
    Graph,
    Health,
    Inspection,
    InspectionIn,
    InspectionList,
    InspectionQueue,
    InspectionQueueItem,
    ObjectPage,
    Occupancy,
    PlanIn,
    PlanOut,
    RobotPose,
    Scene,
    SceneCreate,
    SceneDeleted,
    SceneList,
    SceneRename,
    SimilarIn,
    SimilarOut,
    TrackBelief,
    TrackHistory,
    VerdictIn,
    VerificationItem,
    VerificationList,
)
from pbdag_client.errors import BatchDead, BatchTimeout, RateLimited, problem_error
from pbdag_client.feed import Resume, follow, follow_async

__all__ = ["DEFAULT_TIMEOUT_S", "AsyncClient", "Client", "WallTime"]

DEFAULT_TIMEOUT_S = 30.0
EVENTS_PAGE_SIZE = 1000  # the largest page the service serves
FINISHED = ("done", "dead")
_SSE = "text/event-stream"

T = TypeVar("T")
M = TypeVar("M", bound=BaseModel)
Query = dict[str, str | int | float]
_TRACKS = TypeAdapter(list[TrackBelief])
# A time on the robot's clock (`as_of_time`): a timezone-aware datetime, unix seconds, or ISO 8601.
WallTime = datetime | float | str


@dataclass(frozen=True)
class _Call(Generic[T]):
    """One request of the API and how to read its answer."""

    method: str
    path: str
    read: Callable[[httpx.Response], T]
    query: Query | None = None
    body: BaseModel | None = None
    accept: str = "application/json"


@dataclass(frozen=True)
class Submitted:
    """A posted batch: its status, and whether this post queued it (202) or the same batch had
    been accepted before (200, the original's status)."""

    status: BatchStatus
    new: bool


def _submitted(response: httpx.Response) -> Submitted:
    return Submitted(BatchStatus.model_validate_json(response.content), response.status_code == 202)


def _no_body(_response: httpx.Response) -> None:
    return None


def _model(cls: type[M]) -> Callable[[httpx.Response], M]:
    return lambda response: cls.model_validate_json(response.content)


def _segment(value: str | int) -> str:
    """A path segment, percent-encoded."""
    return quote(str(value), safe="")


def _scene(scene_id: str) -> str:
    return f"/v1/scenes/{_segment(scene_id)}"


def _query(**values: str | int | float | None) -> Query:
    """Query parameters, leaving out those not given."""
    return {name: value for name, value in values.items() if value is not None}


def _wall(value: WallTime | None) -> str | float | None:
    """A wall-clock time as the query carries it (a datetime in ISO 8601)."""
    return value.isoformat() if isinstance(value, datetime) else value


def scenes_called(scenes: Sequence[Scene], name_or_id: str) -> list[Scene]:
    """The scene whose id is `name_or_id`, else every scene named so, oldest first (what a
    command line's `--scene NAME_OR_ID` means)."""
    by_id = [scene for scene in scenes if scene.id == name_or_id]
    return by_id or [scene for scene in scenes if scene.name == name_or_id]


class _Routes:
    """The v1 API's routes as `_Call`s (shared by both clients)."""

    @staticmethod
    def health() -> _Call[Health]:
        return _Call("GET", "/healthz", _model(Health))

    @staticmethod
    def create_scene(body: SceneCreate) -> _Call[Scene]:
        return _Call("POST", "/v1/scenes", _model(Scene), body=body)

    @staticmethod
    def scenes(after: str | None) -> _Call[SceneList]:
        return _Call("GET", "/v1/scenes", _model(SceneList), _query(after=after))

    @staticmethod
    def scene(scene_id: str) -> _Call[Scene]:
        return _Call("GET", _scene(scene_id), _model(Scene))

    @staticmethod
    def rename_scene(scene_id: str, name: str) -> _Call[Scene]:
        return _Call("PATCH", _scene(scene_id), _model(Scene), body=SceneRename(name=name))

    @staticmethod
    def delete_scene(scene_id: str, confirm: str) -> _Call[SceneDeleted]:
        query = _query(confirm=confirm)
        return _Call("DELETE", _scene(scene_id), _model(SceneDeleted), query)

    @staticmethod
    def post_batch(scene_id: str, batch: BatchIn) -> _Call[BatchStatus]:
        return _Call("POST", f"{_scene(scene_id)}/batches", _model(BatchStatus), body=batch)

    @staticmethod
    def submit_batch(scene_id: str, batch: BatchIn) -> _Call[Submitted]:
        return _Call("POST", f"{_scene(scene_id)}/batches", _submitted, body=batch)

    @staticmethod
    def batch(scene_id: str, batch_id: str) -> _Call[BatchStatus]:
        path = f"{_scene(scene_id)}/batches/{_segment(batch_id)}"
        return _Call("GET", path, _model(BatchStatus))

    @staticmethod
    def requeue_batch(scene_id: str, batch_id: str) -> _Call[BatchStatus]:
        path = f"{_scene(scene_id)}/batches/{_segment(batch_id)}/requeue"
        return _Call("POST", path, _model(BatchStatus))

    @staticmethod
    def graph(
        scene_id: str,
        as_of: int | None,
        include: Literal["published", "all"],
        parent: str | None,
        label: str | None,
        as_of_time: WallTime | None = None,
    ) -> _Call[Graph]:
        query = _query(
            as_of=as_of, as_of_time=_wall(as_of_time), include=include, parent=parent, label=label
        )
        return _Call("GET", f"{_scene(scene_id)}/graph", _model(Graph), query)

    @staticmethod
    def events_page(
        scene_id: str, after: int, limit: int, track_id: str | None, type: str | None
    ) -> _Call[EventPage]:
        query = _query(after=after, limit=limit, track_id=track_id, type=type)
        return _Call("GET", f"{_scene(scene_id)}/events", _model(EventPage), query)

    @staticmethod
    def events_stream(
        scene_id: str, after: int, track_id: str | None, type: str | None
    ) -> _Call[None]:
        query = _query(after=after, track_id=track_id, type=type)
        return _Call("GET", f"{_scene(scene_id)}/events/stream", _no_body, query, accept=_SSE)

    @staticmethod
    def tracks(
        scene_id: str, label: str | None, state: str | None, parent: str | None
    ) -> _Call[list[TrackBelief]]:
        query = _query(label=label, state=state, parent=parent)
        return _Call(
            "GET", f"{_scene(scene_id)}/tracks", lambda r: _TRACKS.validate_json(r.content), query
        )

    @staticmethod
    def track(
        scene_id: str, track_id: str, as_of: int | None, as_of_time: WallTime | None = None
    ) -> _Call[TrackBelief]:
        path = f"{_scene(scene_id)}/tracks/{_segment(track_id)}"
        query = _query(as_of=as_of, as_of_time=_wall(as_of_time))
        return _Call("GET", path, _model(TrackBelief), query)

    @staticmethod
    def objects(
        scene_id: str,
        filters: Mapping[str, str | int | float | None],
        as_of: int | None,
        as_of_time: WallTime | None,
    ) -> _Call[ObjectPage]:
        query = _query(**filters, as_of=as_of, as_of_time=_wall(as_of_time))
        return _Call("GET", f"{_scene(scene_id)}/objects", _model(ObjectPage), query)

    @staticmethod
    def similar(
        scene_id: str, body: SimilarIn, as_of: int | None, as_of_time: WallTime | None
    ) -> _Call[SimilarOut]:
        path = f"{_scene(scene_id)}/objects/similar"
        query = _query(as_of=as_of, as_of_time=_wall(as_of_time))
        return _Call("POST", path, _model(SimilarOut), query, body)

    @staticmethod
    def history(
        scene_id: str,
        track_id: str,
        after: int,
        limit: int,
        as_of: int | None,
        as_of_time: WallTime | None,
    ) -> _Call[TrackHistory]:
        path = f"{_scene(scene_id)}/tracks/{_segment(track_id)}/history"
        query = _query(after=after, limit=limit, as_of=as_of, as_of_time=_wall(as_of_time))
        return _Call("GET", path, _model(TrackHistory), query)

    @staticmethod
    def explain(scene_id: str, track_id: str, events: bool) -> _Call[Explanation]:
        path = f"{_scene(scene_id)}/tracks/{_segment(track_id)}/explain"
        return _Call("GET", path, _model(Explanation), _query(events="true" if events else None))

    @staticmethod
    def verifications(
        scene_id: str, status: Literal["pending", "all"]
    ) -> _Call[list[VerificationItem]]:
        return _Call(
            "GET",
            f"{_scene(scene_id)}/verifications",
            lambda r: VerificationList.model_validate_json(r.content).verifications,
            _query(status=status),
        )

    @staticmethod
    def post_verdict(scene_id: str, track_id: str, verdict: VerdictIn) -> _Call[CommandResult]:
        path = f"{_scene(scene_id)}/tracks/{_segment(track_id)}/verification"
        return _Call("POST", path, _model(CommandResult), body=verdict)

    @staticmethod
    def freeze_baseline(scene_id: str) -> _Call[BaselinePackage]:
        return _Call("POST", f"{_scene(scene_id)}/baselines", _model(BaselinePackage))

    @staticmethod
    def baselines(scene_id: str) -> _Call[list[BaselineSummary]]:
        return _Call(
            "GET",
            f"{_scene(scene_id)}/baselines",
            lambda r: BaselineList.model_validate_json(r.content).baselines,
        )

    @staticmethod
    def baseline(scene_id: str, version: int) -> _Call[BaselinePackage]:
        path = f"{_scene(scene_id)}/baselines/{_segment(version)}"
        return _Call("GET", path, _model(BaselinePackage))

    @staticmethod
    def delta(scene_id: str, baseline: int, after: int | None, limit: int) -> _Call[Delta]:
        query = _query(baseline=baseline, after=after, limit=limit)
        return _Call("GET", f"{_scene(scene_id)}/delta", _model(Delta), query)

    @staticmethod
    def post_inspection(scene_id: str, inspection: InspectionIn) -> _Call[Inspection]:
        return _Call("POST", f"{_scene(scene_id)}/inspections", _model(Inspection), body=inspection)

    @staticmethod
    def inspections(scene_id: str) -> _Call[list[Inspection]]:
        return _Call(
            "GET",
            f"{_scene(scene_id)}/inspections",
            lambda r: InspectionList.model_validate_json(r.content).inspections,
        )

    @staticmethod
    def inspection_queue(scene_id: str) -> _Call[list[InspectionQueueItem]]:
        return _Call(
            "GET",
            f"{_scene(scene_id)}/inspection-queue",
            lambda r: InspectionQueue.model_validate_json(r.content).fixtures,
        )

    @staticmethod
    def plan(scene_id: str, robot_pose: RobotPose) -> _Call[PlanOut]:
        body = PlanIn(robot_pose=robot_pose)
        return _Call("POST", f"{_scene(scene_id)}/plan", _model(PlanOut), body=body)

    @staticmethod
    def preview_plan(
        scene_id: str,
        x: float,
        y: float,
        yaw: float,
        as_of: int | None,
        as_of_time: WallTime | None = None,
    ) -> _Call[PlanOut]:
        query = _query(x=x, y=y, yaw=yaw, as_of=as_of, as_of_time=_wall(as_of_time))
        return _Call("GET", f"{_scene(scene_id)}/plan", _model(PlanOut), query)

    @staticmethod
    def occupancy(
        scene_id: str, as_of: int | None, as_of_time: WallTime | None = None
    ) -> _Call[Occupancy]:
        query = _query(as_of=as_of, as_of_time=_wall(as_of_time), format="json")
        return _Call("GET", f"{_scene(scene_id)}/occupancy", _model(Occupancy), query)

    @staticmethod
    def occupancy_png(
        scene_id: str, as_of: int | None, as_of_time: WallTime | None = None
    ) -> _Call[bytes]:
        query = _query(as_of=as_of, as_of_time=_wall(as_of_time), format="png")
        return _Call(
            "GET", f"{_scene(scene_id)}/occupancy", lambda r: r.content, query, accept="image/png"
        )


def _scene_create(
    name: str,
    params: Mapping[str, Any] | None,
    baseline: BaselineRef | None,
    profile: Literal["extended", "paper"] = "extended",
) -> SceneCreate:
    given: dict[str, Any] = {"name": name}
    if profile != "extended":  # a server older than profiles knows only the default
        given["profile"] = profile
    if params is not None:
        given["params"] = dict(params)
    if baseline is not None:
        given["baseline"] = baseline
    return SceneCreate(**given)


def _headers(token: str | None) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"} if token else {}


def _request(http: httpx.Client | httpx.AsyncClient, call: _Call[Any]) -> httpx.Request:
    # Fields left at their defaults stay off the wire: the service applies the same defaults.
    content = None if call.body is None else call.body.model_dump_json(exclude_unset=True).encode()
    headers = {"Accept": call.accept}
    if content is not None:
        headers["Content-Type"] = "application/json"
    return http.build_request(
        call.method, call.path, params=call.query, content=content, headers=headers
    )


def _answer(call: _Call[T], response: httpx.Response) -> T:
    if response.is_error:
        raise problem_error(response)
    return call.read(response)


def _poll_wait(error: RateLimited, poll_interval_s: float) -> float:
    """How long to wait after a 429 while polling."""
    retry_after = error.retry_after
    return max(poll_interval_s, 1.0 if retry_after is None else retry_after)


class Client:
    """The PBD-AG API over HTTP, synchronously.

    `base_url` is the service's root (`http://127.0.0.1:8000`); `token` a bearer token (none for
    a service that allows anonymous local access); `transport` any httpx transport (tests).
    Use it as a context manager, or `close()` it.
    """

    def __init__(
        self,
        base_url: str,
        token: str | None = None,
        *,
        timeout: float = DEFAULT_TIMEOUT_S,
        transport: httpx.BaseTransport | None = None,
    ) -> None:
        self.base_url = base_url.rstrip("/")
        self._http = httpx.Client(
            base_url=self.base_url, headers=_headers(token), timeout=timeout, transport=transport
        )

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the connections."""
        self._http.close()

    def _send(self, call: _Call[T]) -> T:
        return _answer(call, self._http.send(_request(self._http, call)))

    def health(self) -> Health:
        """`GET /healthz`: liveness, backend, batches per status."""
        return self._send(_Routes.health())

    # --- scenes -------------------------------------------------------------------------------

    def create_scene(
        self,
        name: str,
        *,
        params: Mapping[str, Any] | None = None,
        baseline: BaselineRef | None = None,
        profile: Literal["extended", "paper"] = "extended",
    ) -> Scene:
        """`POST /v1/scenes`: a new scene under `profile` (`extended`, the default, or `paper`);
        `params` override the profile's parameters."""
        return self._send(_Routes.create_scene(_scene_create(name, params, baseline, profile)))

    def scenes(self) -> list[Scene]:
        """`GET /v1/scenes`: every scene, oldest first, following the pages to the end."""
        found: list[Scene] = []
        cursor: str | None = None
        while True:
            page = self._send(_Routes.scenes(cursor))
            found.extend(page.scenes)
            if page.next_after is None:
                return found
            cursor = page.next_after

    def scene(self, scene_id: str) -> Scene:
        """`GET /v1/scenes/{id}`: one scene with its head seq and parameters."""
        return self._send(_Routes.scene(scene_id))

    def rename_scene(self, scene_id: str, name: str) -> Scene:
        """`PATCH /v1/scenes/{id}`: the scene under its new name (a `scene_renamed` event in
        its log; the same name again changes nothing). A name the text rule refuses raises
        pydantic's ValidationError before anything is sent, as `create_scene` does."""
        return self._send(_Routes.rename_scene(scene_id, name))

    def delete_scene(self, scene_id: str, *, confirm: str) -> SceneDeleted:
        """`DELETE /v1/scenes/{id}` (admin): the scene and everything it holds, for good;
        `confirm` must repeat `scene_id` (else `InvalidRequest`, nothing deleted)."""
        return self._send(_Routes.delete_scene(scene_id, confirm))

    # --- batches ------------------------------------------------------------------------------

    def post_batch(self, scene_id: str, batch: BatchIn) -> BatchStatus:
        """`POST .../batches`: queue a batch (status `queued`); the same batch again returns the
        original's status, new content under its batch_id raises `Conflict`."""
        return self._send(_Routes.post_batch(scene_id, batch))

    def submit_batch(self, scene_id: str, batch: BatchIn) -> Submitted:
        """`post_batch`, also saying whether this post queued the batch or it was sent before."""
        return self._send(_Routes.submit_batch(scene_id, batch))

    def batch(self, scene_id: str, batch_id: str) -> BatchStatus:
        """`GET .../batches/{batch_id}`: where a batch is, and the seqs it appended."""
        return self._send(_Routes.batch(scene_id, batch_id))

    def requeue_batch(self, scene_id: str, batch_id: str) -> BatchStatus:
        """`POST .../batches/{batch_id}/requeue` (admin): a dead batch back in the queue."""
        return self._send(_Routes.requeue_batch(scene_id, batch_id))

    def wait_for_batch(
        self,
        scene_id: str,
        batch_id: str,
        *,
        timeout: float = 120.0,
        poll_interval: float = 0.05,
    ) -> BatchStatus:
        """Poll until the batch is `done` (returned) or `dead` (`BatchDead`); `BatchTimeout`
        when it is neither after `timeout` seconds. A 429 while polling waits its Retry-After."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                status = self.batch(scene_id, batch_id)
            except RateLimited as error:
                if time.monotonic() >= deadline:
                    raise
                time.sleep(_poll_wait(error, poll_interval))
                continue
            if status.status == "done":
                return status
            if status.status == "dead":
                raise BatchDead(status)
            if time.monotonic() >= deadline:
                raise BatchTimeout(status, timeout)
            time.sleep(poll_interval)

    # --- reading the memory -------------------------------------------------------------------

    def graph(
        self,
        scene_id: str,
        *,
        as_of: int | None = None,
        as_of_time: WallTime | None = None,
        include: Literal["published", "all"] = "published",
        parent: str | None = None,
        label: str | None = None,
    ) -> Graph:
        """`GET .../graph`: the published graph (every track with include="all") at `as_of`."""
        return self._send(_Routes.graph(scene_id, as_of, include, parent, label, as_of_time))

    def events_page(
        self,
        scene_id: str,
        *,
        after: int = -1,
        limit: int = 100,
        track_id: str | None = None,
        type: str | None = None,
    ) -> EventPage:
        """`GET .../events`: one page of the log after a seq cursor."""
        return self._send(_Routes.events_page(scene_id, after, limit, track_id, type))

    def events(
        self,
        scene_id: str,
        *,
        after: int = -1,
        up_to: int | None = None,
        track_id: str | None = None,
        type: str | None = None,
        page_size: int = EVENTS_PAGE_SIZE,
    ) -> Iterator[EventOut]:
        """Every event with after < seq (<= up_to), following the pages to the end."""
        cursor: int | None = after
        while cursor is not None:
            page = self.events_page(
                scene_id, after=cursor, limit=page_size, track_id=track_id, type=type
            )
            for event in page.events:
                if up_to is not None and event.seq > up_to:
                    return
                yield event
            cursor = page.next_after

    def stream_events(
        self,
        scene_id: str,
        *,
        after: int = -1,
        type: str | None = None,
        track_id: str | None = None,
        max_failures: int = 10,
    ) -> Iterator[EventOut]:
        """`GET .../events/stream`: every event after `after`, then each new one as it is
        appended, for as long as the caller iterates. A lost or dropped connection is resumed
        with Last-Event-ID (every seq once, in order), after a backoff of at most 5 s;
        `max_failures` attempts in a row that fail raise the last error. Ends when the server
        ends the stream (the scene deleted, or a quarantined scene's log complete)."""
        call = _Routes.events_stream(scene_id, after, track_id, type)
        resume = Resume(after=after, max_failures=max_failures)
        return follow(self._http, lambda: _request(self._http, call), resume)

    def tracks(
        self,
        scene_id: str,
        *,
        label: str | None = None,
        state: str | None = None,
        parent: str | None = None,
    ) -> list[TrackBelief]:
        """`GET .../tracks`: current tracks from the projection, filtered."""
        return self._send(_Routes.tracks(scene_id, label, state, parent))

    def track(
        self,
        scene_id: str,
        track_id: str,
        *,
        as_of: int | None = None,
        as_of_time: WallTime | None = None,
    ) -> TrackBelief:
        """`GET .../tracks/{track_id}`: the full belief of one track at `as_of`."""
        return self._send(_Routes.track(scene_id, track_id, as_of, as_of_time))

    def objects(
        self,
        scene_id: str,
        *,
        label: str | None = None,
        near: tuple[float, float, float] | None = None,
        radius: float | None = None,
        on: str | None = None,
        changed_since: int | None = None,
        changed_since_time: WallTime | None = None,
        state: str | None = None,
        as_of: int | None = None,
        as_of_time: WallTime | None = None,
        limit: int = 100,
        after: str | None = None,
    ) -> ObjectPage:
        """`GET .../objects`: one page of the scene's objects that match every filter, by
        distance from `near` when given, else by track id."""
        filters = {
            "label": label,
            "near": None if near is None else ",".join(repr(float(v)) for v in near),
            "radius": radius,
            "on": on,
            "changed_since": changed_since,
            "changed_since_time": _wall(changed_since_time),
            "state": state,
            "limit": limit,
            "after": after,
        }
        return self._send(_Routes.objects(scene_id, filters, as_of, as_of_time))

    def similar(
        self,
        scene_id: str,
        embedding: Sequence[float],
        *,
        k: int = 5,
        label: str | None = None,
        as_of: int | None = None,
        as_of_time: WallTime | None = None,
    ) -> SimilarOut:
        """`POST .../objects/similar`: the `k` objects that look most like `embedding`."""
        body = SimilarIn(embedding=list(embedding), k=k, label=label)
        return self._send(_Routes.similar(scene_id, body, as_of, as_of_time))

    def history(
        self,
        scene_id: str,
        track_id: str,
        *,
        after: int = -1,
        limit: int = 100,
        as_of: int | None = None,
        as_of_time: WallTime | None = None,
    ) -> TrackHistory:
        """`GET .../tracks/{track_id}/history`: where the track was and on what, as spans."""
        call = _Routes.history(scene_id, track_id, after, limit, as_of, as_of_time)
        return self._send(call)

    def explain(self, scene_id: str, track_id: str, *, events: bool = False) -> Explanation:
        """`GET .../tracks/{track_id}/explain`: why the track is in its state, from the log (its
        events too with `events`)."""
        return self._send(_Routes.explain(scene_id, track_id, events))

    # --- verification, baselines, inspections, plan --------------------------------------------

    def verifications(
        self, scene_id: str, *, status: Literal["pending", "all"] = "pending"
    ) -> list[VerificationItem]:
        """`GET .../verifications`: fixtures waiting for a verdict (or every one with "all")."""
        return self._send(_Routes.verifications(scene_id, status))

    def post_verdict(self, scene_id: str, track_id: str, verdict: VerdictIn) -> CommandResult:
        """`POST .../tracks/{track_id}/verification`: record a verdict."""
        return self._send(_Routes.post_verdict(scene_id, track_id, verdict))

    def freeze_baseline(self, scene_id: str) -> BaselinePackage:
        """`POST .../baselines`: freeze the confirmed fixtures into a versioned package."""
        return self._send(_Routes.freeze_baseline(scene_id))

    def baselines(self, scene_id: str) -> list[BaselineSummary]:
        """`GET .../baselines`: every frozen baseline."""
        return self._send(_Routes.baselines(scene_id))

    def baseline(self, scene_id: str, version: int) -> BaselinePackage:
        """`GET .../baselines/{version}`: one package."""
        return self._send(_Routes.baseline(scene_id, version))

    def delta(
        self, scene_id: str, baseline: int, *, after: int | None = None, limit: int = 100
    ) -> Delta:
        """`GET .../delta`: a page of the events after a baseline's freeze."""
        return self._send(_Routes.delta(scene_id, baseline, after, limit))

    def post_inspection(self, scene_id: str, inspection: InspectionIn) -> Inspection:
        """`POST .../inspections`: one fixture-centered capture."""
        return self._send(_Routes.post_inspection(scene_id, inspection))

    def inspections(self, scene_id: str) -> list[Inspection]:
        """`GET .../inspections`: the capture ledger."""
        return self._send(_Routes.inspections(scene_id))

    def inspection_queue(self, scene_id: str) -> list[InspectionQueueItem]:
        """`GET .../inspection-queue`: unresolved fixtures, most uncertain first."""
        return self._send(_Routes.inspection_queue(scene_id))

    def plan(self, scene_id: str, robot_pose: RobotPose) -> PlanOut:
        """`POST .../plan`: what to do next, decided on the head (may lock a target)."""
        return self._send(_Routes.plan(scene_id, robot_pose))

    def preview_plan(
        self,
        scene_id: str,
        x: float,
        y: float,
        yaw: float = 0.0,
        *,
        as_of: int | None = None,
        as_of_time: WallTime | None = None,
    ) -> PlanOut:
        """`GET .../plan`: the plan at `as_of` for a robot at (x, y, yaw), without locking."""
        return self._send(_Routes.preview_plan(scene_id, x, y, yaw, as_of, as_of_time))

    def occupancy(
        self, scene_id: str, *, as_of: int | None = None, as_of_time: WallTime | None = None
    ) -> Occupancy:
        """`GET .../occupancy`: the occupancy map A_t at `as_of`, run-length encoded."""
        return self._send(_Routes.occupancy(scene_id, as_of, as_of_time))

    def occupancy_png(
        self, scene_id: str, *, as_of: int | None = None, as_of_time: WallTime | None = None
    ) -> bytes:
        """`GET .../occupancy?format=png`: the map as an 8-bit grey PNG."""
        return self._send(_Routes.occupancy_png(scene_id, as_of, as_of_time))


class AsyncClient:
    """The PBD-AG API over HTTP, for asyncio: the methods of `Client`, awaited."""

    def __init__(
        self,
        base_url: str,
        token: str | None = None,
        *,
        timeout: float = DEFAULT_TIMEOUT_S,
        transport: httpx.AsyncBaseTransport | None = None,
    ) -> None:
        self.base_url = base_url.rstrip("/")
        self._http = httpx.AsyncClient(
            base_url=self.base_url, headers=_headers(token), timeout=timeout, transport=transport
        )

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.aclose()

    async def aclose(self) -> None:
        """Close the connections."""
        await self._http.aclose()

    async def _send(self, call: _Call[T]) -> T:
        return _answer(call, await self._http.send(_request(self._http, call)))

    async def health(self) -> Health:
        """`GET /healthz`."""
        return await self._send(_Routes.health())

    async def create_scene(
        self,
        name: str,
        *,
        params: Mapping[str, Any] | None = None,
        baseline: BaselineRef | None = None,
        profile: Literal["extended", "paper"] = "extended",
    ) -> Scene:
        """`POST /v1/scenes`."""
        return await self._send(
            _Routes.create_scene(_scene_create(name, params, baseline, profile))
        )

    async def scenes(self) -> list[Scene]:
        """`GET /v1/scenes`: every scene, oldest first, following the pages to the end."""
        found: list[Scene] = []
        cursor: str | None = None
        while True:
            page = await self._send(_Routes.scenes(cursor))
            found.extend(page.scenes)
            if page.next_after is None:
                return found
            cursor = page.next_after

    async def scene(self, scene_id: str) -> Scene:
        """`GET /v1/scenes/{id}`."""
        return await self._send(_Routes.scene(scene_id))

    async def rename_scene(self, scene_id: str, name: str) -> Scene:
        """`PATCH /v1/scenes/{id}`."""
        return await self._send(_Routes.rename_scene(scene_id, name))

    async def delete_scene(self, scene_id: str, *, confirm: str) -> SceneDeleted:
        """`DELETE /v1/scenes/{id}` (admin); `confirm` repeats `scene_id`."""
        return await self._send(_Routes.delete_scene(scene_id, confirm))

    async def post_batch(self, scene_id: str, batch: BatchIn) -> BatchStatus:
        """`POST .../batches`."""
        return await self._send(_Routes.post_batch(scene_id, batch))

    async def submit_batch(self, scene_id: str, batch: BatchIn) -> Submitted:
        """`POST .../batches`, also saying whether this post queued the batch."""
        return await self._send(_Routes.submit_batch(scene_id, batch))

    async def batch(self, scene_id: str, batch_id: str) -> BatchStatus:
        """`GET .../batches/{batch_id}`."""
        return await self._send(_Routes.batch(scene_id, batch_id))

    async def requeue_batch(self, scene_id: str, batch_id: str) -> BatchStatus:
        """`POST .../batches/{batch_id}/requeue` (admin)."""
        return await self._send(_Routes.requeue_batch(scene_id, batch_id))

    async def wait_for_batch(
        self,
        scene_id: str,
        batch_id: str,
        *,
        timeout: float = 120.0,
        poll_interval: float = 0.05,
    ) -> BatchStatus:
        """Poll until `done` (returned) or `dead` (`BatchDead`); `BatchTimeout` after `timeout`."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                status = await self.batch(scene_id, batch_id)
            except RateLimited as error:
                if time.monotonic() >= deadline:
                    raise
                await asyncio.sleep(_poll_wait(error, poll_interval))
                continue
            if status.status == "done":
                return status
            if status.status == "dead":
                raise BatchDead(status)
            if time.monotonic() >= deadline:
                raise BatchTimeout(status, timeout)
            await asyncio.sleep(poll_interval)

    async def graph(
        self,
        scene_id: str,
        *,
        as_of: int | None = None,
        as_of_time: WallTime | None = None,
        include: Literal["published", "all"] = "published",
        parent: str | None = None,
        label: str | None = None,
    ) -> Graph:
        """`GET .../graph`."""
        return await self._send(_Routes.graph(scene_id, as_of, include, parent, label, as_of_time))

    async def events_page(
        self,
        scene_id: str,
        *,
        after: int = -1,
        limit: int = 100,
        track_id: str | None = None,
        type: str | None = None,
    ) -> EventPage:
        """`GET .../events`: one page."""
        return await self._send(_Routes.events_page(scene_id, after, limit, track_id, type))

    async def events(
        self,
        scene_id: str,
        *,
        after: int = -1,
        up_to: int | None = None,
        track_id: str | None = None,
        type: str | None = None,
        page_size: int = EVENTS_PAGE_SIZE,
    ) -> AsyncIterator[EventOut]:
        """Every event with after < seq (<= up_to), following the pages (`async for`)."""
        cursor: int | None = after
        while cursor is not None:
            page = await self.events_page(
                scene_id, after=cursor, limit=page_size, track_id=track_id, type=type
            )
            for event in page.events:
                if up_to is not None and event.seq > up_to:
                    return
                yield event
            cursor = page.next_after

    def stream_events(
        self,
        scene_id: str,
        *,
        after: int = -1,
        type: str | None = None,
        track_id: str | None = None,
        max_failures: int = 10,
    ) -> AsyncIterator[EventOut]:
        """`GET .../events/stream` as an async iterator (see `Client.stream_events`)."""
        call = _Routes.events_stream(scene_id, after, track_id, type)
        resume = Resume(after=after, max_failures=max_failures)
        return follow_async(self._http, lambda: _request(self._http, call), resume)

    async def tracks(
        self,
        scene_id: str,
        *,
        label: str | None = None,
        state: str | None = None,
        parent: str | None = None,
    ) -> list[TrackBelief]:
        """`GET .../tracks`."""
        return await self._send(_Routes.tracks(scene_id, label, state, parent))

    async def track(
        self,
        scene_id: str,
        track_id: str,
        *,
        as_of: int | None = None,
        as_of_time: WallTime | None = None,
    ) -> TrackBelief:
        """`GET .../tracks/{track_id}`."""
        return await self._send(_Routes.track(scene_id, track_id, as_of, as_of_time))

    async def objects(
        self,
        scene_id: str,
        *,
        label: str | None = None,
        near: tuple[float, float, float] | None = None,
        radius: float | None = None,
        on: str | None = None,
        changed_since: int | None = None,
        changed_since_time: WallTime | None = None,
        state: str | None = None,
        as_of: int | None = None,
        as_of_time: WallTime | None = None,
        limit: int = 100,
        after: str | None = None,
    ) -> ObjectPage:
        """`GET .../objects`: one page of the scene's objects that match every filter, by
        distance from `near` when given, else by track id."""
        filters = {
            "label": label,
            "near": None if near is None else ",".join(repr(float(v)) for v in near),
            "radius": radius,
            "on": on,
            "changed_since": changed_since,
            "changed_since_time": _wall(changed_since_time),
            "state": state,
            "limit": limit,
            "after": after,
        }
        return await self._send(_Routes.objects(scene_id, filters, as_of, as_of_time))

    async def similar(
        self,
        scene_id: str,
        embedding: Sequence[float],
        *,
        k: int = 5,
        label: str | None = None,
        as_of: int | None = None,
        as_of_time: WallTime | None = None,
    ) -> SimilarOut:
        """`POST .../objects/similar`: the `k` objects that look most like `embedding`."""
        body = SimilarIn(embedding=list(embedding), k=k, label=label)
        return await self._send(_Routes.similar(scene_id, body, as_of, as_of_time))

    async def history(
        self,
        scene_id: str,
        track_id: str,
        *,
        after: int = -1,
        limit: int = 100,
        as_of: int | None = None,
        as_of_time: WallTime | None = None,
    ) -> TrackHistory:
        """`GET .../tracks/{track_id}/history`: where the track was and on what, as spans."""
        call = _Routes.history(scene_id, track_id, after, limit, as_of, as_of_time)
        return await self._send(call)

    async def explain(self, scene_id: str, track_id: str, *, events: bool = False) -> Explanation:
        """`GET .../tracks/{track_id}/explain`."""
        return await self._send(_Routes.explain(scene_id, track_id, events))

    async def verifications(
        self, scene_id: str, *, status: Literal["pending", "all"] = "pending"
    ) -> list[VerificationItem]:
        """`GET .../verifications`."""
        return await self._send(_Routes.verifications(scene_id, status))

    async def post_verdict(self, scene_id: str, track_id: str, verdict: VerdictIn) -> CommandResult:
        """`POST .../tracks/{track_id}/verification`."""
        return await self._send(_Routes.post_verdict(scene_id, track_id, verdict))

    async def freeze_baseline(self, scene_id: str) -> BaselinePackage:
        """`POST .../baselines`."""
        return await self._send(_Routes.freeze_baseline(scene_id))

    async def baselines(self, scene_id: str) -> list[BaselineSummary]:
        """`GET .../baselines`."""
        return await self._send(_Routes.baselines(scene_id))

    async def baseline(self, scene_id: str, version: int) -> BaselinePackage:
        """`GET .../baselines/{version}`."""
        return await self._send(_Routes.baseline(scene_id, version))

    async def delta(
        self, scene_id: str, baseline: int, *, after: int | None = None, limit: int = 100
    ) -> Delta:
        """`GET .../delta`."""
        return await self._send(_Routes.delta(scene_id, baseline, after, limit))

    async def post_inspection(self, scene_id: str, inspection: InspectionIn) -> Inspection:
        """`POST .../inspections`."""
        return await self._send(_Routes.post_inspection(scene_id, inspection))

    async def inspections(self, scene_id: str) -> list[Inspection]:
        """`GET .../inspections`."""
        return await self._send(_Routes.inspections(scene_id))

    async def inspection_queue(self, scene_id: str) -> list[InspectionQueueItem]:
        """`GET .../inspection-queue`."""
        return await self._send(_Routes.inspection_queue(scene_id))

    async def plan(self, scene_id: str, robot_pose: RobotPose) -> PlanOut:
        """`POST .../plan`."""
        return await self._send(_Routes.plan(scene_id, robot_pose))

    async def preview_plan(
        self,
        scene_id: str,
        x: float,
        y: float,
        yaw: float = 0.0,
        *,
        as_of: int | None = None,
        as_of_time: WallTime | None = None,
    ) -> PlanOut:
        """`GET .../plan`."""
        return await self._send(_Routes.preview_plan(scene_id, x, y, yaw, as_of, as_of_time))

    async def occupancy(
        self, scene_id: str, *, as_of: int | None = None, as_of_time: WallTime | None = None
    ) -> Occupancy:
        """`GET .../occupancy`."""
        return await self._send(_Routes.occupancy(scene_id, as_of, as_of_time))

    async def occupancy_png(
        self, scene_id: str, *, as_of: int | None = None, as_of_time: WallTime | None = None
    ) -> bytes:
        """`GET .../occupancy?format=png`."""
        return await self._send(_Routes.occupancy_png(scene_id, as_of, as_of_time))
