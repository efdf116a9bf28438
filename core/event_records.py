"""The stored form of events: type, envelope and payload, and back (core/events.py has the classes).

A few stored types hold more than one class, told apart by the payload itself (the stored JSON
predates the typed classes and is kept byte for byte): `add` by its `kind`, `update` by its
`evidence` and, for observations, by whether it carries a fixture's EMA `center`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from pydantic import TypeAdapter

from core.events import (
    BaselineFrozen,
    BaselineLoaded,
    BatchSkipped,
    Event,
    FixtureAdded,
    FixtureEvidence,
    FixtureObserved,
    InspectionRecorded,
    InspectionTargeted,
    ObjectAdded,
    ObjectObserved,
    ObjectReidentified,
    OccupancyEvidence,
    SceneCreated,
    TrackConfirmed,
    TrackDemoted,
    TrackMoved,
    TrackRemoved,
    TrackReparented,
    TrackRetired,
    TrackVerified,
    VerificationRequested,
    VisibleMiss,
)

ENVELOPE = frozenset({"track_id", "state", "frame_id"})


def payload_of(event: Event) -> dict[str, Any]:
    """The payload of `event` as stored JSON (JSON-able values, in the stored key order)."""
    result: dict[str, Any] = _adapter(type(event)).dump_python(
        event, mode="json", by_alias=True, exclude=set(ENVELOPE)
    )
    return result


_ADAPTERS: dict[type[Event], TypeAdapter[Any]] = {}


def _adapter(cls: type[Event]) -> TypeAdapter[Any]:
    """pydantic's validator and serializer of one event class, built on first use."""
    adapter = _ADAPTERS.get(cls)
    if adapter is None:
        adapter = _ADAPTERS[cls] = TypeAdapter(cls)
    return adapter


_SINGLE_CLASS: dict[str, type[Event]] = {
    cls.type: cls
    for cls in (
        SceneCreated,
        FixtureEvidence,
        BaselineFrozen,
        BaselineLoaded,
        BatchSkipped,
        TrackConfirmed,
        TrackMoved,
        TrackReparented,
        TrackDemoted,
        TrackRemoved,
        TrackRetired,
        VerificationRequested,
        TrackVerified,
        InspectionRecorded,
        OccupancyEvidence,
        InspectionTargeted,
    )
}
EVENT_TYPE_NAMES: tuple[str, ...] = (*sorted(_SINGLE_CLASS), "add", "update")


def event_class(type_name: str, details: Mapping[str, Any]) -> type[Event]:
    """The class of a stored event; ValueError for a type or payload no class describes."""
    if type_name == "add":
        return FixtureAdded if details.get("kind") == "fixture" else ObjectAdded
    if type_name == "update":
        if details.get("evidence") == "visible_miss":
            return VisibleMiss
        if details.get("evidence") == "reidentified":
            return ObjectReidentified
        return FixtureObserved if "center" in details else ObjectObserved
    cls = _SINGLE_CLASS.get(type_name)
    if cls is None:
        raise ValueError(f"unknown event type {type_name!r}")
    return cls


def event_from_record(record: Mapping[str, Any]) -> Event:
    """An event from its stored form; pydantic's ValidationError names a bad payload field."""
    details: Mapping[str, Any] = record.get("details") or {}
    cls = event_class(record["type"], details)
    values = {
        **details,
        "track_id": record.get("track_id"),
        "state": record.get("state"),
        "frame_id": record.get("frame_id"),
    }
    event: Event = _adapter(cls).validate_python(values)
    return event


def event_to_record(event: Event) -> dict[str, Any]:
    """The stored form: type, envelope and the JSON-able payload."""
    return {
        "type": event.type,
        "track_id": event.track_id,
        "state": event.state,
        "frame_id": event.frame_id,
        "details": event.details(),
    }


def non_finite_field(value: Any, path: str = "details") -> str | None:
    """The path of the first NaN or infinite number in a JSON-able value, or None."""
    if _surely_finite(value):  # the common case, without building a path per number
        return None
    return _first_non_finite(value, path)


def _surely_finite(value: Any) -> bool:
    """True only when `value` holds no NaN or infinity; False may also mean "look closer".

    A list of numbers is summed in one C loop: any NaN or infinity makes the sum non-finite
    (a finite sum that overflows only sends the caller to the exact walk).
    """
    kind = type(value)
    if kind is float:
        return math.isfinite(value)
    if kind is str or kind is int or kind is bool or value is None:
        return True
    if kind is dict:
        return all(_surely_finite(item) for item in value.values())
    if kind is list or kind is tuple:
        try:
            return math.isfinite(sum(value))
        except (TypeError, OverflowError):  # not only numbers, or an int too large for a float
            return all(_surely_finite(item) for item in value)
    return False


def _first_non_finite(value: Any, path: str) -> str | None:
    if isinstance(value, float):
        return None if math.isfinite(value) else path
    if isinstance(value, Mapping):
        for key, item in value.items():
            found = _first_non_finite(item, f"{path}.{key}")
            if found is not None:
                return found
    elif isinstance(value, list | tuple):
        for index, item in enumerate(value):
            found = _first_non_finite(item, f"{path}[{index}]")
            if found is not None:
                return found
    return None
