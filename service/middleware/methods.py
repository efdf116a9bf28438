"""HEAD wherever GET is, and a 405 whose `Allow` lists every method of the path.

HEAD is served here, as the GET of the same URL without its body, rather than by adding HEAD to
each route: one rule then covers every route, the pages and the static files, routes added later
included, and the OpenAPI document does not list a HEAD twin of every GET. Everything inside
sees a GET, so a HEAD needs the scope the GET needs (`read`) and answers the GET's status and
headers, Content-Length included. An answer that never ends by itself (the event stream) reads
`HEAD_KEY` in the scope to end after its headers.

A route answers 405 with its own methods only, and a path often has several routes
(`GET /v1/scenes` and `POST /v1/scenes` are two), so the answer's `Allow` is replaced by the
methods of every route whose path matches, HEAD with GET.
"""

from __future__ import annotations

from collections.abc import Sequence

from fastapi.routing import iter_route_contexts
from starlette.routing import BaseRoute, Match
from starlette.types import ASGIApp, Message, Receive, Scope, Send

HEAD_KEY = "pbdag.head"  # in the scope the routes see: the request was a HEAD
# The order `Allow` lists methods in; others follow alphabetically.
_ORDER = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")


def allowed_methods(routes: Sequence[BaseRoute], scope: Scope) -> list[str]:
    """The methods the routes serve at the path of `scope` (HEAD wherever GET), in `_ORDER`.

    Included routers are walked through (FastAPI's route contexts carry their full paths).
    """
    methods: set[str] = set()
    for route in iter_route_contexts(routes):
        if route.methods and route.matches(scope)[0] is not Match.NONE:
            methods.update(route.methods)
    if "GET" in methods:
        methods.add("HEAD")
    rank = {method: index for index, method in enumerate(_ORDER)}
    return sorted(methods, key=lambda method: (rank.get(method, len(_ORDER)), method))


class Methods:
    """Pure ASGI middleware: HEAD as GET without a body; every 405 with the path's full `Allow`.

    `routes` is the app's route list (read at each 405, so routes included later count).
    """

    def __init__(self, app: ASGIApp, *, routes: list[BaseRoute]) -> None:
        self.app = app
        self.routes = routes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Serve the request; a HEAD as a GET whose body is dropped."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        head = scope["method"] == "HEAD"
        # A copy: the server keeps its own scope, and must still see the HEAD to frame the answer.
        inner = {**scope, "method": "GET", HEAD_KEY: True} if head else scope
        requested = dict(inner)  # as it came: routing writes into the scope it is given

        async def send_answer(message: Message) -> None:
            if message["type"] == "http.response.start" and message["status"] == 405:
                allowed = allowed_methods(self.routes, requested)
                if allowed:  # else not a route's 405 (a mounted app's): its own answer stands
                    message["headers"] = [
                        *((k, v) for k, v in message.get("headers", []) if k.lower() != b"allow"),
                        (b"allow", ", ".join(allowed).encode()),
                    ]
            elif head and message["type"] == "http.response.body":
                message = {**message, "body": b""}
            await send(message)

        await self.app(inner, receive, send_answer)
