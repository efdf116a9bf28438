"""The service's problem+json answers (RFC 9457) as typed exceptions, one class per status.

Every error answer of the API is a `Problem` document naming the offending field; `problem_error`
turns a response into the exception of its status, carrying that document's members. The classes
mirror the project's one hierarchy (`pbdag_errors`) without redefining its names: `ApiError` is a
`PbdagError`, a 4xx answer (`RequestRefused` and below) is a `Refused`, a 5xx (`ServerError`) a
`Failure`. Transport failures (refused connection, timeout) stay httpx's own
`httpx.TransportError`s.
"""

from __future__ import annotations

import email.utils
import time

import httpx
from pydantic import ValidationError

from api_schema import BatchStatus, Problem, ProblemField
from pbdag_errors import Failure, PbdagError, Refused

__all__ = [
    "AccessDenied",
    "ApiError",
    "BadRequest",
    "BatchDead",
    "BatchTimeout",
    "Conflict",
    "Forbidden",
    "InsufficientStorage",
    "InvalidRequest",
    "PayloadTooLarge",
    "PbdagError",
    "RateLimited",
    "RequestRefused",
    "ResourceNotFound",
    "ServerError",
    "Unauthorized",
    "problem_error",
]


class ApiError(PbdagError):
    """An error answer of the service: its status and problem document (type, title, detail,
    the offending field and every offending field)."""

    def __init__(
        self,
        status: int,
        type: str,
        title: str,
        detail: str,
        field: str | None = None,
        errors: list[ProblemField] | None = None,
        headers: httpx.Headers | None = None,
    ) -> None:
        super().__init__(detail, field)
        self.status = status
        self.type = type
        self.title = title
        self.errors: list[ProblemField] = errors if errors is not None else []
        self.headers = headers if headers is not None else httpx.Headers()

    def __str__(self) -> str:
        return f"HTTP {self.status} {self.title}: {self.detail}"

    @property
    def fields(self) -> list[str]:
        """Every field the problem names, first the main one."""
        named = [self.field] if self.field else []
        return named + [e.field for e in self.errors if e.field and e.field not in named]


class RequestRefused(ApiError, Refused):
    """4xx, and the 507 of a full quota: the service refused the request and changed nothing."""


class BadRequest(RequestRefused):
    """400: e.g. a Host name the service does not accept."""


class AccessDenied(RequestRefused):
    """401 or 403: no valid token, or a token without the scope the request needs."""


class Unauthorized(AccessDenied):
    """401: a missing, unknown or revoked bearer token."""


class Forbidden(AccessDenied):
    """403: the token lacks the scope (read, write, admin) the request needs."""


class ResourceNotFound(RequestRefused):
    """404: no such scene, batch, track, baseline or seq."""


class Conflict(RequestRefused):
    """409: new content under an old batch_id, a repeated verdict, a quarantined scene..."""


class PayloadTooLarge(RequestRefused):
    """413: the request body is over the service's size limit."""


class InvalidRequest(RequestRefused):
    """422: a request the service cannot accept; `field` names the offending field."""


class RateLimited(RequestRefused):
    """429: too many requests, or the scene's queue is full; retry after `retry_after` seconds."""

    @property
    def retry_after(self) -> float | None:
        """Seconds to wait before retrying, from the Retry-After header (None without one)."""
        return retry_after_seconds(self.headers.get("retry-after"))


class InsufficientStorage(RequestRefused):
    """507: the scene is over its byte quota (a 5xx status, but a limit of the scene, not a
    failure of the service: nothing was changed, and the request is refused until space frees)."""


class ServerError(ApiError, Failure):
    """5xx: the service failed (the request may be retried later)."""


_BY_STATUS: dict[int, type[ApiError]] = {
    400: BadRequest,
    401: Unauthorized,
    403: Forbidden,
    404: ResourceNotFound,
    409: Conflict,
    413: PayloadTooLarge,
    422: InvalidRequest,
    429: RateLimited,
    507: InsufficientStorage,
}


def error_class(status: int) -> type[ApiError]:
    """The exception class of an HTTP error status."""
    if status in _BY_STATUS:
        return _BY_STATUS[status]
    if status >= 500:
        return ServerError
    return RequestRefused if status >= 400 else ApiError


def problem_error(response: httpx.Response) -> ApiError:
    """The typed exception of an error response (a problem+json document, or any other body)."""
    cls = error_class(response.status_code)
    try:
        problem = Problem.model_validate_json(response.content)
    except ValidationError:
        # Not the service's document (a proxy's page, say): keep the status and a short text.
        phrase = response.reason_phrase or "Error"
        text = response.text.strip()[:300] or phrase
        return cls(response.status_code, "about:blank", phrase, text, headers=response.headers)
    return cls(
        response.status_code,
        problem.type,
        problem.title,
        problem.detail,
        problem.field,
        problem.errors,
        response.headers,
    )


def retry_after_seconds(value: str | None) -> float | None:
    """A Retry-After header (delta seconds or an HTTP date) as seconds from now."""
    if value is None:
        return None
    try:
        return max(0.0, float(value))
    except ValueError:
        pass
    try:
        when = email.utils.parsedate_to_datetime(value)
    except (TypeError, ValueError):
        return None
    return max(0.0, when.timestamp() - time.time())


class BatchDead(PbdagError, RuntimeError):
    """A batch that failed every attempt (`dead`): the service keeps its error."""

    def __init__(self, batch: BatchStatus) -> None:
        super().__init__(
            f"batch {batch.batch_id} of scene {batch.scene_id} is dead after "
            f"{batch.attempts} attempts: {batch.error}",
            "batch_id",
        )
        self.batch = batch


class BatchTimeout(PbdagError, TimeoutError):
    """A batch still queued or running when the wait ran out."""

    def __init__(self, batch: BatchStatus, timeout_s: float) -> None:
        super().__init__(
            f"batch {batch.batch_id} of scene {batch.scene_id} still {batch.status} "
            f"after {timeout_s:g} s",
            "batch_id",
        )
        self.batch = batch
