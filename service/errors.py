"""HTTP errors as RFC 9457 problem+json: one table from exception class to HTTP answer.

Every error a client can cause derives from `core.errors.PbdagError` and carries its detail and
its field; `PROBLEMS` gives each class its status, title and problem type, looked up along the
exception's class hierarchy (as Starlette looks up exception handlers). Nothing parses messages.
"""

from __future__ import annotations

import http
import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import orjson
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.responses import Response
from starlette.types import Send

from core.errors import (
    InvalidCommand,
    InvalidParams,
    PbdagError,
    StateConflict,
    UnknownTrack,
    field_path,
)
from service.access_errors import Forbidden, HostNotAllowed, RateLimited, Unauthorized
from service.codec import InvalidObservation
from service.store.errors import (
    BatchConflict,
    ConcurrencyConflict,
    SceneNotFound,
    SceneQuarantined,
    SeqOutOfRange,
    StoreError,
    UnreadableEvent,
)
from service.store.queue import NotRequeueable, QueueFull, QuotaExceeded

PROBLEM_MEDIA_TYPE = "application/problem+json"


class NotFound(PbdagError):
    """A named resource (batch, track, baseline...) does not exist."""

    def __init__(self, what: str, id: str, field: str | None = None) -> None:
        super().__init__(f"{what} '{id}' does not exist", field)


class PayloadTooLarge(PbdagError):
    """The request body is larger than the service accepts."""

    def __init__(self, max_bytes: int) -> None:
        super().__init__(f"request body exceeds the limit of {max_bytes} bytes", "body")


@dataclass(frozen=True)
class Problem:
    """The HTTP answer of one error class."""

    status: int
    title: str
    type: str  # a relative URI naming the problem


INTERNAL = Problem(500, "Internal Server Error", "/problems/internal-error")

# The one table. More specific classes win over their bases.
PROBLEMS: dict[type[Exception], Problem] = {
    HostNotAllowed: Problem(400, "Host not allowed", "/problems/host-not-allowed"),
    Unauthorized: Problem(401, "Unauthorized", "/problems/unauthorized"),
    Forbidden: Problem(403, "Forbidden", "/problems/insufficient-scope"),
    NotFound: Problem(404, "Not Found", "/problems/not-found"),
    SceneNotFound: Problem(404, "Not Found", "/problems/not-found"),
    UnknownTrack: Problem(404, "Not Found", "/problems/unknown-track"),
    SeqOutOfRange: Problem(404, "Not Found", "/problems/seq-out-of-range"),
    BatchConflict: Problem(409, "Conflict", "/problems/batch-conflict"),
    ConcurrencyConflict: Problem(409, "Conflict", "/problems/conflict"),
    StateConflict: Problem(409, "Conflict", "/problems/state-conflict"),
    NotRequeueable: Problem(409, "Conflict", "/problems/not-requeueable"),
    UnreadableEvent: Problem(409, "Scene needs repair", "/problems/scene-needs-repair"),
    SceneQuarantined: Problem(409, "Scene quarantined", "/problems/scene-quarantined"),
    PayloadTooLarge: Problem(413, "Payload Too Large", "/problems/payload-too-large"),
    InvalidCommand: Problem(422, "Invalid command", "/problems/invalid-command"),
    InvalidParams: Problem(422, "Invalid parameters", "/problems/invalid-params"),
    InvalidObservation: Problem(422, "Invalid observation", "/problems/invalid-observation"),
    RateLimited: Problem(429, "Too Many Requests", "/problems/rate-limited"),
    QueueFull: Problem(429, "Too Many Requests", "/problems/queue-full"),
    QuotaExceeded: Problem(507, "Insufficient Storage", "/problems/quota-exceeded"),
    StoreError: INTERNAL,
}


def problem_of(error: BaseException) -> Problem:
    """The table entry of the nearest class of `error` that has one."""
    for cls in type(error).__mro__:
        problem = PROBLEMS.get(cls)
        if problem is not None:
            return problem
    return INTERNAL


def problem_body(
    problem: Problem, detail: str, field: str | None, errors: Iterable[tuple[str | None, str]] = ()
) -> bytes:
    """The problem document; every key is always present so clients parse one shape."""
    return orjson.dumps(
        {
            "type": problem.type,
            "title": problem.title,
            "status": problem.status,
            "detail": detail,
            "field": field,
            "errors": [{"field": name, "reason": reason} for name, reason in errors],
        }
    )


def problem_response(
    problem: Problem,
    detail: str,
    field: str | None = None,
    errors: Sequence[tuple[str | None, str]] | None = None,
    headers: dict[str, str] | None = None,
) -> Response:
    """A problem+json response; `errors` defaults to the one field and detail."""
    listed = errors if errors is not None else [(field, detail)]
    body = problem_body(problem, detail, field, listed)
    return Response(body, problem.status, headers=headers, media_type=PROBLEM_MEDIA_TYPE)


def reported(error: PbdagError) -> tuple[Problem, str, str | None]:
    """The problem, detail and field a client sees for `error` (nothing internal for a 500)."""
    problem = problem_of(error)
    if problem is INTERNAL:  # a store failure no client caused: say nothing of internals
        return INTERNAL, "the server failed to process the request", None
    return problem, error.detail, error.field


async def send_problem(send: Send, error: PbdagError) -> None:
    """Answer with a problem+json document straight on the ASGI channel (from middleware)."""
    problem, detail, field = reported(error)
    body = problem_body(problem, detail, field, [(field, detail)])
    extra = [(name.lower().encode(), value.encode()) for name, value in error.headers.items()]
    await send(
        {
            "type": "http.response.start",
            "status": problem.status,
            "headers": [
                (b"content-type", PROBLEM_MEDIA_TYPE.encode()),
                (b"content-length", str(len(body)).encode()),
                *extra,
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})


async def _handle_reported(request: Request, exc: Exception) -> Response:
    """Every PbdagError: its table entry, its detail and field, and its headers."""
    assert isinstance(exc, PbdagError)
    problem, detail, field = reported(exc)
    return problem_response(problem, detail, field, headers=exc.headers or None)


INVALID_REQUEST = Problem(422, "Invalid request", "/problems/invalid-request")


async def _handle_request_validation(request: Request, exc: Exception) -> Response:
    """Pydantic errors of the request, every one listed with its field path."""
    assert isinstance(exc, RequestValidationError)
    errors = [_validation_error(error) for error in exc.errors()] or [
        (None, "the request is invalid")
    ]
    field, reason = errors[0]
    detail = f"{field}: {reason}" if field else reason
    if len(errors) > 1:
        detail += f" (and {len(errors) - 1} more)"
    return problem_response(INVALID_REQUEST, detail, field, errors)


def _validation_error(error: Any) -> tuple[str | None, str]:
    """One pydantic/FastAPI error as a field path and reason (never echoing the input)."""
    if error.get("type") == "json_invalid":
        # FastAPI puts the character offset in `loc`; it is not a field.
        location = error.get("loc", ())
        offset = location[-1] if len(location) > 1 else "?"
        cause = error.get("ctx", {}).get("error", "malformed JSON")
        return None, f"body is not valid JSON: {cause} at character {offset}"
    location = list(error.get("loc", ()))
    if location and location[0] in ("body", "query", "path", "header"):
        location = location[1:]
    return field_path(location), str(error.get("msg", "invalid value"))


async def _handle_http_exception(request: Request, exc: Exception) -> Response:
    """Routing errors (404 unknown route, 405 wrong method) and explicit HTTPExceptions."""
    assert isinstance(exc, StarletteHTTPException)
    headers = dict(exc.headers) if exc.headers else None
    if exc.status_code < 200 or exc.status_code in (204, 304):
        return Response(status_code=exc.status_code, headers=headers)  # no body allowed
    detail = exc.detail if isinstance(exc.detail, str) else json.dumps(exc.detail, default=str)
    problem = Problem(exc.status_code, _phrase(exc.status_code), "about:blank")
    return problem_response(problem, detail, headers=headers)


def _phrase(status: int) -> str:
    try:
        return http.HTTPStatus(status).phrase
    except ValueError:
        return "Error"


def install_problem_handlers(app: FastAPI) -> None:
    """Make every error response of `app` an RFC 9457 problem+json document.

    Exceptions outside these classes reach `service.middleware.unexpected`, which answers 500
    without closing the connection.
    """
    app.add_exception_handler(PbdagError, _handle_reported)
    app.add_exception_handler(RequestValidationError, _handle_request_validation)
    app.add_exception_handler(StarletteHTTPException, _handle_http_exception)
