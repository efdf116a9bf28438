"""`Client`: every route of the v1 API over a blocking httpx client, typed with the `api_schema`
models (the routes are described once, in `pbdag_client.routes`). Error answers raise the typed
exceptions of `pbdag_client.errors`.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Mapping, Sequence
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
from pbdag_client.feed import Resume, follow
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

__all__ = ["Client"]


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
            base_url=self.base_url, headers=headers(token), timeout=timeout, transport=transport
        )

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the connections."""
        self._http.close()

    def _send(self, call: Call[T]) -> T:
        return answer(call, self._http.send(request_of(self._http, call)))

    def health(self) -> Health:
        """`GET /healthz`: liveness, backend, batches per status."""
        return self._send(Routes.health())

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
        return self._send(Routes.create_scene(scene_create(name, params, baseline, profile)))

    def scenes(self) -> list[Scene]:
        """`GET /v1/scenes`: every scene, oldest first, following the pages to the end."""
        found: list[Scene] = []
        cursor: str | None = None
        while True:
            page = self._send(Routes.scenes(cursor))
            found.extend(page.scenes)
            if page.next_after is None:
                return found
            cursor = page.next_after

    def scene(self, scene_id: str) -> Scene:
        """`GET /v1/scenes/{id}`: one scene with its head seq and parameters."""
        return self._send(Routes.scene(scene_id))

    def rename_scene(self, scene_id: str, name: str) -> Scene:
        """`PATCH /v1/scenes/{id}`: the scene under its new name (a `scene_renamed` event in
        its log; the same name again changes nothing). A name the text rule refuses raises
        pydantic's ValidationError before anything is sent, as `create_scene` does."""
        return self._send(Routes.rename_scene(scene_id, name))

    def delete_scene(self, scene_id: str, *, confirm: str) -> SceneDeleted:
        """`DELETE /v1/scenes/{id}` (admin): the scene and everything it holds, for good;
        `confirm` must repeat `scene_id` (else `InvalidRequest`, nothing deleted)."""
        return self._send(Routes.delete_scene(scene_id, confirm))

    # --- batches ------------------------------------------------------------------------------

    def post_batch(self, scene_id: str, batch: BatchIn) -> BatchStatus:
        """`POST .../batches`: queue a batch (status `queued`); the same batch again returns the
        original's status, new content under its batch_id raises `Conflict`."""
        return self._send(Routes.post_batch(scene_id, batch))

    def submit_batch(self, scene_id: str, batch: BatchIn) -> Submitted:
        """`post_batch`, also saying whether this post queued the batch or it was sent before."""
        return self._send(Routes.submit_batch(scene_id, batch))

    def batch(self, scene_id: str, batch_id: str) -> BatchStatus:
        """`GET .../batches/{batch_id}`: where a batch is, and the seqs it appended."""
        return self._send(Routes.batch(scene_id, batch_id))

    def requeue_batch(self, scene_id: str, batch_id: str) -> BatchStatus:
        """`POST .../batches/{batch_id}/requeue` (admin): a dead batch back in the queue."""
        return self._send(Routes.requeue_batch(scene_id, batch_id))

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
                time.sleep(poll_wait(error, poll_interval))
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
        return self._send(Routes.graph(scene_id, as_of, include, parent, label, as_of_time))

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
        return self._send(Routes.events_page(scene_id, after, limit, track_id, type))

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
        call = Routes.events_stream(scene_id, after, track_id, type)
        resume = Resume(after=after, max_failures=max_failures)
        return follow(self._http, lambda: request_of(self._http, call), resume)

    def tracks(
        self,
        scene_id: str,
        *,
        label: str | None = None,
        state: str | None = None,
        parent: str | None = None,
    ) -> list[TrackBelief]:
        """`GET .../tracks`: current tracks from the projection, filtered."""
        return self._send(Routes.tracks(scene_id, label, state, parent))

    def track(
        self,
        scene_id: str,
        track_id: str,
        *,
        as_of: int | None = None,
        as_of_time: WallTime | None = None,
    ) -> TrackBelief:
        """`GET .../tracks/{track_id}`: the full belief of one track at `as_of`."""
        return self._send(Routes.track(scene_id, track_id, as_of, as_of_time))

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
            "changed_since_time": wall_time(changed_since_time),
            "state": state,
            "limit": limit,
            "after": after,
        }
        return self._send(Routes.objects(scene_id, filters, as_of, as_of_time))

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
        return self._send(Routes.similar(scene_id, body, as_of, as_of_time))

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
        call = Routes.history(scene_id, track_id, after, limit, as_of, as_of_time)
        return self._send(call)

    def explain(self, scene_id: str, track_id: str, *, events: bool = False) -> Explanation:
        """`GET .../tracks/{track_id}/explain`: why the track is in its state, from the log (its
        events too with `events`)."""
        return self._send(Routes.explain(scene_id, track_id, events))

    # --- verification, baselines, inspections, plan --------------------------------------------

    def verifications(
        self, scene_id: str, *, status: Literal["pending", "all"] = "pending"
    ) -> list[VerificationItem]:
        """`GET .../verifications`: fixtures waiting for a verdict (or every one with "all")."""
        return self._send(Routes.verifications(scene_id, status))

    def post_verdict(self, scene_id: str, track_id: str, verdict: VerdictIn) -> CommandResult:
        """`POST .../tracks/{track_id}/verification`: record a verdict."""
        return self._send(Routes.post_verdict(scene_id, track_id, verdict))

    def freeze_baseline(self, scene_id: str) -> BaselinePackage:
        """`POST .../baselines`: freeze the confirmed fixtures into a versioned package."""
        return self._send(Routes.freeze_baseline(scene_id))

    def baselines(self, scene_id: str) -> list[BaselineSummary]:
        """`GET .../baselines`: every frozen baseline."""
        return self._send(Routes.baselines(scene_id))

    def baseline(self, scene_id: str, version: int) -> BaselinePackage:
        """`GET .../baselines/{version}`: one package."""
        return self._send(Routes.baseline(scene_id, version))

    def delta(
        self, scene_id: str, baseline: int, *, after: int | None = None, limit: int = 100
    ) -> Delta:
        """`GET .../delta`: a page of the events after a baseline's freeze."""
        return self._send(Routes.delta(scene_id, baseline, after, limit))

    def post_inspection(self, scene_id: str, inspection: InspectionIn) -> Inspection:
        """`POST .../inspections`: one fixture-centered capture."""
        return self._send(Routes.post_inspection(scene_id, inspection))

    def inspections(self, scene_id: str) -> list[Inspection]:
        """`GET .../inspections`: the capture ledger."""
        return self._send(Routes.inspections(scene_id))

    def inspection_queue(self, scene_id: str) -> list[InspectionQueueItem]:
        """`GET .../inspection-queue`: unresolved fixtures, most uncertain first."""
        return self._send(Routes.inspection_queue(scene_id))

    def plan(self, scene_id: str, robot_pose: RobotPose) -> PlanOut:
        """`POST .../plan`: what to do next, decided on the head (may lock a target)."""
        return self._send(Routes.plan(scene_id, robot_pose))

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
        return self._send(Routes.preview_plan(scene_id, x, y, yaw, as_of, as_of_time))

    def occupancy(
        self, scene_id: str, *, as_of: int | None = None, as_of_time: WallTime | None = None
    ) -> Occupancy:
        """`GET .../occupancy`: the occupancy map A_t at `as_of`, run-length encoded."""
        return self._send(Routes.occupancy(scene_id, as_of, as_of_time))

    def occupancy_png(
        self, scene_id: str, *, as_of: int | None = None, as_of_time: WallTime | None = None
    ) -> bytes:
        """`GET .../occupancy?format=png`: the map as an 8-bit grey PNG."""
        return self._send(Routes.occupancy_png(scene_id, as_of, as_of_time))
