"""413 problem+json for bodies over the limit, checked before and while the app reads them."""

from __future__ import annotations

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from service.access_errors import BodyTooLarge
from service.errors import send_problem


class BodySizeLimit:
    """Pure ASGI middleware: rejects by Content-Length up front, else counts streamed chunks."""

    def __init__(self, app: ASGIApp, max_bytes: int) -> None:
        if max_bytes < 0:
            raise ValueError(f"max_bytes must be >= 0, got {max_bytes}")
        self.app = app
        self.max_bytes = max_bytes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Reject by Content-Length up front, else count streamed chunks as the app reads."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        if self._declared_length(scope) > self.max_bytes:
            await self._send_too_large(send)
            return

        received = 0
        exceeded = False
        response_started = False

        async def limited_receive() -> Message:
            nonlocal received, exceeded
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.max_bytes:
                    exceeded = True
                    # Raising stops the app from buffering the rest of the body.
                    raise BodyTooLarge(self.max_bytes)
            return message

        async def guarded_send(message: Message) -> None:
            nonlocal response_started
            # Once over the limit, whatever the app answers (its own 413, or FastAPI's
            # "error parsing the body" 400) is replaced by the 413 below.
            if exceeded:
                return
            if message["type"] == "http.response.start":
                response_started = True
            await send(message)

        try:
            await self.app(scope, limited_receive, guarded_send)
        except Exception:
            if not exceeded:
                raise
        if exceeded and not response_started:
            await self._send_too_large(send)

    @staticmethod
    def _declared_length(scope: Scope) -> int:
        """The largest Content-Length header, or 0 when absent or malformed (then we count)."""
        declared = 0
        for name, value in scope.get("headers", ()):
            if name.lower() == b"content-length" and value.strip().isdigit():
                declared = max(declared, int(value))
        return declared

    async def _send_too_large(self, send: Send) -> None:
        """Answer 413 straight on the ASGI channel (no Request object exists here)."""
        await send_problem(send, BodyTooLarge(self.max_bytes))
