"""Wire models of the PBD-AG HTTP API (pydantic only: no core, no service)."""

from api_schema.requests import (
    BatchIn,
    DepthImage,
    DetectionIn,
    FrameIn,
    Intrinsics,
    RleMask,
    SceneCreate,
)
from api_schema.responses import (
    BatchStatus,
    EventOut,
    EventPage,
    Explanation,
    Graph,
    GraphEdge,
    GraphNode,
    Health,
    Removal,
    Scene,
    SceneList,
    TrackBelief,
    VisibleMiss,
)

__all__ = [
    "BatchIn",
    "BatchStatus",
    "DepthImage",
    "DetectionIn",
    "EventOut",
    "EventPage",
    "Explanation",
    "FrameIn",
    "Graph",
    "GraphEdge",
    "GraphNode",
    "Health",
    "Intrinsics",
    "Removal",
    "RleMask",
    "Scene",
    "SceneCreate",
    "SceneList",
    "TrackBelief",
    "VisibleMiss",
]
