"""One log record per request (method, path, status, milliseconds), and the request's scene and
batch ids (from the path) on every record logged while it is served."""

from __future__ import annotations

import logging
import re
import time

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.logs import log_context

logger = logging.getLogger("pbdag.api")
_SCENE_PATH = re.compile(r"^/v1/scenes/(?P<scene_id>[^/]+)(?:/batches/(?P<batch_id>[^/]+))?")


class RequestLog:
    """Pure ASGI middleware: the log context of the request, then its access record."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Serve the request inside its log context; log how it ended."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        path = str(scope["path"])
        match = _SCENE_PATH.match(path)
        ids = match.groupdict() if match else {}
        status = 500
        start = time.perf_counter()

        async def tracking_send(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = int(message["status"])
            await send(message)

        with log_context(scene_id=ids.get("scene_id"), batch_id=ids.get("batch_id")):
            try:
                await self.app(scope, receive, tracking_send)
            finally:
                logger.info(
                    "%s %s %d %.1f ms",
                    scope["method"],
                    path,
                    status,
                    1000 * (time.perf_counter() - start),
                )
