"""The errors of the LAN boundary: unknown Host, missing or bad token, missing scope, rate limit,
a body over the limit.

Each keeps what its answer needs (the token error, the scope, the seconds to wait); the statuses
and the headers HTTP asks for (WWW-Authenticate, Retry-After) are in the one problem table
(service/errors.py).
"""

from __future__ import annotations

from pbdag_errors import Refused

AUTH_FIELD = "authorization"  # the request header a token problem is about


class AccessProblem(Refused):
    """Base of the access errors."""


class HostNotAllowed(AccessProblem):
    """The Host header names a host the service does not answer for (DNS rebinding)."""

    def __init__(self, host: str) -> None:
        super().__init__(
            f"the Host header {host!r} is not one this service answers for; "
            "an operator adds the names clients use to PBDAG_ALLOWED_HOSTS",
            "host",
        )


class NotAuthenticated(AccessProblem):
    """No token, or one that is malformed, unknown or revoked (RFC 6750 section 3); `token_error`
    is RFC 6750's error code when a token was sent."""

    def __init__(self, detail: str, *, token_error: str | None = None) -> None:
        super().__init__(detail, AUTH_FIELD)
        self.token_error = token_error


class InsufficientScope(AccessProblem):
    """A valid client without the scope the request needs."""

    def __init__(self, detail: str, *, needed: str) -> None:
        super().__init__(detail, AUTH_FIELD)
        self.needed = needed


class RateLimitExceeded(AccessProblem):
    """Too many requests from one token (or one address): retry after `retry_after` seconds."""

    def __init__(self, retry_after: int, *, per_minute: int, field: str | None) -> None:
        super().__init__(
            f"rate limit of {per_minute} requests per minute exceeded; retry in {retry_after} s",
            field,
        )
        self.retry_after = retry_after


class BodyTooLarge(AccessProblem):
    """The request body is larger than the service accepts."""

    def __init__(self, max_bytes: int) -> None:
        super().__init__(
            f"request body exceeds the limit of {max_bytes} bytes (PBDAG_MAX_BODY_BYTES; a "
            "batch of many frames can be posted as several batches)",
            "body",
        )
