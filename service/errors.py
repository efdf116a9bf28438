"""HTTP errors as RFC 9457 problem+json: the only place domain errors become status codes."""

from __future__ import annotations

import http
import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import orjson
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.responses import Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from core.errors import DomainError, InvalidCommand, StateConflict, UnknownTrack
from service.codec import InvalidObservation
from service.store.errors import BatchConflict, SceneNotFound, SeqOutOfRange, StoreError

__all__ = [
    "PROBLEM_MEDIA_TYPE",
    "BodySizeLimit",
    "Conflict",
    "FieldError",
    "NotFound",
    "PayloadTooLarge",
    "ProblemError",
    "field_path",
    "install_problem_handlers",
    "problem_body",
]

PROBLEM_MEDIA_TYPE = "application/problem+json"
# RFC 9457: "about:blank" means the problem is fully described by its HTTP status.
GENERIC_PROBLEM_TYPE = "about:blank"
_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


@dataclass(frozen=True)
class FieldError:
    """One offending request field (a path like `frames[0].pose`) and why."""

    field: str | None
    reason: str


class ProblemError(Exception):
    """Base of errors the service answers with a problem+json body."""

    status: int = 500
    title: str = "Internal Server Error"
    type: str = "/problems/internal-error"

    def __init__(
        self, detail: str, *, field: str | None = None, errors: Sequence[FieldError] = ()
    ) -> None:
        super().__init__(detail)
        self.detail = detail
        self.field = field
        self.errors = tuple(errors)


class NotFound(ProblemError):
    """A named resource (scene, batch, object...) does not exist."""

    status = 404
    title = "Not Found"
    type = "/problems/not-found"

    def __init__(self, what: str, id: str) -> None:
        super().__init__(f"{what} '{id}' does not exist")
        self.what = what
        self.id = id


class Conflict(ProblemError):
    """The request contradicts the current state, e.g. a reused batch_id with new content."""

    status = 409
    title = "Conflict"
    type = "/problems/conflict"


class PayloadTooLarge(ProblemError):
    """The request body is larger than the service accepts."""

    status = 413
    title = "Payload Too Large"
    type = "/problems/payload-too-large"

    def __init__(self, max_bytes: int) -> None:
        super().__init__(f"request body exceeds the limit of {max_bytes} bytes")
        self.max_bytes = max_bytes


def problem_body(
    *,
    status: int,
    title: str,
    detail: str,
    type: str = GENERIC_PROBLEM_TYPE,
    field: str | None = None,
    errors: Sequence[FieldError] = (),
) -> bytes:
    """Serialize a problem document; every key is always present so clients parse one shape."""
    return orjson.dumps(
        {
            "type": type,
            "title": title,
            "status": status,
            "detail": detail,
            "field": field,
            "errors": [{"field": error.field, "reason": error.reason} for error in errors],
        }
    )


def field_path(location: Sequence[str | int]) -> str | None:
    """Turn a pydantic error location into a path like `frames[0].pose`, without `body`."""
    parts = list(location)
    if parts and parts[0] == "body":
        parts = parts[1:]
    path = ""
    for part in parts:
        if isinstance(part, int):
            path += f"[{part}]"
        elif _IDENTIFIER.fullmatch(part):
            path += f".{part}" if path else part
        else:
            # Dict keys such as class-score labels may contain spaces or dots.
            path += f"[{json.dumps(part)}]"
    return path or None


def _problem_response(
    *,
    status: int,
    title: str,
    detail: str,
    type: str = GENERIC_PROBLEM_TYPE,
    field: str | None = None,
    errors: Sequence[FieldError] = (),
    headers: dict[str, str] | None = None,
) -> Response:
    """A problem+json response."""
    body = problem_body(
        status=status, title=title, detail=detail, type=type, field=field, errors=errors
    )
    return Response(body, status_code=status, headers=headers, media_type=PROBLEM_MEDIA_TYPE)


def _status_phrase(status: int) -> str:
    """The standard reason phrase of a status code, or a generic one."""
    try:
        return http.HTTPStatus(status).phrase
    except ValueError:
        return "Error"


async def _handle_problem(request: Request, exc: Exception) -> Response:
    """ProblemError and subclasses: they already carry every member."""
    assert isinstance(exc, ProblemError)
    return _problem_response(
        status=exc.status,
        title=exc.title,
        detail=exc.detail,
        type=exc.type,
        field=exc.field,
        errors=exc.errors,
    )


async def _handle_invalid_observation(request: Request, exc: Exception) -> Response:
    """Codec errors: the body parsed but its depth, masks or poses are not usable."""
    assert isinstance(exc, InvalidObservation)
    return _problem_response(
        status=422,
        title="Invalid observation",
        detail=f"{exc.field}: {exc.reason}",
        type="/problems/invalid-observation",
        field=exc.field,
        errors=[FieldError(exc.field, exc.reason)],
    )


async def _handle_request_validation(request: Request, exc: Exception) -> Response:
    """Pydantic errors of the request, every one listed with its field path."""
    assert isinstance(exc, RequestValidationError)
    errors = [_validation_field_error(error) for error in exc.errors()]
    if not errors:
        errors = [FieldError(None, "the request is invalid")]
    first = errors[0]
    detail = f"{first.field}: {first.reason}" if first.field else first.reason
    if len(errors) > 1:
        detail += f" (and {len(errors) - 1} more)"
    return _problem_response(
        status=422,
        title="Invalid request",
        detail=detail,
        type="/problems/invalid-request",
        field=first.field,
        errors=errors,
    )


def _validation_field_error(error: Any) -> FieldError:
    """One pydantic/FastAPI error as a field path and reason (never echoing the input)."""
    if error.get("type") == "json_invalid":
        # FastAPI puts the character offset in `loc`; it is not a field.
        location = error.get("loc", ())
        offset = location[-1] if len(location) > 1 else "?"
        cause = error.get("ctx", {}).get("error", "malformed JSON")
        return FieldError(None, f"body is not valid JSON: {cause} at character {offset}")
    return FieldError(field_path(error.get("loc", ())), str(error.get("msg", "invalid value")))


async def _handle_http_exception(request: Request, exc: Exception) -> Response:
    """Routing errors (404 unknown route, 405 wrong method) and explicit HTTPExceptions."""
    assert isinstance(exc, StarletteHTTPException)
    headers = dict(exc.headers) if exc.headers else None
    if exc.status_code < 200 or exc.status_code in (204, 304):
        # These statuses cannot carry a body.
        return Response(status_code=exc.status_code, headers=headers)
    detail = exc.detail if isinstance(exc.detail, str) else json.dumps(exc.detail, default=str)
    return _problem_response(
        status=exc.status_code,
        title=_status_phrase(exc.status_code),
        detail=detail,
        headers=headers,
    )


async def _handle_unexpected(request: Request, exc: Exception) -> Response:
    """Anything else: a bare 500 that names no internals (the server logs the traceback)."""
    return _problem_response(
        status=500,
        title="Internal Server Error",
        detail="the server failed to process the request",
        type=ProblemError.type,
    )


# The store's exceptions and the HTTP answer each gets.
_STORE_PROBLEMS: dict[type[StoreError], tuple[int, str, str, str | None]] = {
    SceneNotFound: (404, "Not Found", "/problems/not-found", "scene_id"),
    SeqOutOfRange: (404, "Not Found", "/problems/seq-out-of-range", "as_of"),
    BatchConflict: (409, "Conflict", "/problems/batch-conflict", "batch_id"),
}


async def _handle_store_error(request: Request, exc: Exception) -> Response:
    """Store errors a client can cause: unknown scene, as_of beyond the head, reused batch id."""
    for error_type, (status, title, problem_type, field) in _STORE_PROBLEMS.items():
        if isinstance(exc, error_type):
            return _problem_response(
                status=status,
                title=title,
                detail=str(exc),
                type=problem_type,
                field=field,
                errors=[FieldError(field, str(exc))],
            )
    return await _handle_unexpected(request, exc)


# The core's command errors and the HTTP answer each gets.
_DOMAIN_PROBLEMS: dict[type[DomainError], tuple[int, str, str]] = {
    UnknownTrack: (404, "Not Found", "/problems/unknown-track"),
    InvalidCommand: (422, "Invalid command", "/problems/invalid-command"),
    StateConflict: (409, "Conflict", "/problems/state-conflict"),
}


async def _handle_domain_error(request: Request, exc: Exception) -> Response:
    """A command the scene's state does not allow: nothing was appended."""
    assert isinstance(exc, DomainError)
    status, title, problem_type = next(
        (answer for kind, answer in _DOMAIN_PROBLEMS.items() if isinstance(exc, kind)),
        (409, "Conflict", "/problems/state-conflict"),
    )
    return _problem_response(
        status=status,
        title=title,
        detail=exc.detail,
        type=problem_type,
        field=exc.field,
        errors=[FieldError(exc.field, exc.detail)],
    )


def install_problem_handlers(app: FastAPI) -> None:
    """Make every error response of `app` an RFC 9457 problem+json document."""
    app.add_exception_handler(ProblemError, _handle_problem)
    app.add_exception_handler(StoreError, _handle_store_error)
    app.add_exception_handler(DomainError, _handle_domain_error)
    app.add_exception_handler(InvalidObservation, _handle_invalid_observation)
    app.add_exception_handler(RequestValidationError, _handle_request_validation)
    app.add_exception_handler(StarletteHTTPException, _handle_http_exception)
    app.add_exception_handler(Exception, _handle_unexpected)


class BodySizeLimit:
    """Pure ASGI middleware: 413 problem+json for bodies over `max_bytes`, without buffering."""

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
                    raise PayloadTooLarge(self.max_bytes)
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
        problem = PayloadTooLarge(self.max_bytes)
        body = problem_body(
            status=problem.status, title=problem.title, detail=problem.detail, type=problem.type
        )
        await send(
            {
                "type": "http.response.start",
                "status": problem.status,
                "headers": [
                    (b"content-type", PROBLEM_MEDIA_TYPE.encode()),
                    (b"content-length", str(len(body)).encode()),
                ],
            }
        )
        await send({"type": "http.response.body", "body": body})
