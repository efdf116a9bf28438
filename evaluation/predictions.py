"""What a method produced per frame: its published graph and its typed events."""

from __future__ import annotations

from dataclasses import dataclass

from core.event_envelope import TrackEvent
from core.events import TrackReparented
from sim.truth import Vec3


@dataclass(frozen=True)
class PredictedNode:
    """One node of the graph a method published."""

    track_id: str
    label: str
    center: Vec3
    parent: str | None
    kind: str = "object"  # "object" or "fixture"


@dataclass(frozen=True)
class FramePrediction:
    """The graph a method published after processing one frame."""

    frame_index: int
    nodes: tuple[PredictedNode, ...]


@dataclass(frozen=True)
class MethodEvent:
    """A change a method showed about one track while processing a frame: the class of the core
    event it is (or, for a method whose only output is its graph, the one it stands for), the
    new and old parents of a reparent, and the event itself when the method emitted one."""

    frame: int  # index of the frame being processed when the event was emitted
    track_id: str
    kind: type[TrackEvent]
    new_parent: str | None = None
    event: TrackEvent | None = None
    old_parent: str | None = None  # a reparent's parent before it (None: its first parent)

    @classmethod
    def of(cls, frame: int, event: TrackEvent) -> MethodEvent:
        """A core event as the method event it is."""
        if isinstance(event, TrackReparented):
            return cls(
                frame, event.track_id, type(event), event.new_parent, event, event.old_parent
            )
        return cls(frame, event.track_id, type(event), None, event)
