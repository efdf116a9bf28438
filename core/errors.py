"""The errors of the method: what a command or a parameter override asks that cannot be done.

Each names the field it is about. They are `Refused` errors of the one hierarchy
(`pbdag_errors`): nothing was changed. The service's one problem table (service/errors.py) gives
each class its HTTP answer.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence

from pbdag_errors import Refused

_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class NotFound(Refused):
    """A named resource (batch, track, baseline...) does not exist."""

    def __init__(self, what: str, id: str, field: str | None = None) -> None:
        super().__init__(f"{what} '{id}' does not exist", field)


class DomainError(Refused):
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
