"""Typed audit events: one frozen dataclass per event type (section 3.3, "Lifecycle transitions").

Events carry what `evolve` needs, so folding the log never recomputes perception. `details`
holds only JSON-able values (str, int, float, bool, None, lists and dicts of them).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

LifecycleState = Literal["tentative", "confirmed", "demoted", "removed"]
LIFECYCLE_STATES: tuple[str, ...] = ("tentative", "confirmed", "demoted", "removed")


@dataclass(frozen=True)
class Event:
    """Base of every event: the track it concerns and its lifecycle state after the event."""

    type: ClassVar[str] = "event"
    track_id: str | None
    state: str | None
    frame_id: str | None = None
    details: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SceneCreated(Event):
    """First event of every scene: its name and the parameters its events are decided with."""

    type: ClassVar[str] = "scene_created"


@dataclass(frozen=True)
class TrackAdded(Event):
    """A new internal hypothesis, with the batch's observations of it."""

    type: ClassVar[str] = "add"


@dataclass(frozen=True)
class TrackConfirmed(Event):
    """Graph publication: cross-batch confirmation with p_exist >= 0.72."""

    type: ClassVar[str] = "confirm"


@dataclass(frozen=True)
class TrackUpdated(Event):
    """One existence update of a batch: `details.evidence` is `observed` or `visible_miss`."""

    type: ClassVar[str] = "update"


@dataclass(frozen=True)
class TrackMoved(Event):
    """A published track is at least 0.35 m from its last published position."""

    type: ClassVar[str] = "move"


@dataclass(frozen=True)
class TrackReparented(Event):
    """The support parent changed: `details` names the old and the new parent."""

    type: ClassVar[str] = "reparent"


@dataclass(frozen=True)
class TrackDemoted(Event):
    """A published track fell below p_exist 0.30 and is unpublished."""

    type: ClassVar[str] = "demote"


@dataclass(frozen=True)
class TrackRemoved(Event):
    """p_exist <= 0.12 after at least three visibility-admissible misses."""

    type: ClassVar[str] = "remove"


@dataclass(frozen=True)
class FixtureEvidence(Event):
    """Class evidence of the batch's fixture masks, added to the scene's voxel map."""

    type: ClassVar[str] = "fixture_evidence"


@dataclass(frozen=True)
class VerificationRequested(Event):
    """A near-threshold or class-conflicting fixture waits for one bounded verification."""

    type: ClassVar[str] = "verification_requested"


@dataclass(frozen=True)
class TrackVerified(Event):
    """A verdict on a pending track: evidence weight 3, existence +1.8 or -2.2."""

    type: ClassVar[str] = "verify"


@dataclass(frozen=True)
class BaselineFrozen(Event):
    """The confirmed fixtures frozen as an immutable, versioned package; they become pinned."""

    type: ClassVar[str] = "baseline_frozen"


@dataclass(frozen=True)
class BaselineLoaded(Event):
    """A new session starts from a frozen baseline: its fixtures keep their identities."""

    type: ClassVar[str] = "baseline_loaded"


@dataclass(frozen=True)
class InspectionRecorded(Event):
    """One fixture-centered capture in the ledger: frames, outcome and attached children."""

    type: ClassVar[str] = "inspection"


EVENT_TYPES: dict[str, type[Event]] = {
    cls.type: cls
    for cls in (
        SceneCreated,
        TrackAdded,
        TrackConfirmed,
        TrackUpdated,
        TrackMoved,
        TrackReparented,
        TrackDemoted,
        TrackRemoved,
        FixtureEvidence,
        VerificationRequested,
        TrackVerified,
        BaselineFrozen,
        BaselineLoaded,
        InspectionRecorded,
    )
}


def event_to_record(event: Event) -> dict[str, Any]:
    """The JSON-able form stored in the log."""
    return {
        "type": event.type,
        "track_id": event.track_id,
        "state": event.state,
        "frame_id": event.frame_id,
        "details": dict(event.details),
    }


def event_from_record(record: Mapping[str, Any]) -> Event:
    """Inverse of `event_to_record`; unknown types raise ValueError."""
    cls = EVENT_TYPES.get(record["type"])
    if cls is None:
        raise ValueError(f"unknown event type {record['type']!r}")
    return cls(
        track_id=record.get("track_id"),
        state=record.get("state"),
        frame_id=record.get("frame_id"),
        details=record.get("details") or {},
    )


def touched_tracks(event: Event) -> tuple[str, ...]:
    """Every track whose state the event changes (scene-level events may change several)."""
    if isinstance(event, BaselineFrozen):
        return tuple(event.details["fixture_ids"])
    if isinstance(event, BaselineLoaded):
        return tuple(record["track_id"] for record in event.details["fixtures"])
    return () if event.track_id is None else (event.track_id,)
