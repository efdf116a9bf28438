"""Every route of the v1 API described once (`Call`: method, path, query, body and how to read
the answer), with what both clients share: the request and answer helpers, the scene lookup by
name and the constants. `Client` (`pbdag_client.client`) and `AsyncClient`
(`pbdag_client.async_client`) only differ in how they send a call.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
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
from pbdag_client.errors import RateLimited, problem_error

__all__ = ["DEFAULT_TIMEOUT_S", "Call", "Routes", "Submitted", "WallTime", "scenes_called"]

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
class Call(Generic[T]):
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


def submitted(response: httpx.Response) -> Submitted:
    return Submitted(BatchStatus.model_validate_json(response.content), response.status_code == 202)


def no_body(_response: httpx.Response) -> None:
    return None


def model_of(cls: type[M]) -> Callable[[httpx.Response], M]:
    return lambda response: cls.model_validate_json(response.content)


def _segment(value: str | int) -> str:
    """A path segment, percent-encoded."""
    return quote(str(value), safe="")


def _scene(scene_id: str) -> str:
    return f"/v1/scenes/{_segment(scene_id)}"


def _query(**values: str | int | float | None) -> Query:
    """Query parameters, leaving out those not given."""
    return {name: value for name, value in values.items() if value is not None}


def wall_time(value: WallTime | None) -> str | float | None:
    """A wall-clock time as the query carries it (a datetime in ISO 8601)."""
    return value.isoformat() if isinstance(value, datetime) else value


def scenes_called(scenes: Sequence[Scene], name_or_id: str) -> list[Scene]:
    """The scene whose id is `name_or_id`, else every scene named so, oldest first (what a
    command line's `--scene NAME_OR_ID` means)."""
    by_id = [scene for scene in scenes if scene.id == name_or_id]
    return by_id or [scene for scene in scenes if scene.name == name_or_id]


class Routes:
    """The v1 API's routes as `Call`s (shared by both clients)."""

    @staticmethod
    def health() -> Call[Health]:
        return Call("GET", "/healthz", model_of(Health))

    @staticmethod
    def create_scene(body: SceneCreate) -> Call[Scene]:
        return Call("POST", "/v1/scenes", model_of(Scene), body=body)

    @staticmethod
    def scenes(after: str | None) -> Call[SceneList]:
        return Call("GET", "/v1/scenes", model_of(SceneList), _query(after=after))

    @staticmethod
    def scene(scene_id: str) -> Call[Scene]:
        return Call("GET", _scene(scene_id), model_of(Scene))

    @staticmethod
    def rename_scene(scene_id: str, name: str) -> Call[Scene]:
        return Call("PATCH", _scene(scene_id), model_of(Scene), body=SceneRename(name=name))

    @staticmethod
    def delete_scene(scene_id: str, confirm: str) -> Call[SceneDeleted]:
        query = _query(confirm=confirm)
        return Call("DELETE", _scene(scene_id), model_of(SceneDeleted), query)

    @staticmethod
    def post_batch(scene_id: str, batch: BatchIn) -> Call[BatchStatus]:
        return Call("POST", f"{_scene(scene_id)}/batches", model_of(BatchStatus), body=batch)

    @staticmethod
    def submit_batch(scene_id: str, batch: BatchIn) -> Call[Submitted]:
        return Call("POST", f"{_scene(scene_id)}/batches", submitted, body=batch)

    @staticmethod
    def batch(scene_id: str, batch_id: str) -> Call[BatchStatus]:
        path = f"{_scene(scene_id)}/batches/{_segment(batch_id)}"
        return Call("GET", path, model_of(BatchStatus))

    @staticmethod
    def requeue_batch(scene_id: str, batch_id: str) -> Call[BatchStatus]:
        path = f"{_scene(scene_id)}/batches/{_segment(batch_id)}/requeue"
        return Call("POST", path, model_of(BatchStatus))

    @staticmethod
    def graph(
        scene_id: str,
        as_of: int | None,
        include: Literal["published", "all"],
        parent: str | None,
        label: str | None,
        as_of_time: WallTime | None = None,
    ) -> Call[Graph]:
        query = _query(
            as_of=as_of,
            as_of_time=wall_time(as_of_time),
            include=include,
            parent=parent,
            label=label,
        )
        return Call("GET", f"{_scene(scene_id)}/graph", model_of(Graph), query)

    @staticmethod
    def events_page(
        scene_id: str, after: int, limit: int, track_id: str | None, type: str | None
    ) -> Call[EventPage]:
        query = _query(after=after, limit=limit, track_id=track_id, type=type)
        return Call("GET", f"{_scene(scene_id)}/events", model_of(EventPage), query)

    @staticmethod
    def events_stream(
        scene_id: str, after: int, track_id: str | None, type: str | None
    ) -> Call[None]:
        query = _query(after=after, track_id=track_id, type=type)
        return Call("GET", f"{_scene(scene_id)}/events/stream", no_body, query, accept=_SSE)

    @staticmethod
    def tracks(
        scene_id: str, label: str | None, state: str | None, parent: str | None
    ) -> Call[list[TrackBelief]]:
        query = _query(label=label, state=state, parent=parent)
        return Call(
            "GET", f"{_scene(scene_id)}/tracks", lambda r: _TRACKS.validate_json(r.content), query
        )

    @staticmethod
    def track(
        scene_id: str, track_id: str, as_of: int | None, as_of_time: WallTime | None = None
    ) -> Call[TrackBelief]:
        path = f"{_scene(scene_id)}/tracks/{_segment(track_id)}"
        query = _query(as_of=as_of, as_of_time=wall_time(as_of_time))
        return Call("GET", path, model_of(TrackBelief), query)

    @staticmethod
    def objects(
        scene_id: str,
        filters: Mapping[str, str | int | float | None],
        as_of: int | None,
        as_of_time: WallTime | None,
    ) -> Call[ObjectPage]:
        query = _query(**filters, as_of=as_of, as_of_time=wall_time(as_of_time))
        return Call("GET", f"{_scene(scene_id)}/objects", model_of(ObjectPage), query)

    @staticmethod
    def similar(
        scene_id: str, body: SimilarIn, as_of: int | None, as_of_time: WallTime | None
    ) -> Call[SimilarOut]:
        path = f"{_scene(scene_id)}/objects/similar"
        query = _query(as_of=as_of, as_of_time=wall_time(as_of_time))
        return Call("POST", path, model_of(SimilarOut), query, body)

    @staticmethod
    def history(
        scene_id: str,
        track_id: str,
        after: int,
        limit: int,
        as_of: int | None,
        as_of_time: WallTime | None,
    ) -> Call[TrackHistory]:
        path = f"{_scene(scene_id)}/tracks/{_segment(track_id)}/history"
        query = _query(after=after, limit=limit, as_of=as_of, as_of_time=wall_time(as_of_time))
        return Call("GET", path, model_of(TrackHistory), query)

    @staticmethod
    def explain(scene_id: str, track_id: str, events: bool) -> Call[Explanation]:
        path = f"{_scene(scene_id)}/tracks/{_segment(track_id)}/explain"
        return Call("GET", path, model_of(Explanation), _query(events="true" if events else None))

    @staticmethod
    def verifications(
        scene_id: str, status: Literal["pending", "all"]
    ) -> Call[list[VerificationItem]]:
        return Call(
            "GET",
            f"{_scene(scene_id)}/verifications",
            lambda r: VerificationList.model_validate_json(r.content).verifications,
            _query(status=status),
        )

    @staticmethod
    def post_verdict(scene_id: str, track_id: str, verdict: VerdictIn) -> Call[CommandResult]:
        path = f"{_scene(scene_id)}/tracks/{_segment(track_id)}/verification"
        return Call("POST", path, model_of(CommandResult), body=verdict)

    @staticmethod
    def freeze_baseline(scene_id: str) -> Call[BaselinePackage]:
        return Call("POST", f"{_scene(scene_id)}/baselines", model_of(BaselinePackage))

    @staticmethod
    def baselines(scene_id: str) -> Call[list[BaselineSummary]]:
        return Call(
            "GET",
            f"{_scene(scene_id)}/baselines",
            lambda r: BaselineList.model_validate_json(r.content).baselines,
        )

    @staticmethod
    def baseline(scene_id: str, version: int) -> Call[BaselinePackage]:
        path = f"{_scene(scene_id)}/baselines/{_segment(version)}"
        return Call("GET", path, model_of(BaselinePackage))

    @staticmethod
    def delta(scene_id: str, baseline: int, after: int | None, limit: int) -> Call[Delta]:
        query = _query(baseline=baseline, after=after, limit=limit)
        return Call("GET", f"{_scene(scene_id)}/delta", model_of(Delta), query)

    @staticmethod
    def post_inspection(scene_id: str, inspection: InspectionIn) -> Call[Inspection]:
        return Call(
            "POST", f"{_scene(scene_id)}/inspections", model_of(Inspection), body=inspection
        )

    @staticmethod
    def inspections(scene_id: str) -> Call[list[Inspection]]:
        return Call(
            "GET",
            f"{_scene(scene_id)}/inspections",
            lambda r: InspectionList.model_validate_json(r.content).inspections,
        )

    @staticmethod
    def inspection_queue(scene_id: str) -> Call[list[InspectionQueueItem]]:
        return Call(
            "GET",
            f"{_scene(scene_id)}/inspection-queue",
            lambda r: InspectionQueue.model_validate_json(r.content).fixtures,
        )

    @staticmethod
    def plan(scene_id: str, robot_pose: RobotPose) -> Call[PlanOut]:
        body = PlanIn(robot_pose=robot_pose)
        return Call("POST", f"{_scene(scene_id)}/plan", model_of(PlanOut), body=body)

    @staticmethod
    def preview_plan(
        scene_id: str,
        x: float,
        y: float,
        yaw: float,
        as_of: int | None,
        as_of_time: WallTime | None = None,
    ) -> Call[PlanOut]:
        query = _query(x=x, y=y, yaw=yaw, as_of=as_of, as_of_time=wall_time(as_of_time))
        return Call("GET", f"{_scene(scene_id)}/plan", model_of(PlanOut), query)

    @staticmethod
    def occupancy(
        scene_id: str, as_of: int | None, as_of_time: WallTime | None = None
    ) -> Call[Occupancy]:
        query = _query(as_of=as_of, as_of_time=wall_time(as_of_time), format="json")
        return Call("GET", f"{_scene(scene_id)}/occupancy", model_of(Occupancy), query)

    @staticmethod
    def occupancy_png(
        scene_id: str, as_of: int | None, as_of_time: WallTime | None = None
    ) -> Call[bytes]:
        query = _query(as_of=as_of, as_of_time=wall_time(as_of_time), format="png")
        return Call(
            "GET", f"{_scene(scene_id)}/occupancy", lambda r: r.content, query, accept="image/png"
        )


def scene_create(
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


def headers(token: str | None) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"} if token else {}


def request_of(http: httpx.Client | httpx.AsyncClient, call: Call[Any]) -> httpx.Request:
    # Fields left at their defaults stay off the wire: the service applies the same defaults.
    content = None if call.body is None else call.body.model_dump_json(exclude_unset=True).encode()
    headers = {"Accept": call.accept}
    if content is not None:
        headers["Content-Type"] = "application/json"
    return http.build_request(
        call.method, call.path, params=call.query, content=content, headers=headers
    )


def answer(call: Call[T], response: httpx.Response) -> T:
    if response.is_error:
        raise problem_error(response)
    return call.read(response)


def poll_wait(error: RateLimited, poll_interval_s: float) -> float:
    """How long to wait after a 429 while polling."""
    retry_after = error.retry_after
    return max(poll_interval_s, 1.0 if retry_after is None else retry_after)
