"""Errors a client can cause, each naming the field it is about; the service maps them to HTTP.

Every error the service reports derives from `PbdagError`: a plain detail (never echoing large
input) and the offending field as a path (`frames[0].pose`, `params.visibility.depth_window_px`).
The service's one problem table (service/errors.py) gives each class its HTTP status.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence

_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class PbdagError(Exception):
    """Base of every reported error: nothing was changed by the request that raised it."""

    def __init__(
        self, detail: str, field: str | None = None, headers: dict[str, str] | None = None
    ) -> None:
        super().__init__(detail)
        self.detail = detail
        self.field = field
        self.headers = headers or {}


class NotFound(PbdagError):
    """A named resource (batch, track, baseline...) does not exist."""

    def __init__(self, what: str, id: str, field: str | None = None) -> None:
        super().__init__(f"{what} '{id}' does not exist", field)


class DomainError(PbdagError):
    """A command that the scene's state does not allow; nothing is appended."""


class UnknownTrack(DomainError):
    """No track with this id in the scene."""


class InvalidCommand(DomainError):
    """The command names something of the wrong kind (an object where a fixture is needed...)."""


class StateConflict(DomainError):
    """The command conflicts with the track's state (a second verdict, an unconfirmed fixture...)."""


class InvalidParams(DomainError):
    """A parameter override outside the method's parameter tree, its types or its ranges."""


def field_path(location: Sequence[str | int]) -> str | None:
    """A pydantic error location as a path like `frames[0].pose` (None when empty)."""
    path = ""
    for part in location:
        if isinstance(part, int):
            path += f"[{part}]"
        elif _IDENTIFIER.fullmatch(part):
            path += f".{part}" if path else part
        else:  # dict keys such as class-score labels may contain spaces or dots
            path += f"[{json.dumps(part)}]"
    return path or None
