"""HTTP errors as RFC 9457 problem+json: one table from exception class to HTTP answer.

Every error a client can cause is a `pbdag_errors.Refused` and carries its detail and its field;
`PROBLEMS` gives each class its status, title and problem type, looked up along the exception's
class hierarchy (as Starlette looks up exception handlers), and `headers_of` the headers HTTP
asks for. A `Failure` (the store failed) and anything else is a 500 that names nothing internal.
Nothing parses messages; nothing outside this module knows HTTP's statuses or headers.
"""

from __future__ import annotations

import http
import json
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import orjson
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.responses import Response
from starlette.types import Message, Send

from codec.observations import InvalidObservation
from core.errors import (
    InvalidCommand,
    InvalidParams,
    NotFound,
    StateConflict,
    UnknownTrack,
    field_path,
)
from pbdag_errors import Failure, PbdagError
from service.access_errors import (
    BodyTooLarge,
    HostNotAllowed,
    InsufficientScope,
    NotAuthenticated,
    RateLimitExceeded,
)
from service.feed import TooManyStreams
from service.store.errors import (
    BatchConflict,
    ConcurrencyConflict,
    SceneQuarantined,
    SeqOutOfRange,
    StoreUnavailable,
    UnreadableEvent,
)
from service.store.queue_records import NotRequeueable, QueueFull, QuotaExceeded, RawBatchCollected

logger = logging.getLogger("pbdag.api")
PROBLEM_MEDIA_TYPE = "application/problem+json"
REALM = 'realm="pbdag"'  # of the bearer challenges (RFC 6750 section 3)


@dataclass(frozen=True)
class Problem:
    """The HTTP answer of one error class."""

    status: int
    title: str
    type: str  # a relative URI naming the problem


INTERNAL = Problem(500, "Internal Server Error", "/problems/internal-error")

# The one table: what a client can cause (`Refused`), then what the server fails at (`Failure`).
# More specific classes win over their bases.
PROBLEMS: dict[type[Exception], Problem] = {
    HostNotAllowed: Problem(400, "Host not allowed", "/problems/host-not-allowed"),
    NotAuthenticated: Problem(401, "Unauthorized", "/problems/unauthorized"),
    InsufficientScope: Problem(403, "Forbidden", "/problems/insufficient-scope"),
    NotFound: Problem(404, "Not Found", "/problems/not-found"),  # SceneNotFound too
    UnknownTrack: Problem(404, "Not Found", "/problems/unknown-track"),
    SeqOutOfRange: Problem(404, "Not Found", "/problems/seq-out-of-range"),
    BatchConflict: Problem(409, "Conflict", "/problems/batch-conflict"),
    ConcurrencyConflict: Problem(409, "Conflict", "/problems/conflict"),
    StateConflict: Problem(409, "Conflict", "/problems/state-conflict"),
    NotRequeueable: Problem(409, "Conflict", "/problems/not-requeueable"),
    RawBatchCollected: Problem(410, "Gone", "/problems/raw-batch-collected"),
    UnreadableEvent: Problem(409, "Scene needs repair", "/problems/scene-needs-repair"),
    SceneQuarantined: Problem(409, "Scene quarantined", "/problems/scene-quarantined"),
    BodyTooLarge: Problem(413, "Payload Too Large", "/problems/payload-too-large"),
    InvalidCommand: Problem(422, "Invalid command", "/problems/invalid-command"),
    InvalidParams: Problem(422, "Invalid parameters", "/problems/invalid-params"),
    InvalidObservation: Problem(422, "Invalid observation", "/problems/invalid-observation"),
    RateLimitExceeded: Problem(429, "Too Many Requests", "/problems/rate-limited"),
    QueueFull: Problem(429, "Too Many Requests", "/problems/queue-full"),
    QuotaExceeded: Problem(507, "Insufficient Storage", "/problems/quota-exceeded"),
    StoreUnavailable: Problem(503, "Service Unavailable", "/problems/store-unavailable"),
    TooManyStreams: Problem(503, "Service Unavailable", "/problems/too-many-streams"),
    Failure: INTERNAL,
}
# A lost database connection or a full disk may pass: the client is told to retry after this.
STORE_RETRY_AFTER_SECONDS = 2


def headers_of(error: PbdagError) -> dict[str, str] | None:
    """The response headers HTTP asks for with `error`: a bearer challenge with a 401 or 403
    (RFC 6750 section 3), Retry-After with a 429 or a 503."""
    match error:
        case NotAuthenticated(token_error=None):
            return {"WWW-Authenticate": f"Bearer {REALM}"}
        case NotAuthenticated(token_error=token_error):
            return {"WWW-Authenticate": f'Bearer {REALM}, error="{token_error}"'}
        case InsufficientScope(needed=needed):
            challenge = f'Bearer {REALM}, error="insufficient_scope", scope="{needed}"'
            return {"WWW-Authenticate": challenge}
        case (
            RateLimitExceeded(retry_after=seconds)
            | QueueFull(retry_after=seconds)
            | TooManyStreams(retry_after=seconds)
        ):
            return {"Retry-After": str(seconds)}
        case StoreUnavailable():
            return {"Retry-After": str(STORE_RETRY_AFTER_SECONDS)}
    return None


def problem_of(error: BaseException) -> Problem:
    """The table entry of the nearest class of `error` that has one."""
    for cls in type(error).__mro__:
        problem = PROBLEMS.get(cls)
        if problem is not None:
            return problem
    return INTERNAL


def problem_response(
    problem: Problem,
    detail: str,
    field: str | None = None,
    errors: Sequence[tuple[str | None, str]] | None = None,
    headers: dict[str, str] | None = None,
) -> Response:
    """A problem+json response, every key always present; `errors` defaults to the field."""
    listed = errors if errors is not None else [(field, detail)]
    body = orjson.dumps(
        {
            "type": problem.type,
            "title": problem.title,
            "status": problem.status,
            "detail": detail,
            "field": field,
            "errors": [{"field": name, "reason": reason} for name, reason in listed],
        }
    )
    return Response(body, problem.status, headers=headers, media_type=PROBLEM_MEDIA_TYPE)


def reported(error: PbdagError) -> Response:
    """The answer to `error`: its table entry, detail, field and headers (nothing internal for
    a 500: a failure no client caused)."""
    problem = problem_of(error)
    if problem is INTERNAL:
        return problem_response(INTERNAL, "the server failed to process the request")
    if isinstance(error, StoreUnavailable):  # the driver's words stay in the server's log
        detail = "the database or the blob store is unavailable for a moment; retry"
        return problem_response(problem, detail, headers=headers_of(error))
    return problem_response(problem, error.detail, error.field, headers=headers_of(error))


async def send_problem(send: Send, error: PbdagError) -> None:
    """Answer with a problem+json document straight on the ASGI channel (from middleware)."""
    await reported(error)({"type": "http"}, _nothing_to_receive, send)


async def _nothing_to_receive() -> Message:
    return {"type": "http.disconnect"}  # a response never reads the request


async def _handle_reported(request: Request, exc: Exception) -> Response:
    assert isinstance(exc, PbdagError)
    if problem_of(exc) is INTERNAL:  # the server failed: the log keeps what the answer hides
        logger.error("%s on %s %s", exc.detail, request.method, request.url.path, exc_info=exc)
    elif isinstance(exc, StoreUnavailable):
        logger.warning("%s on %s %s (answered 503)", exc.detail, request.method, request.url.path)
    return reported(exc)


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
    phrase = http.HTTPStatus(exc.status_code).phrase if exc.status_code in _STATUSES else "Error"
    return problem_response(
        Problem(exc.status_code, phrase, "about:blank"), detail, headers=headers
    )


_STATUSES = frozenset(status.value for status in http.HTTPStatus)


def install_problem_handlers(app: FastAPI) -> None:
    """Every error response of `app` a problem+json document (other exceptions reach
    `service.middleware.unexpected`, a 500 that keeps the connection)."""
    app.add_exception_handler(PbdagError, _handle_reported)
    app.add_exception_handler(RequestValidationError, _handle_request_validation)
    app.add_exception_handler(StarletteHTTPException, _handle_http_exception)
