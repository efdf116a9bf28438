"""`AsyncClient`: every route of the v1 API over httpx's asyncio client, as `Client` has them
(the routes are described once, in `pbdag_client.routes`). Error answers raise the typed
exceptions of `pbdag_client.errors`.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Mapping, Sequence
from typing import Any, Literal

import httpx

from api_schema import (
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
    InspectionQueueItem,
    ObjectPage,
    Occupancy,
    PlanOut,
    RobotPose,
    Scene,
    SceneDeleted,
    SimilarIn,
    SimilarOut,
    TrackBelief,
    TrackHistory,
    VerdictIn,
    VerificationItem,
)
from pbdag_client.errors import BatchDead, BatchTimeout, RateLimited
from pbdag_client.feed import Resume, follow_async
from pbdag_client.routes import (
    DEFAULT_TIMEOUT_S,
    EVENTS_PAGE_SIZE,
    Call,
    Routes,
    Submitted,
    T,
    WallTime,
    answer,
    headers,
    poll_wait,
    request_of,
    scene_create,
    wall_time,
)

__all__ = ["AsyncClient"]


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
            base_url=self.base_url, headers=headers(token), timeout=timeout, transport=transport
        )

    async def __aenter__(self) -> AsyncClient:
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.aclose()

    async def aclose(self) -> None:
        """Close the connections."""
        await self._http.aclose()

    async def _send(self, call: Call[T]) -> T:
        return answer(call, await self._http.send(request_of(self._http, call)))

    async def health(self) -> Health:
        """`GET /healthz`."""
        return await self._send(Routes.health())

    async def create_scene(
        self,
        name: str,
        *,
        params: Mapping[str, Any] | None = None,
        baseline: BaselineRef | None = None,
        profile: Literal["extended", "paper"] = "extended",
    ) -> Scene:
        """`POST /v1/scenes`."""
        return await self._send(Routes.create_scene(scene_create(name, params, baseline, profile)))

    async def scenes(self) -> list[Scene]:
        """`GET /v1/scenes`: every scene, oldest first, following the pages to the end."""
        found: list[Scene] = []
        cursor: str | None = None
        while True:
            page = await self._send(Routes.scenes(cursor))
            found.extend(page.scenes)
            if page.next_after is None:
                return found
            cursor = page.next_after

    async def scene(self, scene_id: str) -> Scene:
        """`GET /v1/scenes/{id}`."""
        return await self._send(Routes.scene(scene_id))

    async def rename_scene(self, scene_id: str, name: str) -> Scene:
        """`PATCH /v1/scenes/{id}`."""
        return await self._send(Routes.rename_scene(scene_id, name))

    async def delete_scene(self, scene_id: str, *, confirm: str) -> SceneDeleted:
        """`DELETE /v1/scenes/{id}` (admin); `confirm` repeats `scene_id`."""
        return await self._send(Routes.delete_scene(scene_id, confirm))

    async def post_batch(self, scene_id: str, batch: BatchIn) -> BatchStatus:
        """`POST .../batches`."""
        return await self._send(Routes.post_batch(scene_id, batch))

    async def submit_batch(self, scene_id: str, batch: BatchIn) -> Submitted:
        """`POST .../batches`, also saying whether this post queued the batch."""
        return await self._send(Routes.submit_batch(scene_id, batch))

    async def batch(self, scene_id: str, batch_id: str) -> BatchStatus:
        """`GET .../batches/{batch_id}`."""
        return await self._send(Routes.batch(scene_id, batch_id))

    async def requeue_batch(self, scene_id: str, batch_id: str) -> BatchStatus:
        """`POST .../batches/{batch_id}/requeue` (admin)."""
        return await self._send(Routes.requeue_batch(scene_id, batch_id))

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
                await asyncio.sleep(poll_wait(error, poll_interval))
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
        return await self._send(Routes.graph(scene_id, as_of, include, parent, label, as_of_time))

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
        return await self._send(Routes.events_page(scene_id, after, limit, track_id, type))

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
        call = Routes.events_stream(scene_id, after, track_id, type)
        resume = Resume(after=after, max_failures=max_failures)
        return follow_async(self._http, lambda: request_of(self._http, call), resume)

    async def tracks(
        self,
        scene_id: str,
        *,
        label: str | None = None,
        state: str | None = None,
        parent: str | None = None,
    ) -> list[TrackBelief]:
        """`GET .../tracks`."""
        return await self._send(Routes.tracks(scene_id, label, state, parent))

    async def track(
        self,
        scene_id: str,
        track_id: str,
        *,
        as_of: int | None = None,
        as_of_time: WallTime | None = None,
    ) -> TrackBelief:
        """`GET .../tracks/{track_id}`."""
        return await self._send(Routes.track(scene_id, track_id, as_of, as_of_time))

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
            "changed_since_time": wall_time(changed_since_time),
            "state": state,
            "limit": limit,
            "after": after,
        }
        return await self._send(Routes.objects(scene_id, filters, as_of, as_of_time))

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
        return await self._send(Routes.similar(scene_id, body, as_of, as_of_time))

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
        call = Routes.history(scene_id, track_id, after, limit, as_of, as_of_time)
        return await self._send(call)

    async def explain(self, scene_id: str, track_id: str, *, events: bool = False) -> Explanation:
        """`GET .../tracks/{track_id}/explain`."""
        return await self._send(Routes.explain(scene_id, track_id, events))

    async def verifications(
        self, scene_id: str, *, status: Literal["pending", "all"] = "pending"
    ) -> list[VerificationItem]:
        """`GET .../verifications`."""
        return await self._send(Routes.verifications(scene_id, status))

    async def post_verdict(self, scene_id: str, track_id: str, verdict: VerdictIn) -> CommandResult:
        """`POST .../tracks/{track_id}/verification`."""
        return await self._send(Routes.post_verdict(scene_id, track_id, verdict))

    async def freeze_baseline(self, scene_id: str) -> BaselinePackage:
        """`POST .../baselines`."""
        return await self._send(Routes.freeze_baseline(scene_id))

    async def baselines(self, scene_id: str) -> list[BaselineSummary]:
        """`GET .../baselines`."""
        return await self._send(Routes.baselines(scene_id))

    async def baseline(self, scene_id: str, version: int) -> BaselinePackage:
        """`GET .../baselines/{version}`."""
        return await self._send(Routes.baseline(scene_id, version))

    async def delta(
        self, scene_id: str, baseline: int, *, after: int | None = None, limit: int = 100
    ) -> Delta:
        """`GET .../delta`."""
        return await self._send(Routes.delta(scene_id, baseline, after, limit))

    async def post_inspection(self, scene_id: str, inspection: InspectionIn) -> Inspection:
        """`POST .../inspections`."""
        return await self._send(Routes.post_inspection(scene_id, inspection))

    async def inspections(self, scene_id: str) -> list[Inspection]:
        """`GET .../inspections`."""
        return await self._send(Routes.inspections(scene_id))

    async def inspection_queue(self, scene_id: str) -> list[InspectionQueueItem]:
        """`GET .../inspection-queue`."""
        return await self._send(Routes.inspection_queue(scene_id))

    async def plan(self, scene_id: str, robot_pose: RobotPose) -> PlanOut:
        """`POST .../plan`."""
        return await self._send(Routes.plan(scene_id, robot_pose))

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
        return await self._send(Routes.preview_plan(scene_id, x, y, yaw, as_of, as_of_time))

    async def occupancy(
        self, scene_id: str, *, as_of: int | None = None, as_of_time: WallTime | None = None
    ) -> Occupancy:
        """`GET .../occupancy`."""
        return await self._send(Routes.occupancy(scene_id, as_of, as_of_time))

    async def occupancy_png(
        self, scene_id: str, *, as_of: int | None = None, as_of_time: WallTime | None = None
    ) -> bytes:
        """`GET .../occupancy?format=png`."""
        return await self._send(Routes.occupancy_png(scene_id, as_of, as_of_time))
