"""The FastAPI application: routers, problem+json errors, body limit, optional in-process worker."""

from __future__ import annotations

import dataclasses
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI
from starlette.responses import PlainTextResponse

from api_schema import Health, WorkerStatus
from service.bootstrap import Container, build_container
from service.errors import install_problem_handlers
from service.feed import StreamSlots
from service.handoff import Handoff
from service.metrics import CONTENT_TYPE_LATEST
from service.middleware.body_limit import BodySizeLimit
from service.middleware.content_type_options import ContentTypeOptions
from service.middleware.methods import Methods
from service.middleware.request_log import RequestLog
from service.middleware.unexpected import UnexpectedErrors
from service.openapi import install_openapi
from service.routes import (
    baselines,
    batches,
    events,
    graph,
    inspections,
    objects,
    plan,
    scenes,
    tracks,
    verifications,
)
from service.security import install_security
from service.states import StateReader
from service.store.engine import is_postgres
from service.store.notifications import Wakeups
from service.viewer import install_pages
from service.worker import WorkerThread

API_VERSION = "1.0.0"


def create_app(container: Container | None = None, *, run_worker: bool = False) -> FastAPI:
    """The service; with `run_worker` a worker thread processes the queue in this process."""
    container = container or build_container()

    @asynccontextmanager
    async def lifespan(_app: FastAPI) -> AsyncIterator[None]:
        worker = WorkerThread(container, app.state.handoff) if run_worker else None
        app.state.worker = worker
        if worker is not None:
            worker.start()
        listening = container.settings.stream_listen and is_postgres(container.engine)
        wakeups = app.state.wakeups = Wakeups(container.engine) if listening else None
        try:
            yield
        finally:
            if wakeups is not None:
                wakeups.close()
            if worker is not None:
                worker.close()

    app = FastAPI(
        title="PBD-AG scene memory",
        version=API_VERSION,
        description=(
            "Long-term memory of a service robot: posted RGB-D observations become a persistent "
            "3D scene graph kept as an append-only log of typed events, with time travel (`as_of`) "
            "and explanations of every removal."
        ),
        lifespan=lifespan,
        docs_url=None,  # served from the package by install_pages: offline, no CDN
        redoc_url=None,
    )
    app.state.container = container
    app.state.states = StateReader(container.log)
    app.state.streams = StreamSlots(container.settings.max_streams)
    app.state.wakeups = None  # set while the lifespan runs, on PostgreSQL
    # What the API decodes, its worker need not decode again (only when it runs one).
    handoff_bytes = container.settings.handoff_max_bytes
    app.state.handoff = Handoff(handoff_bytes) if run_worker and handoff_bytes > 0 else None
    install_problem_handlers(app)
    install_pages(app)  # /docs, /viewer, /static (innermost: their headers on their answers)
    app.add_middleware(BodySizeLimit, max_bytes=container.settings.max_body_bytes)
    install_security(app, container)
    install_openapi(app)  # hosts, CORS, tokens, rate limits: before the body limit
    app.add_middleware(Methods, routes=app.router.routes)  # HEAD as GET; 405 with a full Allow
    app.add_middleware(UnexpectedErrors)  # a 500 keeps the connection
    app.add_middleware(ContentTypeOptions)  # nosniff on every answer, a 500 included
    app.add_middleware(RequestLog)  # outermost: every answer logged, with its scene and batch
    routers = (
        scenes,
        batches,
        graph,
        events,
        tracks,
        objects,
        verifications,
        baselines,
        inspections,
        plan,
    )
    for module in routers:
        app.include_router(module.router)

    @app.get("/healthz", response_model=Health, tags=["health"])
    def healthz() -> Health:
        """Liveness, the database backend, batches per status, and the in-process worker's
        health (`degraded` while it cannot record what it does)."""
        thread: WorkerThread | None = getattr(app.state, "worker", None)
        health = None if thread is None else thread.worker.health
        return Health(
            status="ok" if health is None or health.healthy else "degraded",
            database=container.engine.dialect.name,
            batches=container.queue.counts(),
            worker=None if health is None else WorkerStatus(**dataclasses.asdict(health)),
        )

    @app.get(
        "/metrics",
        tags=["health"],
        response_class=PlainTextResponse,
        responses={200: {"content": {"text/plain": {"schema": {"type": "string"}}}}},
    )
    def metrics() -> PlainTextResponse:
        """Prometheus metrics (text format): batches per status, the oldest waiting batch's age,
        this process's worker latencies, events appended and dead letters (`read` scope)."""
        return PlainTextResponse(container.metrics.exposition(), media_type=CONTENT_TYPE_LATEST)

    return app
