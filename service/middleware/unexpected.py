"""The last resort: an exception no handler knows becomes a 500 that names no internals.

Starlette's own outermost handler answers 500 too, but then re-raises, and the server closes the
keep-alive connection; a robot's client would see its next request fail. This middleware sits
inside it, logs the traceback with the request line, answers, and keeps the connection.
"""

from __future__ import annotations

import logging

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from pbdag_errors import PbdagError
from service.errors import send_problem

logger = logging.getLogger("pbdag.api")


class UnexpectedErrors:
    """500 problem+json for any exception that escapes the app, logged, without re-raising."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Pass through; on an escaping exception answer 500 if nothing was sent yet."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = False

        async def tracking_send(message: Message) -> None:
            nonlocal started
            if message["type"] == "http.response.start":
                started = True
            await send(message)

        try:
            await self.app(scope, receive, tracking_send)
        except Exception:
            logger.exception("unexpected error on %s %s", scope.get("method"), scope.get("path"))
            if started:
                raise  # the response is half sent: only closing the connection is honest
            await send_problem(send, PbdagError("unexpected"))  # unregistered: a bare 500
