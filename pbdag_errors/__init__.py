"""The root of every error PBD-AG raises on purpose, shared by every package: it imports nothing.

Two branches, by who can act on the error:

- `Refused`: what was asked cannot be done as asked (bad input, an unknown name, a conflict with
  the current state, a limit reached). Nothing was changed; the detail says what to correct.
- `Failure`: the system failed (the database, the blob store, a stored record). What was asked
  was fine; a retry or an operator may help.

It lives below every package, `core` and `pbdag_client` included, so that the method, the
service, the simulator, `ingest` and the client share one root without importing each other.
No transport lives here: the service's one problem table (service/errors.py) gives each class its
HTTP answer.
"""

from __future__ import annotations

__all__ = ["Failure", "PbdagError", "Refused"]


class PbdagError(Exception):
    """Base of every error raised on purpose: a plain detail (never echoing large input) and the
    offending field as a path (`frames[0].pose`, `params.visibility.depth_window_px`), if any."""

    def __init__(self, detail: str, field: str | None = None) -> None:
        super().__init__(detail)
        self.detail = detail
        self.field = field


class Refused(PbdagError):
    """What was asked cannot be done as asked; nothing was changed."""


class Failure(PbdagError):
    """The system failed, not what was asked; a retry or an operator may help."""
