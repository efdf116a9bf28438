"""What a method produced per frame: its published graph and its typed events."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

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
    """A typed event a method emitted (add, confirm, update, move, reparent, demote, remove)."""

    frame: int  # index of the frame being processed when the event was emitted
    type: str
    track_id: str
    details: Mapping[str, Any]
