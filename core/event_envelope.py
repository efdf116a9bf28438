"""What every event shares: its names, its envelope, and its payload as stored JSON.

Every event has an envelope (the track it concerns, the lifecycle state after it, the frame it
came from), stored in columns of its own; `details()` is the rest, the payload, as stored JSON.
core/events.py has the event classes, core/event_records.py their stored rows.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from pydantic import TypeAdapter

from core.values import FINITE, LifecycleState

ENVELOPE = frozenset({"track_id", "state", "frame_id"})


@dataclass(frozen=True, kw_only=True)
class BaseEvent:
    """Base of every event class: its two names and the envelope the log keeps in columns."""

    __pydantic_config__ = FINITE
    # The name the class's rows are stored under: one per class and payload version, never
    # reused (the upcasters in core/upcasters.py read names and payloads stored before).
    topic: ClassVar[str]
    # The paper's audit vocabulary (add, update, confirm, move, reparent, demote, remove, ...):
    # what the API shows as the event's `type`. Several classes may share one.
    type: ClassVar[str]
    track_id: str | None = None
    state: LifecycleState | None = None
    frame_id: str | None = None

    def details(self) -> dict[str, Any]:
        """The payload as stored JSON (JSON-able values, in the stored key order)."""
        payload: dict[str, Any] = payload_adapter(type(self)).dump_python(
            self, mode="json", by_alias=True, exclude=set(ENVELOPE)
        )
        return payload

    def touched_tracks(self) -> tuple[str, ...]:
        """Every track whose state the event changes."""
        return () if self.track_id is None else (self.track_id,)


@dataclass(frozen=True, kw_only=True)
class TrackEvent(BaseEvent):
    """An event about one track: it names the track and its lifecycle state after the event."""

    track_id: str
    state: LifecycleState


_ADAPTERS: dict[type[BaseEvent], TypeAdapter[Any]] = {}


def payload_adapter(cls: type[BaseEvent]) -> TypeAdapter[Any]:
    """pydantic's validator and serializer of one event class, built on first use."""
    adapter = _ADAPTERS.get(cls)
    if adapter is None:
        adapter = _ADAPTERS[cls] = TypeAdapter(cls)
    return adapter
