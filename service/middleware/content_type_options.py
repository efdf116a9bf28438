"""`X-Content-Type-Options: nosniff` on every answer: a browser never guesses a media type.

An export, a problem document or a JSON answer holding text from the log is then never run as
a script or rendered as HTML because a browser's sniffing took it for one.
"""

from __future__ import annotations

from starlette.types import ASGIApp, Message, Receive, Scope, Send

HEADER = b"x-content-type-options"


class ContentTypeOptions:
    """Pure ASGI middleware: add `X-Content-Type-Options: nosniff` unless the answer has one."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Pass the request through; add the header to the response's start."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_header(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers", []))
                if all(name.lower() != HEADER for name, _value in headers):
                    headers.append((HEADER, b"nosniff"))
                message["headers"] = headers
            await send(message)

        await self.app(scope, receive, send_with_header)
