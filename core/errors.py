"""Domain errors of the method's commands; the service maps them to HTTP in one place."""

from __future__ import annotations


class DomainError(Exception):
    """A command that the scene's state does not allow; nothing is appended."""

    def __init__(self, detail: str, field: str | None = None) -> None:
        super().__init__(detail)
        self.detail = detail
        self.field = field


class UnknownTrack(DomainError):
    """No track with this id in the scene."""


class InvalidCommand(DomainError):
    """The command names something of the wrong kind (an object where a fixture is needed...)."""


class StateConflict(DomainError):
    """The command conflicts with the track's state (a second verdict, an unconfirmed fixture...)."""
